// The command-line spelling of an area light's size (dsm-lookup, the bindings).
#pragma once

#include <string_view>

#include "dsm/area_light.h"

namespace dsm {

/// "disk:R" (radius R) or "rect:W,H" (full width W and height H), sizes
/// finite and > 0, light-space units. Throws dsm::Error quoting the text
/// otherwise.
AreaLightSize parseAreaLightSize(std::string_view text);

}  // namespace dsm
