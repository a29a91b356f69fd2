#include "dsm/map_info.h"

#include <algorithm>
#include <cmath>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

bool LightCamera::lightToRaster(const std::array<double, 3>& p, int width, int height, double& rx, double& ry,
                                double& z) const {
    z = p[2];
    double sx = p[0], sy = p[1];
    if (projection == Projection::Perspective) {
        if (!(p[2] > 0.0)) return false;
        sx /= p[2];
        sy /= p[2];
    }
    const auto& w = screenWindow;
    rx = (sx - w[0]) / (w[1] - w[0]) * width;
    ry = (w[3] - sy) / (w[3] - w[2]) * height;
    return std::isfinite(rx) && std::isfinite(ry);
}

void LightCamera::validate() const {
    for (double m : worldToLight)
        if (!std::isfinite(m))
            throw Error(ErrorCode::argument,
                        detail::concat("light camera: world-to-light entry ", m, " is not finite"));
    for (double s : screenWindow)
        if (!std::isfinite(s))
            throw Error(ErrorCode::argument, detail::concat("light camera: screen window value ", s, " is not finite"));
    if (!(screenWindow[0] < screenWindow[1]) || !(screenWindow[2] < screenWindow[3]))
        throw Error(ErrorCode::argument,
                    detail::concat("light camera: screen window [", screenWindow[0], ", ", screenWindow[1], "] x [",
                                   screenWindow[2], ", ", screenWindow[3], "] is empty"));
    if (!std::isfinite(nearPlane) || nearPlane < 0.0)
        throw Error(ErrorCode::argument,
                    detail::concat("light camera: near plane ", nearPlane, " is not a finite value >= 0"));
}

std::uint32_t levelExtent(std::uint32_t fullExtent, unsigned level) {
    std::uint64_t e = fullExtent;
    for (unsigned i = 0; i < level && e > 1; ++i) e = (e + 1) / 2;
    return static_cast<std::uint32_t>(std::max<std::uint64_t>(e, 1));
}

unsigned fullLevelCount(std::uint32_t width, std::uint32_t height) {
    unsigned levels = 1;
    std::uint64_t w = width, h = height;
    while (w > 1 || h > 1) {
        w = (w + 1) / 2;
        h = (h + 1) / 2;
        ++levels;
    }
    return levels;
}

DSM_NAMESPACE_END
