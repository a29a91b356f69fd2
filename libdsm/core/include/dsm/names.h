// How files, tools and bindings spell the enums of map_info.h (metadata,
// OpenEXR attributes, command lines, dsm-info).
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

DSM_API const char* projectionName(Projection projection);
DSM_API const char* filterName(PixelFilter filter);
/// The filter named "box", "triangle" or "gaussian" (as filterName() gives);
/// nothing for any other text.
DSM_API std::optional<PixelFilter> pixelFilterFromName(std::string_view name);
/// The header's required flags of the file `info` describes, by their names
/// in spec/dsm-format.md §4 ("HAS_COUNTS", "HAS_LAYERS", "CODED_TILES",
/// "PREDICTED_DEPTHS"), lowest bit first; empty for a plain 1.0 map.
DSM_API std::vector<std::string> requiredFlagNames(const MapInfo& info);

DSM_NAMESPACE_END
