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

// Slab test: the parameter range [t0, t1] of the ray inside the box.
[[gnu::always_inline]] inline bool slabs(const Bounds3& b, const Vec3& o, const Vec3& inv, double tMin, double tMax, double& t0, double& t1) {
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

struct VolumeData {
    std::uint32_t object;
    Affine worldToObject;
    Bounds3 bounds;  // object space
    std::unique_ptr<DensityField> field;
    double scale;
    double step;
};

struct Node {
    Bounds3 box;
    std::uint32_t first = 0;  // leaf: first primitive; inner: left child
    std::uint32_t right = 0;  // inner: right child
    std::uint32_t count = 0;  // > 0 for a leaf
};

}  // namespace

struct RayCaster::Impl {
    explicit Impl(const Scene& scene) : surfaces(scene) {}

    ScenePrimitives surfaces;
    std::vector<VolumeData> volumes;
    std::vector<Node> nodes;

    void build() {
        std::vector<Primitive>& primitives = surfaces.all();
        if (primitives.empty()) return;
        std::vector<Bounds3> boxes(primitives.size());
        std::vector<Vec3> centres(primitives.size());
        for (std::size_t i = 0; i < primitives.size(); ++i) {
            boxes[i] = surfaces.bounds(primitives[i]);
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
            Bounds3 box, centreBounds;
            for (std::uint32_t i = task.begin; i < task.end; ++i) {
                box.grow(boxes[order[i]]);
                centreBounds.grow(centres[order[i]]);
            }
            nodes[task.node].box = box;
            const std::uint32_t n = task.end - task.begin;
            std::size_t axis = 0;
            const Vec3 extent = sub(centreBounds.hi, centreBounds.lo);
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
            Bounds3 binBounds[kBins];
            std::uint32_t binCount[kBins] = {};
            const double lo = centreBounds.lo[axis], width = extent[axis];
            auto binOf = [&](std::uint32_t prim) {
                const int b = static_cast<int>((centres[prim][axis] - lo) / width * kBins);
                return std::clamp(b, 0, kBins - 1);
            };
            for (std::uint32_t i = task.begin; i < task.end; ++i) {
                const int b = binOf(order[i]);
                binBounds[b].grow(boxes[order[i]]);
                ++binCount[b];
            }
            auto area = [](const Bounds3& b) {
                if (b.lo[0] > b.hi[0]) return 0.0;
                const Vec3 e = sub(b.hi, b.lo);
                return e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
            };
            double rightArea[kBins];
            std::uint32_t rightCount[kBins];
            {
                Bounds3 acc;
                std::uint32_t count = 0;
                for (int b = kBins - 1; b > 0; --b) {
                    acc.grow(binBounds[b]);
                    count += binCount[b];
                    rightArea[b] = area(acc);
                    rightCount[b] = count;
                }
            }
            double bestCost = std::numeric_limits<double>::infinity();
            int bestSplit = -1;
            {
                Bounds3 acc;
                std::uint32_t count = 0;
                for (int b = 0; b + 1 < kBins; ++b) {
                    acc.grow(binBounds[b]);
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

};

RayCaster::RayCaster(const Scene& scene, Surfaces surfaces) : impl_(std::make_unique<Impl>(scene)) {
    Impl& s = *impl_;
    for (std::uint32_t o = 0; o < scene.objects.size(); ++o) {
        const SceneObject& object = scene.objects[o];
        const auto* g = std::get_if<Volume>(&object.geometry);
        if (!g) continue;
        const std::string what = detail::concat("object ", o, " '", detail::clip(object.name), "'");
        VolumeData v;
        v.object = o;
        v.worldToObject = inverseAffine(affineOf(object.objectToWorld), what);
        v.bounds.lo = g->boundsMin;
        v.bounds.hi = g->boundsMax;
        v.field = makeDensityField(*g);
        v.scale = g->scale;
        v.step = g->step;
        if (!(g->step > 0.0)) throw Error(ErrorCode::scene, detail::concat(what, ": volume step ", g->step, " is not > 0"));
        s.volumes.push_back(std::move(v));
    }
    if (surfaces == Surfaces::hierarchy) s.build();
}

RayCaster::~RayCaster() = default;

bool RayCaster::hasVolumes() const { return !impl_->volumes.empty(); }
std::size_t RayCaster::primitiveCount() const { return impl_->surfaces.size(); }
const ScenePrimitives& RayCaster::surfaces() const { return impl_->surfaces; }

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
            const std::vector<Primitive>& primitives = s.surfaces.all();
            for (std::uint32_t i = node.first; i < node.first + node.count; ++i)
                s.surfaces.intersect(primitives[i], origin, direction, time, tMin, out);
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
        const Vec3 o = transformPoint(v.worldToObject, sub(origin, scale(s.surfaces.motion(v.object), time)));
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
