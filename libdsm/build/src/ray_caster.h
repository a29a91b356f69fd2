// All-hits ray casting of a scene's surfaces (through Embree's bounding volume
// hierarchy, each primitive crossed by ScenePrimitives' exact test) and
// volumes from the light (internal). Rays are parametrised by
// light-space depth: a point at parameter t lies at depth t, so hit
// parameters are map depths directly.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "density.h"
#include "scene_primitives.h"
#include "dsm/scene.h"
#include "tested_internal.h"

DSM_NAMESPACE_BEGIN

struct RayVolumeSample {
    double t;
    double extinction;  // per unit of t (depth), perspective-corrected
};

/// World-space primitives of a scene under Embree's bounding volume hierarchy.
/// Immutable after construction and safe to use from many threads.
class DSM_TESTED_INTERNAL RayCaster {
public:
    /// Whether surfaceHits() may be called: Embree's hierarchy over the
    /// surfaces is built only when it is (the scanline sampler visits them
    /// itself).
    enum class Surfaces { hierarchy, none };
    explicit RayCaster(const Scene& scene, Surfaces surfaces = Surfaces::hierarchy);
    ~RayCaster();
    RayCaster(const RayCaster&) = delete;
    RayCaster& operator=(const RayCaster&) = delete;

    /// Every surface crossing of origin + t * direction with t > tMin at
    /// shutter time `time` in [0, 1), appended to `out` in no particular order.
    void surfaceHits(const Vec3& origin, const Vec3& direction, double time, double tMin,
                     RaySurfaceHits& out) const;

    /// Extinction samples along the ray through every volume, in increasing t,
    /// appended to `out`. Each volume is sampled every `step` world units of
    /// path length from where the ray enters its box to where it leaves; where
    /// volumes overlap their extinctions add; between disjoint stretches the
    /// extinction drops to 0 (samples of zero extinction at both ends).
    void volumeSamples(const Vec3& origin, const Vec3& direction, double time, double tMin,
                       std::vector<RayVolumeSample>& out) const;

    bool hasVolumes() const;
    std::size_t primitiveCount() const;
    const ScenePrimitives& surfaces() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
