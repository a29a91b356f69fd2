#include "dsm/area_light.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <optional>
#include <system_error>
#include <bit>
#include <cmath>
#include <numbers>

#include "affine.h"
#include "dsm/error.h"
#include "simd_lanes.h"
#include "splitmix64.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using detail::Double2;
using detail::Mask2;

namespace {

// Two samples at a time: a sample's mapping is a chain of dependent
// multiplications, and one SSE2 register carries two chains for the price of
// one. Each lane's arithmetic is what one sample alone would do.

// sin and cos of |t| <= pi/4 by their Taylor series to t^15 and t^16, whose
// first omitted terms are below 5e-17 there: within a few ulps of the
// library's, at a fraction of the cost of its general argument reduction (a
// query draws a sample a ray).
void sinCosQuarter(Double2 t, Double2& sine, Double2& cosine) {
    const Double2 t2 = t * t;
    Double2 s = Double2{} + 1.0 / 1307674368000.0, c = Double2{} + 1.0 / 20922789888000.0;  // 1/15!, 1/16!
    constexpr double kSine[] = {-1.0 / 6227020800.0, 1.0 / 39916800.0, -1.0 / 362880.0, 1.0 / 5040.0,
                                -1.0 / 120.0,        1.0 / 6.0,        -1.0};  // 1/13! .. 1/1!, alternating
    constexpr double kCosine[] = {-1.0 / 87178291200.0, 1.0 / 479001600.0, -1.0 / 3628800.0, 1.0 / 40320.0,
                                  -1.0 / 720.0,         1.0 / 24.0,        -1.0 / 2.0,       1.0};  // 1/14! .. 1/0!
    for (double k : kSine) s = s * t2 + k;
    for (double k : kCosine) c = c * t2 + k;
    sine = -s * t;
    cosine = c;
}

Double2 magnitude(Double2 a) { return a < 0.0 ? -a : a; }

// Shirley & Chiu's concentric map from [0,1)^2 to the unit disk: keeps
// neighbouring strata neighbours, unlike the polar map.
void concentricDisk(Double2 u, Double2 v, Double2& x, Double2& y) {
    const Double2 a = 2.0 * u - 1.0, b = 2.0 * v - 1.0;
    // The angle pi/4 (b/a) from the x axis, or pi/2 - pi/4 (a/b): cos and sin
    // of the second are sin and cos of pi/4 (a/b). Which one applies is a
    // coin toss from sample to sample: chosen by lane masks, not branches.
    const Mask2 alongX = magnitude(a) > magnitude(b);
    const Double2 radius = alongX ? a : b, across = alongX ? b : a;
    Double2 sine, cosine;
    sinCosQuarter((std::numbers::pi / 4.0) * (across / radius), sine, cosine);
    x = radius * (alongX ? cosine : sine);
    y = radius * (alongX ? sine : cosine);
    const Mask2 centre = (a == 0.0) & (b == 0.0);  // where across / radius is 0 / 0
    x = centre ? Double2{} : x;
    y = centre ? Double2{} : y;
}

}  // namespace

AreaLight AreaLight::make(const LightCamera& camera, AreaLightShape shape, double halfWidth, double halfHeight,
                          std::optional<double> givenPlaneDepth) {
    camera.validate();
    const char* what = shape == AreaLightShape::Disk ? "disk" : "rectangle";
    if (camera.projection != Projection::Perspective)
        throw Error(ErrorCode::argument, concat("area light: the ", what, " needs a perspective (spot) light camera"));
    if (!(halfWidth > 0.0) || !(halfHeight > 0.0) || !std::isfinite(halfWidth) || !std::isfinite(halfHeight))
        throw Error(ErrorCode::argument,
                    concat("area light: ", what, " size ", halfWidth, " x ", halfHeight, " is not finite and > 0"));
    const auto& w = camera.screenWindow;
    // Half-angles (as tangents) of the frustum about the axis, per axis.
    const double tanX = std::min(w[1], -w[0]), tanY = std::min(w[3], -w[2]);
    if (!(tanX > 0.0) || !(tanY > 0.0))
        throw Error(ErrorCode::argument, concat("area light: the light camera's window [", w[0], ", ", w[1], "] x [",
                                                w[2], ", ", w[3], "] does not contain its axis"));
    const double fit = std::max(halfWidth / tanX, halfHeight / tanY);  // smallest plane depth that fits
    const double planeDepth = givenPlaneDepth.value_or(fit);
    if (!std::isfinite(planeDepth))
        throw Error(ErrorCode::argument, concat("area light: plane depth ", planeDepth, " is not finite"));
    // A light wider than the frustum at its plane sends rays the map never saw.
    if (planeDepth < fit * (1.0 - 1e-9))
        throw Error(ErrorCode::argument, concat("area light: the ", what, " (half-size ", halfWidth, " x ", halfHeight,
                                                ") does not fit the map's frustum at plane depth ", planeDepth,
                                                " (needs >= ", fit, "): the map was built for a smaller area light"));

    const detail::Affine lightToWorld = detail::inverseAffine(
        detail::affineOf(camera.worldToLight), "area light: the light camera's world-to-light matrix");

    AreaLight light;
    light.camera_ = camera;
    light.shape_ = shape;
    light.halfWidth_ = halfWidth;
    light.halfHeight_ = halfHeight;
    light.planeDepth_ = planeDepth;
    light.lightToWorld_ = lightToWorld;
    return light;
}

AreaLight AreaLight::disk(const LightCamera& camera, double radius, std::optional<double> planeDepth) {
    return make(camera, AreaLightShape::Disk, radius, radius, planeDepth);
}

AreaLight AreaLight::rectangle(const LightCamera& camera, double halfWidth, double halfHeight,
                               std::optional<double> planeDepth) {
    return make(camera, AreaLightShape::Rectangle, halfWidth, halfHeight, planeDepth);
}

double AreaLight::recordedRadius(const MapInfo& info) {
    if (info.areaLightRadius > 0.0) return info.areaLightRadius;  // the header's (format 1.1)
    // Files of format 1.0 record it only in their metadata.
    const nlohmann::json metadata = nlohmann::json::parse(info.metadata, nullptr, /*allow_exceptions=*/false);
    if (!metadata.is_object()) return 0.0;
    const auto number = [](const nlohmann::json& j) { return j.is_number() ? j.get<double>() : 0.0; };
    const auto settings = metadata.find("settings");
    if (settings != metadata.end() && settings->is_object() && settings->contains("area_light_radius"))
        return number((*settings)["area_light_radius"]);
    const auto scene = metadata.find("scene_json");
    if (scene != metadata.end() && scene->is_string()) {
        const nlohmann::json parsed = nlohmann::json::parse(scene->get<std::string>(), nullptr, false);
        if (parsed.is_object() && parsed.contains("light") && parsed["light"].is_object() &&
            parsed["light"].contains("area_radius"))
            return number(parsed["light"]["area_radius"]);
    }
    return 0.0;
}

AreaLight AreaLight::forMap(const MapInfo& info, AreaLightShape shape, double halfWidth, double halfHeight) {
    // A distant light first gets make()'s own complaint: it has no position.
    if (info.camera.projection != Projection::Perspective)
        return make(info.camera, shape, halfWidth, halfHeight, std::nullopt);
    const double built = recordedRadius(info);
    if (!(built > 0.0))
        throw Error(ErrorCode::argument,
                    "area light: the map records no area-light radius (build it from a scene whose light has "
                    "area_radius); its light is a point");
    const double planeDepth =
        info.areaLightPlaneDepth > 0.0 ? info.areaLightPlaneDepth : disk(info.camera, built).planeDepth();
    return make(info.camera, shape, halfWidth, shape == AreaLightShape::Disk ? halfWidth : halfHeight, planeDepth);
}

double AreaLight::area() const {
    return shape_ == AreaLightShape::Disk ? std::numbers::pi * halfWidth_ * halfWidth_
                                          : 4.0 * halfWidth_ * halfHeight_;
}

Vec3 AreaLight::lightToWorld(const Vec3& p) const {
    const auto& m = lightToWorld_;
    return {m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3], m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
            m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11]};
}

void AreaLight::lightSpaceSamples(const Vec3& receiver, int count, std::uint64_t seed, std::vector<Vec3>& out) const {
    out.clear();
    if (count < 1) throw Error(ErrorCode::argument, concat("area light: sample count ", count, " is not >= 1"));
    if (!std::isfinite(receiver[0]) || !std::isfinite(receiver[1]) || !std::isfinite(receiver[2]))
        throw Error(ErrorCode::argument,
                    concat("area light: receiver ", receiver[0], ",", receiver[1], ",", receiver[2], " is not finite"));
    // Seeded by the receiver's bits (+0.0 and -0.0 alike), so the samples of
    // a point never change between frames or threads.
    std::uint64_t s = detail::mix64(seed ^ 0x5DEECE66Dull);
    for (double q : receiver) s = detail::mix64(s ^ std::bit_cast<std::uint64_t>(q == 0.0 ? 0.0 : q));
    detail::SplitMix64 rng(s);
    const auto n = static_cast<std::uint32_t>(count);
    const std::uint32_t gy = std::max(1u, static_cast<std::uint32_t>(std::floor(std::sqrt(double(n)))));
    const std::uint32_t gx = (n + gy - 1) / gy;
    // A grid with more cells than samples leaves a random choice of cells
    // empty; a full one (the usual square counts) needs no list of them.
    std::vector<std::uint32_t> cells;
    if (std::size_t(gx) * gy > n) {
        cells.resize(std::size_t(gx) * gy);
        for (std::uint32_t k = 0; k < cells.size(); ++k) cells[k] = k;
        for (std::uint32_t k = 0; k < n; ++k) std::swap(cells[k], cells[k + rng.next() % (cells.size() - k)]);
    }
    out.reserve(n);
    std::uint32_t column = 0, row = 0;  // of cell k in a full grid, counted rather than divided out
    double firstU = 0.0, firstV = 0.0;  // sample k - 1's point of the unit square, when k is odd
    for (std::uint32_t k = 0; k < n; ++k) {
        std::uint32_t cx = column, cy = row;
        if (!cells.empty()) {
            cx = cells[k] % gx;
            cy = cells[k] / gx;
        } else if (++column == gx) {
            column = 0;
            ++row;
        }
        const double pointU = (cx + rng.uniform()) / gx;
        const double pointV = (cy + rng.uniform()) / gy;
        const int lane = static_cast<int>(k % 2);
        if (lane == 0) {
            firstU = pointU;
            firstV = pointV;
            if (k + 1 < n) continue;  // its pair is still to come
        }
        // Built in registers, not lane by lane through memory (which stalls
        // the load of the pair).
        const Double2 u = {firstU, pointU}, v = {firstV, pointV};
        Double2 x, y;
        if (shape_ == AreaLightShape::Disk) {
            concentricDisk(u, v, x, y);
        } else {
            x = 2.0 * u - 1.0;
            y = 2.0 * v - 1.0;
        }
        for (int l = 0; l <= lane; ++l) out.push_back({x[l] * halfWidth_, y[l] * halfHeight_, planeDepth_});
    }
}

std::vector<Vec3> AreaLight::samples(const Vec3& receiverWorld, int count, std::uint64_t seed) const {
    std::vector<Vec3> light;
    lightSpaceSamples(receiverWorld, count, seed, light);
    for (Vec3& p : light) p = lightToWorld(p);
    return light;
}

DSM_NAMESPACE_END
