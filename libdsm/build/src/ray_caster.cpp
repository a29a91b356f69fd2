#include "ray_caster.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "dsm/error.h"
#include "affine.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

using namespace detail;  // affine.h

constexpr double kInf = std::numeric_limits<double>::infinity();
/// Samples one ray may take through one volume.
constexpr double kMaxStepsPerRay = 1e7;

struct Box {
    Vec3 lo{kInf, kInf, kInf};
    Vec3 hi{-kInf, -kInf, -kInf};
    void grow(const Vec3& p) {
        for (int i = 0; i < 3; ++i) {
            lo[static_cast<std::size_t>(i)] = std::min(lo[static_cast<std::size_t>(i)], p[static_cast<std::size_t>(i)]);
            hi[static_cast<std::size_t>(i)] = std::max(hi[static_cast<std::size_t>(i)], p[static_cast<std::size_t>(i)]);
        }
    }
    void grow(const Box& b) {
        if (b.lo[0] > b.hi[0]) return;  // empty
        grow(b.lo);
        grow(b.hi);
    }
    void pad(double r) {
        for (std::size_t i = 0; i < 3; ++i) {
            lo[i] -= r;
            hi[i] += r;
        }
    }
    Vec3 centre() const { return scale(add(lo, hi), 0.5); }
};

// Slab test: the parameter range [t0, t1] of the ray inside the box.
[[gnu::always_inline]] inline bool slabs(const Box& b, const Vec3& o, const Vec3& inv, double tMin, double tMax, double& t0, double& t1) {
    t0 = tMin;
    t1 = tMax;
    for (std::size_t i = 0; i < 3; ++i) {
        double a = (b.lo[i] - o[i]) * inv[i];
        double c = (b.hi[i] - o[i]) * inv[i];
        if (std::isnan(a) || std::isnan(c)) {  // ray parallel to the slab, origin on its plane
            if (o[i] < b.lo[i] || o[i] > b.hi[i]) return false;
            continue;
        }
        if (a > c) std::swap(a, c);
        t0 = std::max(t0, a);
        t1 = std::min(t1, c);
        if (t0 > t1) return false;
    }
    return true;
}

enum class Kind : std::uint8_t { Triangle, Sphere, Quad, Segment };

struct Primitive {
    Kind kind;
    std::uint32_t object;
    std::uint32_t index;
};

struct TriangleData {
    Vec3 a, b, c;
};
struct SphereData {
    Affine worldToObject;
    Vec3 centre;
    double radius;
};
struct QuadData {
    Vec3 centre, u, v;
};
struct SegmentData {
    Vec3 p0, p1;
    double r0, r1;  // half-widths
    bool last;      // the curve's last segment owns its end point
};
struct VolumeData {
    std::uint32_t object;
    Affine worldToObject;
    Box bounds;  // object space
    std::unique_ptr<DensityField> field;
    double scale;
    double step;
};

struct Node {
    Box box;
    std::uint32_t first = 0;  // leaf: first primitive; inner: left child
    std::uint32_t right = 0;  // inner: right child
    std::uint32_t count = 0;  // > 0 for a leaf
};

// Mean linear scale of an affine map (for widths of curves).
double linearScale(const Affine& m) { return std::cbrt(std::abs(determinant3(m))); }

}  // namespace

struct RayCaster::Impl {
    std::vector<Vec3> motion;  // per object
    std::vector<Primitive> primitives;
    std::vector<TriangleData> triangles;
    std::vector<SphereData> spheres;
    std::vector<QuadData> quads;
    std::vector<SegmentData> segments;
    std::vector<VolumeData> volumes;
    std::vector<Node> nodes;

    Box primitiveBox(const Primitive& p) const {
        Box b;
        switch (p.kind) {
            case Kind::Triangle: {
                const TriangleData& t = triangles[p.index];
                b.grow(t.a);
                b.grow(t.b);
                b.grow(t.c);
                break;
            }
            case Kind::Sphere: {
                // Bound the transformed sphere by transforming its object box.
                const SphereData& s = spheres[p.index];
                const Affine toWorld = inverseAffine(s.worldToObject, "sphere");
                for (int corner = 0; corner < 8; ++corner) {
                    const Vec3 q{s.centre[0] + ((corner & 1) ? s.radius : -s.radius),
                                 s.centre[1] + ((corner & 2) ? s.radius : -s.radius),
                                 s.centre[2] + ((corner & 4) ? s.radius : -s.radius)};
                    b.grow(transformPoint(toWorld, q));
                }
                break;
            }
            case Kind::Quad: {
                const QuadData& q = quads[p.index];
                for (double su : {-1.0, 1.0})
                    for (double sv : {-1.0, 1.0}) b.grow(add(q.centre, add(scale(q.u, su), scale(q.v, sv))));
                break;
            }
            case Kind::Segment: {
                const SegmentData& s = segments[p.index];
                Box a, c;
                a.grow(s.p0);
                a.pad(s.r0);
                c.grow(s.p1);
                c.pad(s.r1);
                b.grow(a);
                b.grow(c);
                break;
            }
        }
        // Cover the whole shutter: the box at t = 0 and at t = 1.
        const Vec3& m = motion[p.object];
        Box moved = b;
        moved.lo = add(moved.lo, m);
        moved.hi = add(moved.hi, m);
        b.grow(moved);
        return b;
    }

    void build() {
        if (primitives.empty()) return;
        std::vector<Box> boxes(primitives.size());
        std::vector<Vec3> centres(primitives.size());
        for (std::size_t i = 0; i < primitives.size(); ++i) {
            boxes[i] = primitiveBox(primitives[i]);
            centres[i] = boxes[i].centre();
        }
        std::vector<std::uint32_t> order(primitives.size());
        std::iota(order.begin(), order.end(), 0u);
        nodes.reserve(2 * primitives.size());
        nodes.emplace_back();
        struct Task {
            std::uint32_t node, begin, end;
        };
        std::vector<Task> stack{{0, 0, static_cast<std::uint32_t>(order.size())}};
        while (!stack.empty()) {
            const Task task = stack.back();
            stack.pop_back();
            Box box, centreBox;
            for (std::uint32_t i = task.begin; i < task.end; ++i) {
                box.grow(boxes[order[i]]);
                centreBox.grow(centres[order[i]]);
            }
            nodes[task.node].box = box;
            const std::uint32_t n = task.end - task.begin;
            std::size_t axis = 0;
            const Vec3 extent = sub(centreBox.hi, centreBox.lo);
            if (extent[1] > extent[axis]) axis = 1;
            if (extent[2] > extent[axis]) axis = 2;
            if (n <= 2 || extent[axis] <= 0.0) {
                nodes[task.node].first = task.begin;
                nodes[task.node].count = n;
                continue;
            }
            // Binned surface-area heuristic on the widest axis of the centres
            // (a good tree matters: every sample ray visits every node it
            // crosses, since it needs all hits, not the nearest).
            constexpr int kBins = 16;
            Box binBox[kBins];
            std::uint32_t binCount[kBins] = {};
            const double lo = centreBox.lo[axis], width = extent[axis];
            auto binOf = [&](std::uint32_t prim) {
                const int b = static_cast<int>((centres[prim][axis] - lo) / width * kBins);
                return std::clamp(b, 0, kBins - 1);
            };
            for (std::uint32_t i = task.begin; i < task.end; ++i) {
                const int b = binOf(order[i]);
                binBox[b].grow(boxes[order[i]]);
                ++binCount[b];
            }
            auto area = [](const Box& b) {
                if (b.lo[0] > b.hi[0]) return 0.0;
                const Vec3 e = sub(b.hi, b.lo);
                return e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
            };
            double rightArea[kBins];
            std::uint32_t rightCount[kBins];
            {
                Box acc;
                std::uint32_t count = 0;
                for (int b = kBins - 1; b > 0; --b) {
                    acc.grow(binBox[b]);
                    count += binCount[b];
                    rightArea[b] = area(acc);
                    rightCount[b] = count;
                }
            }
            double bestCost = std::numeric_limits<double>::infinity();
            int bestSplit = -1;
            {
                Box acc;
                std::uint32_t count = 0;
                for (int b = 0; b + 1 < kBins; ++b) {
                    acc.grow(binBox[b]);
                    count += binCount[b];
                    if (count == 0 || rightCount[b + 1] == 0) continue;
                    const double cost = area(acc) * count + rightArea[b + 1] * rightCount[b + 1];
                    if (cost < bestCost) {
                        bestCost = cost;
                        bestSplit = b;
                    }
                }
            }
            const double leafCost = area(box) * n;
            if (bestSplit < 0 || (n <= 4 && leafCost <= bestCost + area(box))) {
                nodes[task.node].first = task.begin;
                nodes[task.node].count = n;
                continue;
            }
            const auto middle = std::stable_partition(order.begin() + task.begin, order.begin() + task.end,
                                                      [&](std::uint32_t prim) { return binOf(prim) <= bestSplit; });
            const std::uint32_t mid = static_cast<std::uint32_t>(middle - order.begin());
            const std::uint32_t left = static_cast<std::uint32_t>(nodes.size());
            nodes.emplace_back();
            const std::uint32_t right = static_cast<std::uint32_t>(nodes.size());
            nodes.emplace_back();
            nodes[task.node].first = left;
            nodes[task.node].right = right;
            nodes[task.node].count = 0;
            stack.push_back({left, task.begin, mid});
            stack.push_back({right, mid, task.end});
        }
        std::vector<Primitive> sorted(primitives.size());
        for (std::size_t i = 0; i < order.size(); ++i) sorted[i] = primitives[order[i]];
        primitives = std::move(sorted);
    }

    void intersect(const Primitive& p, const Vec3& origin, const Vec3& d, double tMin,
                   std::vector<RaySurfaceHit>& out) const {
        switch (p.kind) {
            case Kind::Triangle: {
                const TriangleData& tri = triangles[p.index];
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
                return;
            }
            case Kind::Sphere: {
                const SphereData& s = spheres[p.index];
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
                return;
            }
            case Kind::Quad: {
                const QuadData& q = quads[p.index];
                const Vec3 n = cross(q.u, q.v);
                const double denom = dot(n, d);
                if (denom == 0.0) return;
                const double t = dot(n, sub(q.centre, origin)) / denom;
                if (!(t > tMin)) return;
                const Vec3 rel = sub(add(origin, scale(d, t)), q.centre);
                const double u = dot(rel, q.u) / dot(q.u, q.u), v = dot(rel, q.v) / dot(q.v, q.v);
                if (std::abs(u) <= 1.0 && std::abs(v) <= 1.0) out.push_back({t, p.object});
                return;
            }
            case Kind::Segment: {
                // A ribbon facing the ray: a hit where the ray passes the
                // segment's axis closer than its half-width.
                const SegmentData& s = segments[p.index];
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
                return;
            }
        }
    }
};

RayCaster::RayCaster(const Scene& scene) : impl_(std::make_unique<Impl>()) {
    Impl& s = *impl_;
    for (std::uint32_t o = 0; o < scene.objects.size(); ++o) {
        const SceneObject& object = scene.objects[o];
        const std::string what = detail::concat("object ", o, " '", detail::clip(object.name), "'");
        const Affine toWorld = affineOf(object.objectToWorld);
        s.motion.push_back(object.motion);
        std::visit(
            [&](const auto& g) {
                using G = std::decay_t<decltype(g)>;
                if constexpr (std::is_same_v<G, TriangleMesh>) {
                    for (const auto& tri : g.triangles) {
                        for (std::uint32_t k : tri)
                            if (k >= g.positions.size())
                                throw Error(ErrorCode::scene, detail::concat(what, ": triangle index ", k, " beyond ",
                                                                             g.positions.size(), " positions"));
                        auto world = [&](std::uint32_t k) {
                            const auto& p = g.positions[k];
                            return transformPoint(toWorld, Vec3{p[0], p[1], p[2]});
                        };
                        s.primitives.push_back({Kind::Triangle, o, static_cast<std::uint32_t>(s.triangles.size())});
                        s.triangles.push_back({world(tri[0]), world(tri[1]), world(tri[2])});
                    }
                } else if constexpr (std::is_same_v<G, Sphere>) {
                    s.primitives.push_back({Kind::Sphere, o, static_cast<std::uint32_t>(s.spheres.size())});
                    s.spheres.push_back({inverseAffine(toWorld, what), g.center, g.radius});
                } else if constexpr (std::is_same_v<G, Quad>) {
                    s.primitives.push_back({Kind::Quad, o, static_cast<std::uint32_t>(s.quads.size())});
                    s.quads.push_back({transformPoint(toWorld, g.center), transformVector(toWorld, g.halfU),
                                       transformVector(toWorld, g.halfV)});
                } else if constexpr (std::is_same_v<G, Curves>) {
                    const double widthScale = 0.5 * linearScale(toWorld);
                    std::size_t first = 0;
                    for (std::uint32_t n : g.pointsPerCurve) {
                        if (first + n > g.points.size())
                            throw Error(ErrorCode::scene, detail::concat(what, ": curves need ", first + n,
                                                                         " points, have ", g.points.size()));
                        for (std::uint32_t k = 0; k + 1 < n; ++k) {
                            auto point = [&](std::size_t i) {
                                const auto& p = g.points[i];
                                return transformPoint(toWorld, Vec3{p[0], p[1], p[2]});
                            };
                            auto width = [&](std::size_t i) {
                                return (g.widths.size() == 1 ? g.widths[0] : g.widths.at(i)) * widthScale;
                            };
                            s.primitives.push_back({Kind::Segment, o, static_cast<std::uint32_t>(s.segments.size())});
                            s.segments.push_back({point(first + k), point(first + k + 1), width(first + k),
                                                  width(first + k + 1), k + 2 == n});
                        }
                        first += n;
                    }
                } else if constexpr (std::is_same_v<G, Volume>) {
                    VolumeData v;
                    v.object = o;
                    v.worldToObject = inverseAffine(toWorld, what);
                    v.bounds.lo = g.boundsMin;
                    v.bounds.hi = g.boundsMax;
                    v.field = makeDensityField(g);
                    v.scale = g.scale;
                    v.step = g.step;
                    if (!(g.step > 0.0))
                        throw Error(ErrorCode::scene, detail::concat(what, ": volume step ", g.step, " is not > 0"));
                    s.volumes.push_back(std::move(v));
                }
            },
            object.geometry);
    }
    if (s.primitives.size() > UINT32_MAX / 2) throw Error(ErrorCode::limit, "scene: too many primitives");
    s.build();
}

RayCaster::~RayCaster() = default;

bool RayCaster::hasVolumes() const { return !impl_->volumes.empty(); }
std::size_t RayCaster::primitiveCount() const { return impl_->primitives.size(); }

void RayCaster::surfaceHits(const Vec3& origin, const Vec3& direction, double time, double tMin,
                            std::vector<RaySurfaceHit>& out) const {
    const Impl& s = *impl_;
    if (s.nodes.empty()) return;
    const Vec3 inv{1.0 / direction[0], 1.0 / direction[1], 1.0 / direction[2]};
    std::uint32_t stack[128];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        const Node& node = s.nodes[stack[--top]];
        double t0, t1;
        if (!slabs(node.box, origin, inv, tMin, kInf, t0, t1)) continue;
        if (node.count > 0) {
            for (std::uint32_t i = node.first; i < node.first + node.count; ++i) {
                const Primitive& p = s.primitives[i];
                const Vec3& m = s.motion[p.object];
                const Vec3 o = time != 0.0 ? sub(origin, scale(m, time)) : origin;
                s.intersect(p, o, direction, tMin, out);
            }
        } else {
            if (top + 2 > 128) throw Error(ErrorCode::internal, "ray caster: hierarchy deeper than 128 levels");
            stack[top++] = node.right;
            stack[top++] = node.first;
        }
    }
}

void RayCaster::volumeSamples(const Vec3& origin, const Vec3& direction, double time, double tMin,
                              std::vector<RayVolumeSample>& out) const {
    const Impl& s = *impl_;
    if (s.volumes.empty()) return;
    const double pathPerT = std::sqrt(dot(direction, direction));
    struct Span {
        double t0, t1;
        const VolumeData* volume;
        Vec3 o, d;  // ray in the volume's object space
    };
    std::vector<Span> spans;
    for (const VolumeData& v : s.volumes) {
        const Vec3 o = transformPoint(v.worldToObject, sub(origin, scale(s.motion[v.object], time)));
        const Vec3 d = transformVector(v.worldToObject, direction);
        const Vec3 inv{1.0 / d[0], 1.0 / d[1], 1.0 / d[2]};
        double t0, t1;
        if (slabs(v.bounds, o, inv, tMin, kInf, t0, t1) && t1 > t0) spans.push_back({t0, t1, &v, o, d});
    }
    if (spans.empty()) return;
    std::sort(spans.begin(), spans.end(), [](const Span& a, const Span& b) { return a.t0 < b.t0; });

    auto extinctionAt = [&](double t, std::size_t begin, std::size_t end) {
        double kappa = 0.0;
        for (std::size_t i = begin; i < end; ++i) {
            const Span& sp = spans[i];
            if (t < sp.t0 || t > sp.t1) continue;
            // Inside [t0, t1] the point is in the box; clamp away the rounding
            // that would put the samples on its faces (the entry and exit
            // samples) just outside, where the density reads 0.
            Vec3 p = add(sp.o, scale(sp.d, t));
            for (std::size_t a = 0; a < 3; ++a)
                p[a] = std::clamp(p[a], sp.volume->bounds.lo[a], sp.volume->bounds.hi[a]);
            const double density = sp.volume->field->density(p);
            kappa += std::max(0.0, density) * sp.volume->scale;
        }
        return kappa * pathPerT;  // per unit depth (Lokovic & Veach, footnote 3)
    };

    std::vector<double> ts;
    std::size_t g = 0;
    while (g < spans.size()) {
        // A group of overlapping spans is sampled on the union of their grids.
        std::size_t end = g + 1;
        double groupEnd = spans[g].t1;
        while (end < spans.size() && spans[end].t0 <= groupEnd) groupEnd = std::max(groupEnd, spans[end++].t1);
        ts.clear();
        for (std::size_t i = g; i < end; ++i) {
            const double dt = spans[i].volume->step / pathPerT;
            const double length = spans[i].t1 - spans[i].t0;
            // Bounded as a double: converting a count beyond 2^64 (or NaN) to
            // an integer is undefined.
            const double count = std::ceil(length / dt);
            if (!(count <= kMaxStepsPerRay))
                throw Error(ErrorCode::limit, detail::concat("volume of object ", spans[i].volume->object, ": ", count,
                                                             " steps along one ray, more than ", kMaxStepsPerRay,
                                                             "; raise its step"));
            const auto steps = static_cast<std::uint64_t>(count);
            for (std::uint64_t k = 0; k < steps; ++k) ts.push_back(spans[i].t0 + static_cast<double>(k) * dt);
            ts.push_back(spans[i].t1);
        }
        std::sort(ts.begin(), ts.end());
        ts.erase(std::unique(ts.begin(), ts.end()), ts.end());
        const double groupStart = ts.front();
        const double first = extinctionAt(groupStart, g, end);
        if (first > 0.0) out.push_back({groupStart, 0.0});
        for (double t : ts) out.push_back({t, extinctionAt(t, g, end)});
        if (out.back().extinction > 0.0) out.push_back({ts.back(), 0.0});
        g = end;
    }
}

DSM_NAMESPACE_END
