// libdsm's build component (dsm::build): scenes and the sampler that makes
// maps from them. Needs TBB and tinyobjloader (and OpenVDB for VDB volumes).
#pragma once

#include "dsm/dsm.h"
#include "dsm/sampler.h"
#include "dsm/scene.h"
#include "dsm/threads.h"
