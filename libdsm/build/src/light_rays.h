// Rays from a light camera (internal): the sampler's and the depth map's rays
// through raster positions, parametrised by light-space depth, and the small
// deterministic generator that places their samples.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "dsm/map_info.h"
#include "dsm/scene.h"
#include "splitmix64.h"

namespace dsm::detail {

/// A seed for pixel (x, y) derived from a map-wide seed.
inline std::uint64_t pixelSeed(std::uint64_t seed, std::uint32_t x, std::uint32_t y) {
    SplitMix64 r(seed ^ (std::uint64_t(x) << 32 | y));
    r.next();
    return r.next() ^ (std::uint64_t(y) << 32 | x);
}

/// The light's frame in world space. A ray's direction has unit light-space z,
/// so the point at parameter t lies at light depth t.
struct LightRayFrame {
    Projection projection = Projection::Perspective;
    Vec3 origin{};                 ///< projection centre (perspective) or window centre
    Vec3 right{}, up{}, forward{}; ///< light-space axes in world space
    std::array<double, 4> window{};
    std::uint32_t width = 0, height = 0;

    /// The ray through raster position (rx, ry).
    void ray(double rx, double ry, Vec3& o, Vec3& d) const {
        double sx, sy;
        screen(rx, ry, sx, sy);
        rayAt(sx, sy, o, d);
    }
    /// Raster position (rx, ry) in screen units (the window's).
    void screen(double rx, double ry, double& sx, double& sy) const {
        sx = window[0] + rx / width * (window[1] - window[0]);
        sy = window[3] - ry / height * (window[3] - window[2]);
    }
    /// The ray through screen position (sx, sy).
    void rayAt(double sx, double sy, Vec3& o, Vec3& d) const {
        if (projection == Projection::Perspective) {
            o = origin;
            for (std::size_t i = 0; i < 3; ++i) d[i] = forward[i] + sx * right[i] + sy * up[i];
        } else {
            for (std::size_t i = 0; i < 3; ++i) o[i] = origin[i] + sx * right[i] + sy * up[i];
            d = forward;
        }
    }
};

/// The frame of a camera whose worldToLight is rigid (rows are the light
/// axes; the inverse translation is the projection centre).
inline LightRayFrame lightRayFrame(const LightCamera& camera, std::uint32_t width, std::uint32_t height) {
    const auto& m = camera.worldToLight;
    LightRayFrame f;
    f.projection = camera.projection;
    f.right = {m[0], m[1], m[2]};
    f.up = {m[4], m[5], m[6]};
    f.forward = {m[8], m[9], m[10]};
    const Vec3 t{m[3], m[7], m[11]};
    for (std::size_t i = 0; i < 3; ++i) f.origin[i] = -(f.right[i] * t[0] + f.up[i] * t[1] + f.forward[i] * t[2]);
    f.window = camera.screenWindow;
    f.width = width;
    f.height = height;
    return f;
}

}  // namespace dsm::detail
