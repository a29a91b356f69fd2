// libdsm: deep shadow maps. This header includes the renderer-facing core
// (dsm::core: functions, the file, lookups, soft shadows, merging). The
// heavy components have their own: dsm/build.h, dsm/exr.h, dsm/reference.h.
#pragma once

#include "dsm/area_light.h"
#include "dsm/auto_bias.h"
#include "dsm/build_visibility.h"
#include "dsm/compressor.h"
#include "dsm/error.h"
#include "dsm/lookup.h"
#include "dsm/map_images.h"
#include "dsm/map_info.h"
#include "dsm/merge.h"
#include "dsm/names.h"
#include "dsm/output_file.h"
#include "dsm/reader.h"
#include "dsm/shadow_system.h"
#include "dsm/soft_shadow.h"
#include "dsm/soft_shadow_image.h"
#include "dsm/sweep.h"
#include "dsm/tile_cache.h"
#include "dsm/transmittance.h"
#include "dsm/value_step.h"
#include "dsm/vec3.h"
#include "dsm/vertex_sink.h"
#include "dsm/visibility.h"
#include "dsm/visibility_product.h"
#include "dsm/writer.h"
