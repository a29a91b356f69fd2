// How files, tools and bindings spell the enums of map_info.h (metadata,
// OpenEXR attributes, command lines, dsm-info).
#pragma once

#include <optional>
#include <string_view>

#include "dsm/map_info.h"

namespace dsm {

const char* projectionName(Projection projection);
const char* filterName(PixelFilter filter);
/// The filter named "box", "triangle" or "gaussian" (as filterName() gives);
/// nothing for any other text.
std::optional<PixelFilter> pixelFilterFromName(std::string_view name);

}  // namespace dsm
