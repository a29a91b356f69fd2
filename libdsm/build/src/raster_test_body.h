// The raster test's loop over a pixel's samples (raster_test.h, internal),
// for a vector type of L doubles and its comparison mask. Included by
// raster_test.cpp (two lanes) and raster_test_avx2.cpp (four, built with
// -mavx2). The helpers are static: each translation unit keeps its own copy,
// compiled for its own instructions.
#pragma once

#include <cstring>

#include "raster_test.h"

namespace dsm::detail {
namespace {

// LaneBits(mask) gives bit l for lane l of a comparison that holds.
template <class Doubles, class Mask, std::size_t L, class LaneBits>
[[gnu::always_inline]] inline std::uint64_t passingSamples(const double* xs, const double* ys, std::size_t n,
                                                            const RasterTest& t, LaneBits laneBits) {
    const auto splat = [](double v) {
        Doubles lanes;
        for (std::size_t l = 0; l < L; ++l) lanes[l] = v;
        return lanes;
    };
    std::uint64_t result = 0;
    if (t.radius2 >= 0.0) {
        const Doubles x0 = splat(t.x0), y0 = splat(t.y0), dx = splat(t.dx), dy = splat(t.dy);
        const Doubles inverse = splat(t.invLength2), radius2 = splat(t.radius2), zero = splat(0.0), one = splat(1.0);
        for (std::size_t j = 0; j < n; j += L) {
            Doubles x, y;
            std::memcpy(&x, xs + j, sizeof x);
            std::memcpy(&y, ys + j, sizeof y);
            const Doubles ex = x - x0, ey = y - y0;
            Doubles along = (ex * dx + ey * dy) * inverse;
            along = along < zero ? zero : along;
            along = along > one ? one : along;
            const Doubles gx = ex - along * dx, gy = ey - along * dy;
            const Mask pass = ~(gx * gx + gy * gy > radius2);
            result |= laneBits(pass) << j;
        }
    } else {
        const Doubles bx0 = splat(t.boundsX0), bx1 = splat(t.boundsX1), by0 = splat(t.boundsY0),
                      by1 = splat(t.boundsY1);
        for (std::size_t j = 0; j < n; j += L) {
            Doubles x, y;
            std::memcpy(&x, xs + j, sizeof x);
            std::memcpy(&y, ys + j, sizeof y);
            const Mask pass = (x >= bx0) & (x <= bx1) & (y >= by0) & (y <= by1);
            result |= laneBits(pass) << j;
        }
    }
    return n == 64 ? result : result & ((std::uint64_t(1) << n) - 1);
}

}  // namespace
}  // namespace dsm::detail
