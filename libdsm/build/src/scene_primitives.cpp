#include "scene_primitives.h"

#include <type_traits>
#include <variant>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using namespace detail;  // affine.h, vec3_math.h

namespace {

// Mean linear scale of an affine map (for widths of curves).
double linearScale(const Affine& m) { return std::cbrt(std::abs(determinant3(m))); }

// A quad's world axes with what its crossing test needs of them. The scene
// checked u and v non-zero and perpendicular, and the transform non-singular,
// so the normal is non-zero; should its square still round to 0 or overflow,
// the test's coordinates are not finite and no ray crosses the quad.
ScenePrimitives::Quad worldQuad(const Vec3& centre, const Vec3& u, const Vec3& v) {
    const Vec3 normal = cross(u, v);
    const double area2 = dot(normal, normal);
    return {centre, u, v, normal, scale(cross(v, normal), 1.0 / area2), scale(cross(normal, u), 1.0 / area2)};
}

}  // namespace

ScenePrimitives::ScenePrimitives(const Scene& scene) {
    // Room for every primitive first: filling the arrays as they grew copied
    // the hair ball's 120,000 segments over and over (4-5 ms before a build
    // could start). Curves have fewer segments than points.
    std::size_t triangles = 0, spheres = 0, quads = 0, segments = 0;
    for (const SceneObject& object : scene.objects)
        std::visit(
            [&](const auto& g) {
                using G = std::decay_t<decltype(g)>;
                if constexpr (std::is_same_v<G, TriangleMesh>) triangles += g.triangles.size();
                if constexpr (std::is_same_v<G, dsm::Sphere>) ++spheres;
                if constexpr (std::is_same_v<G, dsm::Quad>) ++quads;
                if constexpr (std::is_same_v<G, Curves>) segments += g.points.size();
            },
            object.geometry);
    triangles_.reserve(triangles);
    spheres_.reserve(spheres);
    quads_.reserve(quads);
    segments_.reserve(segments);
    primitives_.reserve(triangles + spheres + quads + segments);
    motion_.reserve(scene.objects.size());
    for (std::uint32_t o = 0; o < scene.objects.size(); ++o) {
        const SceneObject& object = scene.objects[o];
        const std::string what = concat("object ", o, " '", clip(object.name), "'");
        const Affine toWorld = affineOf(object.objectToWorld);
        motion_.push_back(object.motion);
        std::visit(
            [&](const auto& g) {
                using G = std::decay_t<decltype(g)>;
                if constexpr (std::is_same_v<G, TriangleMesh>) {
                    for (const auto& tri : g.triangles) {
                        for (std::uint32_t k : tri)
                            if (k >= g.positions.size())
                                throw Error(ErrorCode::scene, concat(what, ": triangle index ", k, " beyond ",
                                                                     g.positions.size(), " positions"));
                        auto world = [&](std::uint32_t k) {
                            const auto& p = g.positions[k];
                            return transformPoint(toWorld, Vec3{p[0], p[1], p[2]});
                        };
                        primitives_.push_back(
                            {PrimitiveKind::Triangle, o, static_cast<std::uint32_t>(triangles_.size())});
                        triangles_.push_back({world(tri[0]), world(tri[1]), world(tri[2])});
                    }
                } else if constexpr (std::is_same_v<G, dsm::Sphere>) {
                    primitives_.push_back({PrimitiveKind::Sphere, o, static_cast<std::uint32_t>(spheres_.size())});
                    spheres_.push_back({inverseAffine(toWorld, what), g.center, g.radius});
                } else if constexpr (std::is_same_v<G, dsm::Quad>) {
                    primitives_.push_back({PrimitiveKind::Quad, o, static_cast<std::uint32_t>(quads_.size())});
                    quads_.push_back(worldQuad(transformPoint(toWorld, g.center), transformVector(toWorld, g.halfU),
                                               transformVector(toWorld, g.halfV)));
                } else if constexpr (std::is_same_v<G, Curves>) {
                    const double widthScale = 0.5 * linearScale(toWorld);
                    std::size_t first = 0;
                    for (std::uint32_t n : g.pointsPerCurve) {
                        if (first + n > g.points.size())
                            throw Error(ErrorCode::scene,
                                        concat(what, ": curves need ", first + n, " points, have ", g.points.size()));
                        for (std::uint32_t k = 0; k + 1 < n; ++k) {
                            auto point = [&](std::size_t i) {
                                const auto& p = g.points[i];
                                return transformPoint(toWorld, Vec3{p[0], p[1], p[2]});
                            };
                            auto width = [&](std::size_t i) {
                                return (g.widths.size() == 1 ? g.widths[0] : g.widths.at(i)) * widthScale;
                            };
                            primitives_.push_back(
                                {PrimitiveKind::Segment, o, static_cast<std::uint32_t>(segments_.size())});
                            segments_.push_back({point(first + k), point(first + k + 1), width(first + k),
                                                 width(first + k + 1), k + 2 == n});
                        }
                        first += n;
                    }
                }
            },
            object.geometry);
    }
    if (primitives_.size() > UINT32_MAX / 2) throw Error(ErrorCode::limit, "scene: too many primitives");
}

Bounds3 ScenePrimitives::boundsAt(const Primitive& p, double time) const {
    Bounds3 b;
    switch (p.kind) {
        case PrimitiveKind::Triangle: {
            const Triangle& t = triangles_[p.index];
            b.grow(t.a);
            b.grow(t.b);
            b.grow(t.c);
            break;
        }
        case PrimitiveKind::Sphere: {
            // Bound the transformed sphere by transforming its object box.
            const Sphere& s = spheres_[p.index];
            const Affine toWorld = inverseAffine(s.worldToObject, "sphere");
            for (int corner = 0; corner < 8; ++corner) {
                const Vec3 q{s.centre[0] + ((corner & 1) ? s.radius : -s.radius),
                             s.centre[1] + ((corner & 2) ? s.radius : -s.radius),
                             s.centre[2] + ((corner & 4) ? s.radius : -s.radius)};
                b.grow(transformPoint(toWorld, q));
            }
            break;
        }
        case PrimitiveKind::Quad: {
            const Quad& q = quads_[p.index];
            for (double su : {-1.0, 1.0})
                for (double sv : {-1.0, 1.0}) b.grow(add(q.centre, add(scale(q.u, su), scale(q.v, sv))));
            break;
        }
        case PrimitiveKind::Segment: {
            const Segment& s = segments_[p.index];
            Bounds3 a, c;
            a.grow(s.p0);
            a.pad(s.r0);
            c.grow(s.p1);
            c.pad(s.r1);
            b.grow(a);
            b.grow(c);
            break;
        }
    }
    if (time != 0.0) {
        const Vec3 offset = scale(motion_[p.object], time);
        b.lo = add(b.lo, offset);
        b.hi = add(b.hi, offset);
    }
    return b;
}

Bounds3 ScenePrimitives::bounds(const Primitive& p) const {
    // Cover the whole shutter: the box at t = 0 and at t = 1.
    Bounds3 b = boundsAt(p, 0.0);
    if (motion_[p.object] != Vec3{0.0, 0.0, 0.0}) b.grow(boundsAt(p, 1.0));
    return b;
}

DSM_NAMESPACE_END
