#include "dsm/soft_shadow_image.h"

#include <cmath>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

FloatImage softShadowImage(const std::shared_ptr<const SoftShadowTracer>& tracer, unsigned level,
                           const PixelRect& rect, const SoftShadowImageOptions& options) {
    const DeepShadowMap& map = tracer->map();
    checkPixelRect(map, level, rect);
    const double z = options.receiverDepth;
    if (!std::isfinite(z))
        throw Error(ErrorCode::argument, detail::concat("'", map.path(), "': receiver depth is not finite"),
                    map.path());
    const MapInfo& info = map.info();
    const LevelInfo& L = info.levels[level];
    const LightCamera& camera = info.camera;
    const auto& window = camera.screenWindow;
    // Level pixels to level-0 raster to screen to light space.
    const double scaleX = static_cast<double>(info.width) / L.width, scaleY = static_cast<double>(info.height) / L.height;
    const bool perspective = camera.projection == Projection::Perspective;
    SoftShadowContext context(tracer);
    FloatImage image(rect.width, rect.height, info.channels, 1.0f);
    for (std::uint32_t j = 0; j < rect.height; ++j)
        for (std::uint32_t i = 0; i < rect.width; ++i) {
            const double rx = (rect.x + i + 0.5) * scaleX, ry = (rect.y + j + 0.5) * scaleY;
            const double sx = window[0] + rx / info.width * (window[1] - window[0]);
            const double sy = window[3] - ry / info.height * (window[3] - window[2]);
            const Vec3 light = perspective ? Vec3{sx * z, sy * z, z} : Vec3{sx, sy, z};
            const SoftShadowResult result = context.visibility(tracer->light().lightToWorld(light), options.shadow);
            for (int c = 0; c < image.channels; ++c)
                image.at(i, j, c) = static_cast<float>(result.v[static_cast<std::size_t>(c)]);
        }
    return image;
}

DSM_NAMESPACE_END
