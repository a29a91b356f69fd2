// How files, tools and bindings spell the enums of map_info.h (metadata,
// OpenEXR attributes, command lines, dsm-info).
#pragma once

#include <optional>
#include <string_view>

#include "dsm/map_info.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

DSM_API const char* projectionName(Projection projection);
DSM_API const char* filterName(PixelFilter filter);
/// The filter named "box", "triangle" or "gaussian" (as filterName() gives);
/// nothing for any other text.
DSM_API std::optional<PixelFilter> pixelFilterFromName(std::string_view name);

DSM_NAMESPACE_END
