// A scene's surfaces as world-space primitives (internal): triangles, spheres,
// quads and hair segments (ribbons facing the ray), each moving with its
// object, and the exact crossing of a ray with each. Shared by the ray
// caster (through Embree's hierarchy) and the scanline hider, so that a
// sample finds the same crossings whichever visits the primitives.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "affine.h"
#include "dsm/scene.h"
#include "dsm/transmittance.h"
#include "huge_pages.h"
#include "tested_internal.h"

DSM_NAMESPACE_BEGIN

/// An axis-aligned box; empty (lo > hi) until grown.
struct Bounds3 {
    static constexpr double kInf = std::numeric_limits<double>::infinity();
    Vec3 lo{kInf, kInf, kInf};
    Vec3 hi{-kInf, -kInf, -kInf};

    bool empty() const { return lo[0] > hi[0]; }
    void grow(const Vec3& p) {
        for (std::size_t i = 0; i < 3; ++i) {
            lo[i] = std::min(lo[i], p[i]);
            hi[i] = std::max(hi[i], p[i]);
        }
    }
    void grow(const Bounds3& b) {
        if (b.empty()) return;
        grow(b.lo);
        grow(b.hi);
    }
    void pad(double r) {
        for (std::size_t i = 0; i < 3; ++i) {
            lo[i] -= r;
            hi[i] += r;
        }
    }
};

/// One surface crossing of a ray: its parameter (light depth) and object.
struct RaySurfaceHit {
    double t;
    std::uint32_t object;
};
/// Crossings as ScenePrimitives::intersect() and RayCaster::surfaceHits()
/// append them: a ray's few, or a whole tile's (on huge pages once large).
using RaySurfaceHits = detail::LargeVector<RaySurfaceHit>;

/// The crossing as the sampler keeps it: its depth as a float and its
/// object's opacity (`opacity` holds each object's, by object index).
inline SurfaceHit samplerHit(const RaySurfaceHit& h, std::span<const Rgb> opacity) {
    const Rgb& o = opacity[h.object];
    return SurfaceHit{static_cast<float>(h.t), {o[0], o[1], o[2]}};
}

enum class PrimitiveKind : std::uint8_t { Triangle, Sphere, Quad, Segment };

struct Primitive {
    PrimitiveKind kind;
    std::uint32_t object;
    std::uint32_t index;  ///< into the array of its kind
};

class DSM_TESTED_INTERNAL ScenePrimitives {
public:
    struct Triangle {
        Vec3 a, b, c;
    };
    struct Sphere {
        detail::Affine worldToObject;
        Vec3 centre;
        double radius;
    };
    // The image of the scene's rectangle: a parallelogram in the world when
    // the transform shears or scales its axes unequally. A point centre + a u
    // + b v of its plane has a = (point - centre) . acrossU and b likewise,
    // whether or not u and v are perpendicular.
    struct Quad {
        Vec3 centre, u, v;
        Vec3 normal;            // u x v
        Vec3 acrossU, acrossV;  // (v x normal) / |normal|^2, (normal x u) / |normal|^2
    };
    struct Segment {
        Vec3 p0, p1;
        double r0, r1;  // half-widths
        bool last;      // the curve's last segment owns its end point
    };

    /// The surfaces of every object (volumes are left to the ray caster).
    /// Throws dsm::Error (scene) for indices beyond a mesh's positions or a
    /// curve's points, and for singular transforms.
    explicit ScenePrimitives(const Scene& scene);

    /// Every primitive; an object's primitives are consecutive, in object order.
    const detail::LargeVector<Primitive>& all() const { return primitives_; }
    std::size_t size() const { return primitives_.size(); }

    /// The hair segment `p` is (p.kind == PrimitiveKind::Segment).
    const Segment& segment(const Primitive& p) const { return segments_[p.index]; }

    /// Asks the processor for hair segment `p`'s data ahead of its use.
    void prefetchSegment(const Primitive& p) const {
        const char* at = reinterpret_cast<const char*>(&segments_[p.index]);
        __builtin_prefetch(at);
        __builtin_prefetch(at + sizeof(Segment) - 1);
    }

    /// How far an object moves over the shutter (its linear motion), per object index.
    const Vec3& motion(std::uint32_t object) const { return motion_[object]; }

    /// World bounds over the whole shutter: at time 0 and moved to time 1.
    Bounds3 bounds(const Primitive& p) const;

    /// World bounds at shutter time `time` (moved by its object's motion times `time`).
    Bounds3 boundsAt(const Primitive& p, double time) const;

    /// Appends every crossing of origin + t * direction with t > tMin at
    /// shutter time `time` in [0, 1) (the object's motion is undone on the
    /// ray's origin).
    [[gnu::always_inline]] void intersect(const Primitive& p, const Vec3& origin, const Vec3& direction, double time,
                                          double tMin, RaySurfaceHits& out) const {
        const Vec3& m = motion_[p.object];
        const Vec3 o = time != 0.0 ? detail::sub(origin, detail::scale(m, time)) : origin;
        switch (p.kind) {
            case PrimitiveKind::Triangle: return intersectTriangle(p, o, direction, tMin, out);
            case PrimitiveKind::Sphere: return intersectSphere(p, o, direction, tMin, out);
            case PrimitiveKind::Quad: return intersectQuad(p, o, direction, tMin, out);
            case PrimitiveKind::Segment: return intersectSegment(p, o, direction, tMin, out);
        }
    }

private:
    void intersectTriangle(const Primitive& p, const Vec3& origin, const Vec3& d, double tMin,
                           RaySurfaceHits& out) const {
        using namespace detail;
        const Triangle& tri = triangles_[p.index];
        const Vec3 e1 = sub(tri.b, tri.a), e2 = sub(tri.c, tri.a);
        const Vec3 pv = cross(d, e2);
        const double det = dot(e1, pv);
        if (det == 0.0) return;
        const double inv = 1.0 / det;
        const Vec3 tv = sub(origin, tri.a);
        const double u = dot(tv, pv) * inv;
        if (u < 0.0 || u > 1.0) return;
        const Vec3 qv = cross(tv, e1);
        const double v = dot(d, qv) * inv;
        if (v < 0.0 || u + v > 1.0) return;
        const double t = dot(e2, qv) * inv;
        if (t > tMin) out.push_back({t, p.object});
    }

    void intersectSphere(const Primitive& p, const Vec3& origin, const Vec3& d, double tMin,
                         RaySurfaceHits& out) const {
        using namespace detail;
        const Sphere& s = spheres_[p.index];
        const Vec3 o = sub(transformPoint(s.worldToObject, origin), s.centre);
        const Vec3 dd = transformVector(s.worldToObject, d);
        const double a = dot(dd, dd), b = dot(o, dd), c = dot(o, o) - s.radius * s.radius;
        const double disc = b * b - a * c;
        if (disc < 0.0 || a == 0.0) return;
        const double root = std::sqrt(disc);
        // Two roots computed without cancellation.
        const double q = b >= 0.0 ? -(b + root) : -(b - root);
        double t0 = q / a, t1 = q != 0.0 ? c / q : t0;
        if (t0 > t1) std::swap(t0, t1);
        if (t0 > tMin) out.push_back({t0, p.object});
        if (t1 > tMin && t1 != t0) out.push_back({t1, p.object});
    }

    void intersectQuad(const Primitive& p, const Vec3& origin, const Vec3& d, double tMin,
                       RaySurfaceHits& out) const {
        using namespace detail;
        const Quad& q = quads_[p.index];
        const double denom = dot(q.normal, d);
        if (denom == 0.0) return;
        const double t = dot(q.normal, sub(q.centre, origin)) / denom;
        if (!(t > tMin)) return;
        const Vec3 rel = sub(add(origin, scale(d, t)), q.centre);
        const double a = dot(rel, q.acrossU), b = dot(rel, q.acrossV);
        if (std::abs(a) <= 1.0 && std::abs(b) <= 1.0) out.push_back({t, p.object});
    }

    // A ribbon facing the ray: a hit where the ray passes the segment's axis
    // closer than its half-width.
    void intersectSegment(const Primitive& p, const Vec3& origin, const Vec3& d, double tMin,
                          RaySurfaceHits& out) const {
        using namespace detail;
        const Segment& s = segments_[p.index];
        const Vec3 v = sub(s.p1, s.p0), w0 = sub(origin, s.p0);
        const double a = dot(d, d), b = dot(d, v), c = dot(v, v), dd = dot(d, w0), e = dot(v, w0);
        const double den = a * c - b * b;
        if (!(den > 1e-300 * a * c) || c == 0.0) return;  // parallel to the ray
        const double t = (b * e - c * dd) / den;
        const double sParam = (a * e - b * dd) / den;
        if (sParam < 0.0 || sParam > 1.0 || (sParam == 1.0 && !s.last)) return;
        if (!(t > tMin)) return;
        const Vec3 gap = sub(add(origin, scale(d, t)), add(s.p0, scale(v, sParam)));
        const double r = s.r0 + sParam * (s.r1 - s.r0);
        if (dot(gap, gap) < r * r) out.push_back({t, p.object});
    }

    std::vector<Vec3> motion_;  // per object
    detail::LargeVector<Primitive> primitives_;
    detail::LargeVector<Triangle> triangles_;
    detail::LargeVector<Sphere> spheres_;
    detail::LargeVector<Quad> quads_;
    detail::LargeVector<Segment> segments_;
};

DSM_NAMESPACE_END
