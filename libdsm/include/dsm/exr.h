// libdsm's exr component (dsm::exr): deep OpenEXR import and export. Needs OpenEXR.
#pragma once

#include "dsm/dsm.h"
#include "dsm/exr_deep.h"
