#include "area_light_size.h"

#include <charconv>
#include <cmath>
#include <optional>
#include <system_error>

#include "dsm/error.h"
#include "text.h"

namespace dsm {

using detail::concat;

AreaLightSize parseAreaLightSize(std::string_view text) {
    const auto positive = [](std::string_view field) -> std::optional<double> {
        if (!field.empty() && field.front() == '+') field.remove_prefix(1);
        double value = 0.0;
        const auto [end, error] = std::from_chars(field.data(), field.data() + field.size(), value);
        if (error != std::errc() || end != field.data() + field.size() || !std::isfinite(value) || !(value > 0.0))
            return std::nullopt;
        return value;
    };
    AreaLightSize size;
    if (text.starts_with("disk:")) {
        if (const auto radius = positive(text.substr(5))) {
            size.halfWidth = size.halfHeight = *radius;
            return size;
        }
    } else if (text.starts_with("rect:")) {
        const std::string_view sizes = text.substr(5);
        if (const auto comma = sizes.find(','); comma != std::string_view::npos) {
            const auto width = positive(sizes.substr(0, comma)), height = positive(sizes.substr(comma + 1));
            if (width && height) {
                size.shape = AreaLightShape::Rectangle;
                size.halfWidth = *width / 2.0;
                size.halfHeight = *height / 2.0;
                return size;
            }
        }
    }
    throw Error(ErrorCode::argument, concat("area light '", text, "': expected disk:R or rect:W,H with sizes > 0 (light-space units)"));
}

}  // namespace dsm
