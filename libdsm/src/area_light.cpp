#include "dsm/area_light.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <charconv>
#include <optional>
#include <system_error>
#include <bit>
#include <cmath>
#include <numbers>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

std::uint64_t mix(std::uint64_t z) {
    z ^= z >> 30;
    z *= 0xBF58476D1CE4E5B9ull;
    z ^= z >> 27;
    z *= 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

// SplitMix64: tiny, fast, and good enough for jitter.
class Random {
public:
    explicit Random(std::uint64_t seed) : state_(seed) {}
    std::uint64_t next() { return mix(state_ += 0x9E3779B97F4A7C15ull); }
    double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

private:
    std::uint64_t state_;
};

// Shirley & Chiu's concentric map from [0,1)^2 to the unit disk: keeps
// neighbouring strata neighbours, unlike the polar map.
void concentricDisk(double u, double v, double& x, double& y) {
    const double a = 2.0 * u - 1.0, b = 2.0 * v - 1.0;
    if (a == 0.0 && b == 0.0) {
        x = y = 0.0;
        return;
    }
    double r, phi;
    if (std::abs(a) > std::abs(b)) {
        r = a;
        phi = (std::numbers::pi / 4.0) * (b / a);
    } else {
        r = b;
        phi = (std::numbers::pi / 2.0) - (std::numbers::pi / 4.0) * (a / b);
    }
    x = r * std::cos(phi);
    y = r * std::sin(phi);
}

}  // namespace

AreaLight AreaLight::make(const LightCamera& camera, AreaLightShape shape, double halfWidth, double halfHeight,
                          std::optional<double> givenPlaneDepth) {
    camera.validate();
    const char* what = shape == AreaLightShape::Disk ? "disk" : "rectangle";
    if (camera.projection != Projection::Perspective)
        throw Error(concat("area light: the ", what, " needs a perspective (spot) light camera"));
    if (!(halfWidth > 0.0) || !(halfHeight > 0.0) || !std::isfinite(halfWidth) || !std::isfinite(halfHeight))
        throw Error(concat("area light: ", what, " size ", halfWidth, " x ", halfHeight, " is not finite and > 0"));
    const auto& w = camera.screenWindow;
    // Half-angles (as tangents) of the frustum about the axis, per axis.
    const double tanX = std::min(w[1], -w[0]), tanY = std::min(w[3], -w[2]);
    if (!(tanX > 0.0) || !(tanY > 0.0))
        throw Error(concat("area light: the light camera's window [", w[0], ", ", w[1], "] x [", w[2], ", ", w[3],
                           "] does not contain its axis"));
    const double fit = std::max(halfWidth / tanX, halfHeight / tanY);  // smallest plane depth that fits
    const double planeDepth = givenPlaneDepth.value_or(fit);
    if (!std::isfinite(planeDepth))
        throw Error(concat("area light: plane depth ", planeDepth, " is not finite"));
    // A light wider than the frustum at its plane sends rays the map never saw.
    if (planeDepth < fit * (1.0 - 1e-9))
        throw Error(concat("area light: the ", what, " (half-size ", halfWidth, " x ", halfHeight,
                           ") does not fit the map's frustum at plane depth ", planeDepth, " (needs >= ", fit,
                           "): the map was built for a smaller area light"));

    // Inverse of the affine world-to-light matrix, by the adjugate.
    const auto& m = camera.worldToLight;
    const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], k = m[10];
    const double det = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g);
    if (!(std::abs(det) > 1e-300) || !std::isfinite(det))
        throw Error("area light: the light camera's world-to-light matrix is singular");
    const double inv[9] = {(e * k - f * h) / det, (c * h - b * k) / det, (b * f - c * e) / det,
                           (f * g - d * k) / det, (a * k - c * g) / det, (c * d - a * f) / det,
                           (d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det};
    const double t[3] = {m[3], m[7], m[11]};

    AreaLight light;
    light.camera_ = camera;
    light.shape_ = shape;
    light.halfWidth_ = halfWidth;
    light.halfHeight_ = halfHeight;
    light.planeDepth_ = planeDepth;
    for (int r = 0; r < 3; ++r) {
        for (int col = 0; col < 3; ++col) light.lightToWorld_[4 * r + col] = inv[3 * r + col];
        light.lightToWorld_[4 * r + 3] = -(inv[3 * r] * t[0] + inv[3 * r + 1] * t[1] + inv[3 * r + 2] * t[2]);
    }
    return light;
}

AreaLight AreaLight::disk(const LightCamera& camera, double radius, std::optional<double> planeDepth) {
    return make(camera, AreaLightShape::Disk, radius, radius, planeDepth);
}

AreaLight AreaLight::rectangle(const LightCamera& camera, double halfWidth, double halfHeight,
                               std::optional<double> planeDepth) {
    return make(camera, AreaLightShape::Rectangle, halfWidth, halfHeight, planeDepth);
}

AreaLightSize AreaLightSize::parse(std::string_view text) {
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
    throw Error(concat("area light '", text, "': expected disk:R or rect:W,H with sizes > 0 (light-space units)"));
}

double AreaLight::recordedRadius(const MapInfo& info) {
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
        throw Error("area light: the map records no area-light radius (build it from a scene whose light has "
                    "area_radius); its light is a point");
    return make(info.camera, shape, halfWidth, shape == AreaLightShape::Disk ? halfWidth : halfHeight,
                disk(info.camera, built).planeDepth());
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
    if (count < 1) throw Error(concat("area light: sample count ", count, " is not >= 1"));
    if (!std::isfinite(receiver[0]) || !std::isfinite(receiver[1]) || !std::isfinite(receiver[2]))
        throw Error(concat("area light: receiver ", receiver[0], ",", receiver[1], ",", receiver[2], " is not finite"));
    // Seeded by the receiver's bits (+0.0 and -0.0 alike), so the samples of
    // a point never change between frames or threads.
    std::uint64_t s = mix(seed ^ 0x5DEECE66Dull);
    for (double q : receiver) s = mix(s ^ std::bit_cast<std::uint64_t>(q == 0.0 ? 0.0 : q));
    Random rng(s);
    const auto n = static_cast<std::uint32_t>(count);
    const std::uint32_t gy = std::max(1u, static_cast<std::uint32_t>(std::floor(std::sqrt(double(n)))));
    const std::uint32_t gx = (n + gy - 1) / gy;
    std::vector<std::uint32_t> cells(std::size_t(gx) * gy);
    for (std::uint32_t k = 0; k < cells.size(); ++k) cells[k] = k;
    if (cells.size() > n)
        for (std::uint32_t k = 0; k < n; ++k) std::swap(cells[k], cells[k + rng.next() % (cells.size() - k)]);
    out.reserve(n);
    for (std::uint32_t k = 0; k < n; ++k) {
        const double u = (cells[k] % gx + rng.uniform()) / gx;
        const double v = (cells[k] / gx + rng.uniform()) / gy;
        double x, y;
        if (shape_ == AreaLightShape::Disk) {
            concentricDisk(u, v, x, y);
        } else {
            x = 2.0 * u - 1.0;
            y = 2.0 * v - 1.0;
        }
        out.push_back({x * halfWidth_, y * halfHeight_, planeDepth_});
    }
}

std::vector<Vec3> AreaLight::samples(const Vec3& receiverWorld, int count, std::uint64_t seed) const {
    std::vector<Vec3> light;
    lightSpaceSamples(receiverWorld, count, seed, light);
    for (Vec3& p : light) p = lightToWorld(p);
    return light;
}

DSM_NAMESPACE_END
