// The kernels of the pixel filters (internal; PixelFilter in map_info.h),
// shared by the sampler that builds maps and the lookups that filter them.
// Distances are in pixels; r is half the filter width. Both cut the kernels
// at |d| = r on each axis. The box is not here: the sampler weighs samples
// inside the square equally, the lookup weighs pixels by their overlap.
#pragma once

#include <algorithm>
#include <cmath>

#include "exponential.h"

namespace dsm::detail {

/// Triangle (tent): 1 at the centre, falling linearly to 0 at distance r.
inline double triangleWeight(double d, double r) { return std::max(0.0, 1.0 - std::abs(d) / r); }

/// Gaussian of standard deviation r / 2, at squared distance d2 (one axis,
/// or the sum over both for a radial weight).
inline double gaussianWeight(double d2, double r) {
    const double s = 0.5 * r;
    return exponential(-d2 / (2.0 * s * s));
}

}  // namespace dsm::detail
