// The reference ray tracer: exact transmittance between any two points of a
// scene, traced with Embree 3. It is the accuracy oracle that soft-shadow
// lookups are measured against, not part of the map pipeline: it needs no map
// and makes no approximation beyond single-precision geometry and a
// finely stepped ray march through volumes.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>

#include "dsm/scene.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// Settings of a ReferenceTracer.
struct ReferenceTracerOptions {
    /// Volumes are integrated with the midpoint rule at a step of the
    /// volume's own `step` divided by this (>= 1). With h the step used, the
    /// error of the optical depth along a stretch of length L is at most
    /// L h^2 max|kappa''| / 24, and the transmittance's error is at most that
    /// (|exp(-a) - exp(-b)| <= |a - b| for a, b >= 0). Homogeneous media are
    /// exact. (The sampler's own march, linear between samples `step` apart,
    /// is the trapezoid rule: error up to L step^2 max|kappa''| / 12, 128
    /// times this bound at the default.)
    int volumeStepDivisor = 8;
};

/// The nearest surface along a ray.
struct RayHit {
    double distance = 0.0;              ///< world units from the ray origin
    Vec3 position{0.0, 0.0, 0.0};       ///< origin + distance * unit direction
    Vec3 normal{0.0, 0.0, 1.0};         ///< geometric normal, unit, facing the ray origin
    std::uint32_t object = 0;           ///< index into Scene::objects
};

/// All surfaces of a scene in one Embree scene, plus its volumes:
///
/// - triangle meshes, quads and planes (two triangles each), with the object's
///   transform applied; surfaces are two-sided;
/// - spheres, exact (double-precision ray-quadric intersection, under any
///   affine transform, so a non-uniformly scaled sphere is an ellipsoid);
/// - curves and hair as Embree flat linear curves: ribbons facing each ray,
///   of the scene's widths (scaled by the cube root of the transform's
///   determinant, as the sampler does). Each segment's ribbon ends in a
///   half-disc, which fills the outside of a bend where the sampler's
///   light-facing ribbons leave a gap; on the inside of a bend both tracers'
///   ribbons overlap, and a ray there crosses both. So the two agree except
///   within about a width of a bent joint;
/// - linear motion blur: an object at shutter time t is translated by
///   t * motion (Embree's two time steps, interpolated exactly);
/// - volumes, integrated by ray marching (see ReferenceTracerOptions).
///
/// Geometry other than spheres is intersected by Embree in single precision:
/// a ray within about 1e-6 (relative) of an edge may count the surface or not.
///
/// Construction is not thread-safe; after it every member is, and answers are
/// deterministic: the same query gives the same bits on every call and thread.
/// Throws dsm::Error naming the object for bad geometry (a triangle index
/// beyond the positions, curves short of points, a singular transform), the
/// density field's error for an unreadable VDB file, and Embree's message for
/// any Embree device error.
class DSM_API ReferenceTracer {
public:
    explicit ReferenceTracer(const Scene& scene, const ReferenceTracerOptions& options = {});
    ~ReferenceTracer();
    ReferenceTracer(const ReferenceTracer&) = delete;
    ReferenceTracer& operator=(const ReferenceTracer&) = delete;

    /// Transmittance per channel (R, G, B, each in [0, 1]) along the open
    /// segment from `from` to `to` at shutter time `time` in [0, 1]:
    ///
    ///   product over every surface crossing with 0 < distance < |to - from|
    ///   of (1 - the object's opacity), times exp(-integral of extinction).
    ///
    /// Every crossing counts, in any order (rejected by an occlusion filter so
    /// traversal goes on), except that crossings of one object less than
    /// 1e-6 * max(1, distance) apart are counted once: a ray through the shared
    /// edge of two triangles (the diagonal of a quad, a joint of a curve) is
    /// reported by both, and counts once. Hence also two sheets of one object
    /// closer than that count once. Returns 0 in every channel as soon as each
    /// channel meets an opaque crossing (without marching volumes).
    ///
    /// A point on a surface (such as RayHit::position) may see that surface at
    /// a tiny distance by rounding: move it off the surface first.
    /// Throws dsm::Error for non-finite points or a time outside [0, 1]; `from`
    /// equal to `to` gives 1.
    std::array<double, 3> transmittance(const Vec3& from, const Vec3& to, double time = 0.0) const;

    /// The nearest surface crossing of the ray origin + s * direction with
    /// 0 <= s <= tMax (s in world units: `direction` need not be unit length;
    /// tMax may be infinite), at shutter time `time` in [0, 1]. Surfaces of
    /// any opacity count (even 0: a receiver that casts no shadow); volumes do
    /// not. Empty when nothing is hit. Throws dsm::Error for a non-finite
    /// origin, a zero or non-finite direction, a negative or NaN tMax, or a
    /// time outside [0, 1].
    std::optional<RayHit> closestHit(const Vec3& origin, const Vec3& direction, double tMax,
                                     double time = 0.0) const;

    /// Number of Embree primitives (triangles, curve segments, spheres).
    std::size_t primitiveCount() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
