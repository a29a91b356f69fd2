#include "colour_ramp.h"

#include <algorithm>
#include <array>
#include <cstddef>

#include "dsm/error.h"
#include "text.h"

namespace dsm {

using detail::concat;

FloatImage colourRamp(const FloatImage& image, float maximum) {
    if (image.channels != 1)
        throw Error(ErrorCode::argument, concat("colour ramp: expected a one-channel image, got ", image.channels, " channels"));
    // Luminance rises along the ramp, so it still reads in grey.
    static constexpr std::array<std::array<float, 3>, 5> kStops{{
        {0.0f, 0.0f, 0.0f},
        {0.1f, 0.1f, 0.9f},
        {0.85f, 0.15f, 0.75f},
        {1.0f, 0.65f, 0.25f},
        {1.0f, 1.0f, 1.0f},
    }};
    FloatImage rgb(image.width, image.height, 3);
    for (std::uint32_t y = 0; y < image.height; ++y)
        for (std::uint32_t x = 0; x < image.width; ++x) {
            const float t = maximum > 0.0f ? std::clamp(image.at(x, y) / maximum, 0.0f, 1.0f) : 0.0f;
            const float position = t * static_cast<float>(kStops.size() - 1);
            const std::size_t k = std::min(static_cast<std::size_t>(position), kStops.size() - 2);
            const float u = position - static_cast<float>(k);
            for (int c = 0; c < 3; ++c) {
                const auto ci = static_cast<std::size_t>(c);
                rgb.at(x, y, c) = kStops[k][ci] + (kStops[k + 1][ci] - kStops[k][ci]) * u;
            }
        }
    return rgb;
}

}  // namespace dsm
