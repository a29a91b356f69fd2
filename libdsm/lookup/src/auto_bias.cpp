#include "dsm/auto_bias.h"

#include <algorithm>
#include <cmath>

DSM_NAMESPACE_BEGIN

namespace {

constexpr double kDepthPrecision = 1.0 / 16384.0;  // 2^-14

// The surface's depth slope along the light's ray: tan of the angle between
// the normal and the ray, in [1, max]; 1 without a usable normal. Not below 1:
// a surface facing the light still meets rays leaving it at up to the light's
// angle, curves away within the filter's reach and, blurred by motion, spreads
// its depths; a smaller floor made the examples' mean errors 1.6-2.6 times
// the best constant bias's.
double slope(const MapInfo& info, double rx, double ry, const std::optional<Vec3>& n) {
    if (!n) return 1.0;
    const Vec3& v = *n;
    const double length = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!(length > 0.0) || !std::isfinite(length)) return 1.0;  // no usable normal
    Vec3 ray{0.0, 0.0, 1.0};
    if (info.camera.projection == Projection::Perspective) {
        const auto& w = info.camera.screenWindow;
        ray = {w[0] + rx / info.width * (w[1] - w[0]), w[3] - ry / info.height * (w[3] - w[2]), 1.0};
    }
    // tan = |n x ray| / |n . ray| (the cross product keeps the sine exact
    // near 0, where 1 - cos^2 would cancel).
    const double c = std::abs(v[0] * ray[0] + v[1] * ray[1] + v[2] * ray[2]);
    const double x = v[1] * ray[2] - v[2] * ray[1], y = v[2] * ray[0] - v[0] * ray[2],
                 z = v[0] * ray[1] - v[1] * ray[0];
    const double s = std::sqrt(x * x + y * y + z * z);
    if (s >= kAutomaticBiasMaxSlope * c) return kAutomaticBiasMaxSlope;
    return std::max(1.0, s / c);
}

}  // namespace

double automaticBias(const MapInfo& info, double rx, double ry, double z, const std::optional<Vec3>& lightNormal) noexcept {
    const auto& w = info.camera.screenWindow;
    const double window = std::max((w[1] - w[0]) / info.width, (w[3] - w[2]) / info.height);
    const bool perspective = info.camera.projection == Projection::Perspective;
    const double pixel = perspective ? std::abs(z) * window : window;
    const double reach = 1.0 + 0.5 * info.filterWidth;
    return std::abs(z) * kDepthPrecision + pixel * reach * slope(info, rx, ry, lightNormal);
}

Vec3 lightSpaceNormal(const LightCamera& camera, const Vec3& n) noexcept {
    // The inverse transpose of the upper 3x3 block A of worldToLight is
    // cofactor(A) / det(A); the scale does not matter for a normal, but the
    // sign of det does (a mirrored camera).
    const auto& m = camera.worldToLight;
    const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
    const double c00 = e * i - f * h, c01 = f * g - d * i, c02 = d * h - e * g;
    const double c10 = c * h - b * i, c11 = a * i - c * g, c12 = b * g - a * h;
    const double c20 = b * f - c * e, c21 = c * d - a * f, c22 = a * e - b * d;
    const double det = a * c00 + b * c01 + c * c02;
    const double s = det < 0.0 ? -1.0 : 1.0;
    return {s * (c00 * n[0] + c01 * n[1] + c02 * n[2]), s * (c10 * n[0] + c11 * n[1] + c12 * n[2]),
            s * (c20 * n[0] + c21 * n[1] + c22 * n[2])};
}

DSM_NAMESPACE_END
