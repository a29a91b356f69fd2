// Area lights centred on a map's light, and the light samples a soft-shadow
// query traces (Xie et al. 2007 §4, §6.2; Curtis 2009 §3.1).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/vec3.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

enum class AreaLightShape : std::uint8_t { Disk = 0, Rectangle = 1 };

/// A light's shape and half-sizes.
struct DSM_API AreaLightSize {
    AreaLightShape shape = AreaLightShape::Disk;
    double halfWidth = 0.0;
    double halfHeight = 0.0;
};

/// A flat light centred on the light axis of a perspective map, in the plane
/// light-space z = planeDepth() and facing along +z.
///
/// Where the light lies
///   A map built for an area light of radius R (scene `area_radius`, see
///   spec/scene.md §3.2) has its projection centre pushed back by d behind
///   the light's centre, so the light's plane is light-space z = d and the map
///   sees whatever any point of the light sees. A map of format 1.1 records R
///   and d in its header (MapInfo::areaLightRadius, areaLightPlaneDepth); for
///   older maps d follows from the LightCamera and the radius the map was
///   built for, d = R / min(xmax, -xmin, ymax, -ymin) (the same formula as
///   dsm::lightCamera). The factories derive it that way unless `planeDepth`
///   is given (needed when the light is smaller than the one the map was built
///   for, since the plane stays where the map's push-back put it).
///
/// Units
///   Sizes are in light-space units (world units for the rigid cameras of
///   dsm::lightCamera).
///
/// Samples
///   samples() stratifies N points over the light: a gx x gy grid, gy =
///   floor(sqrt(N)), gx = ceil(N / gy), one jittered point per cell (when the
///   grid has more cells than N, N cells chosen at random), mapped to the disk
///   by Shirley & Chiu's concentric map (which keeps the strata compact). The
///   random numbers are seeded by the receiver point's bits and `seed`, so a
///   receiver always gets the same samples (images do not crawl) and the
///   reference tracer can trace exactly the rays the map query traces.
///
/// Thread safety: immutable once made; every const member may be called from
/// any number of threads at once.
class DSM_API AreaLight {
public:
    /// A disk of `radius` > 0. Without `planeDepth` the push-back is derived
    /// from `camera` for this radius. Throws dsm::Error when the camera is not
    /// perspective, does not contain its own axis, or the light does not fit
    /// inside the map's frustum at its plane (the map was built for a smaller
    /// light, or without `area_radius`).
    static AreaLight disk(const LightCamera& camera, double radius, std::optional<double> planeDepth = std::nullopt);
    /// A rectangle with half-sizes along light-space x and y, both > 0. The
    /// derived push-back is the smallest that fits it:
    /// max(halfWidth / min(xmax, -xmin), halfHeight / min(ymax, -ymin)).
    static AreaLight rectangle(const LightCamera& camera, double halfWidth, double halfHeight,
                               std::optional<double> planeDepth = std::nullopt);

    /// A light of the given shape and half-sizes for a map, placed where the
    /// map's build put its light: the plane depth follows from the area-light
    /// radius recorded in the map's metadata (settings.area_light_radius,
    /// written by buildMap; or the light's area_radius in the scene JSON the
    /// map keeps). Throws dsm::Error when the map records no radius (its
    /// projection centre is the point light itself, so no light plane lies in
    /// its frustum: build it with the light's area_radius, or give disk() or
    /// rectangle() a plane depth) or when the light does not fit the map
    /// (callers add the file's name).
    static AreaLight forMap(const MapInfo& info, AreaLightShape shape, double halfWidth, double halfHeight);
    static AreaLight forMap(const MapInfo& info, const AreaLightSize& size) {
        return forMap(info, size.shape, size.halfWidth, size.halfHeight);
    }
    /// The area-light radius a map was built for (0 when it records none).
    static double recordedRadius(const MapInfo& info);

    AreaLightShape shape() const { return shape_; }
    /// Half-size along light x (the radius of a disk).
    double halfWidth() const { return halfWidth_; }
    /// Half-size along light y (the radius of a disk).
    double halfHeight() const { return halfHeight_; }
    /// Light-space z of the light's plane (the push-back d).
    double planeDepth() const { return planeDepth_; }
    double area() const;
    const LightCamera& camera() const { return camera_; }

    /// The light's centre, in world space.
    Vec3 centerWorld() const { return lightToWorld({0.0, 0.0, planeDepth_}); }
    /// Light space to world space (the inverse of camera().worldToLight).
    Vec3 lightToWorld(const Vec3& light) const;

    /// `count` >= 1 stratified sample positions on the light for a receiver at
    /// `receiverWorld`, in world space. Deterministic in (receiver, count,
    /// seed). Throws dsm::Error for count < 1 or a non-finite receiver.
    std::vector<Vec3> samples(const Vec3& receiverWorld, int count, std::uint64_t seed = 1) const;
    /// The same samples in light space (z = planeDepth()), appended to `out`
    /// after clearing it.
    void lightSpaceSamples(const Vec3& receiverWorld, int count, std::uint64_t seed, std::vector<Vec3>& out) const;

private:
    AreaLight() = default;
    static AreaLight make(const LightCamera& camera, AreaLightShape shape, double halfWidth, double halfHeight,
                          std::optional<double> planeDepth);

    LightCamera camera_;
    AreaLightShape shape_ = AreaLightShape::Disk;
    double halfWidth_ = 0.0;
    double halfHeight_ = 0.0;
    double planeDepth_ = 0.0;
    std::array<double, 12> lightToWorld_{};  // row-major 3x4
};

DSM_NAMESPACE_END
