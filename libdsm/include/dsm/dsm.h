// libdsm: deep shadow maps. This header includes the whole public API.
#pragma once

#include "dsm/build_visibility.h"
#include "dsm/compressor.h"
#include "dsm/error.h"
#include "dsm/lookup.h"
#include "dsm/map_info.h"
#include "dsm/reader.h"
#include "dsm/sweep.h"
#include "dsm/tile_cache.h"
#include "dsm/transmittance.h"
#include "dsm/vertex_sink.h"
#include "dsm/visibility.h"
#include "dsm/writer.h"
