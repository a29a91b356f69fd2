// libdsm's reference component (dsm::reference): the Embree reference tracer,
// the accuracy oracle of soft shadows. Needs Embree and dsm::build.
#pragma once

#include "dsm/build.h"
#include "dsm/reference_tracer.h"
