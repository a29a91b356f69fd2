#include "ray_caster.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <type_traits>

#include "dsm/error.h"
#include "affine.h"
#include "embree_device.h"
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

// Embree's bounds and ribbons are floats, and so is the ray it traverses
// with: every box and ribbon is widened by this much of the scene's size (its
// largest coordinate), far more than the rounding of the ray's origin
// (rebased onto the scene's box), direction, time, the vertices and their
// interpolation over the shutter (all of order 1e-7 of it), so that Embree
// reaches every primitive the exact test in double precision crosses.
constexpr double kBoxSlack = 1e-5;

// Embree ignores a ribbon's crossing nearer its ray's origin than a multiple
// of the ribbon's radius (EMBREE_CURVE_SELF_INTERSECTION_AVOIDANCE_FACTOR,
// measured 2 with Debian's Embree 3.13), to spare a ray leaving a strand the
// strand itself. These rays leave no strand, so Embree's ray starts this many
// of the widest ribbon's radii (twice that factor) before the scene's box.
constexpr double kRibbonRadiiBeforeTheBox = 4.0;

constexpr const char* kWho = "ray caster";  // in Embree's errors

// Primitives of one object as one Embree geometry: hair as Embree's own
// ray-facing ribbons, widened by `pad` (found through oriented boxes around
// the strands, far tighter than axis-aligned ones around diagonal hair),
// other surfaces, and hair segments whose half-width reaches their length,
// as user geometry (boxes). Embree's primitive k is all()[members[k]].
struct ObjectGeometry {
    const ScenePrimitives* surfaces;
    const std::uint32_t* members;
    double pad;
    const Primitive& primitive(unsigned k) const { return surfaces->all()[members[k]]; }
};

// Whether hair segment `s` goes to Embree as a box rather than a ribbon.
// Embree's ribbons are made for strands; for a segment about a thousand times
// wider than long its hierarchy was seen to pass over crossings the exact
// test finds (for some ray origins, not for others). As a box, the exact
// test decides every ray that reaches it.
bool wideSegment(const ScenePrimitives::Segment& s) {
    const Vec3 axis = sub(s.p1, s.p0);
    const double widest = std::max(s.r0, s.r1);
    return widest * widest >= dot(axis, axis);
}

// The context handed to Embree: Embree's part first, so the callbacks can
// recover the rest from the RTCIntersectContext pointer they are given.
struct HitContext {
    RTCIntersectContext embree;
    // The ray in double precision, as the caller gave it.
    Vec3 origin{}, direction{};
    double time = 0.0;
    double tMin = 0.0;
    RaySurfaceHits* out = nullptr;
};
static_assert(std::is_standard_layout_v<HitContext>);

void primitiveBounds(const RTCBoundsFunctionArguments* args) {
    const ObjectGeometry& g = *static_cast<const ObjectGeometry*>(args->geometryUserPtr);
    const Primitive& p = g.primitive(args->primID);
    // Time step 1 (a moving object's only other one) is the shutter's end.
    Bounds3 b = g.surfaces->boundsAt(p, static_cast<double>(args->timeStep));
    b.pad(g.pad);
    constexpr float kFloatInf = std::numeric_limits<float>::infinity();
    RTCBounds& o = *args->bounds_o;
    o.lower_x = std::nextafter(static_cast<float>(b.lo[0]), -kFloatInf);
    o.lower_y = std::nextafter(static_cast<float>(b.lo[1]), -kFloatInf);
    o.lower_z = std::nextafter(static_cast<float>(b.lo[2]), -kFloatInf);
    o.upper_x = std::nextafter(static_cast<float>(b.hi[0]), kFloatInf);
    o.upper_y = std::nextafter(static_cast<float>(b.hi[1]), kFloatInf);
    o.upper_z = std::nextafter(static_cast<float>(b.hi[2]), kFloatInf);
}

// Records every crossing and never reports one to Embree, so that its ray
// stays unbounded and traversal goes on to every primitive (all hits). The
// crossing itself is the exact double-precision test the scanline sampler
// makes, on the caller's ray rather than Embree's float copy.
void primitiveHits(const RTCIntersectFunctionNArguments* args) {
    const ObjectGeometry& g = *static_cast<const ObjectGeometry*>(args->geometryUserPtr);
    const HitContext& c = *reinterpret_cast<const HitContext*>(args->context);
    const Primitive& p = g.primitive(args->primID);
    for (unsigned i = 0; i < args->N; ++i)
        if (args->valid[i] != 0) g.surfaces->intersect(p, c.origin, c.direction, c.time, c.tMin, *c.out);
}

// The same for a widened ribbon Embree's float test met: the exact test on
// the segment decides, and Embree is told to go on.
void segmentHits(const RTCFilterFunctionNArguments* args) {
    const ObjectGeometry& g = *static_cast<const ObjectGeometry*>(args->geometryUserPtr);
    const HitContext& c = *reinterpret_cast<const HitContext*>(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        const Primitive& p = g.primitive(RTCHitN_primID(args->hit, args->N, i));
        g.surfaces->intersect(p, c.origin, c.direction, c.time, c.tMin, *c.out);
        args->valid[i] = 0;
    }
}

}  // namespace

struct RayCaster::Impl {
    explicit Impl(const Scene& scene) : surfaces(scene) {}
    ~Impl() {
        if (embreeScene != nullptr) rtcReleaseScene(embreeScene);
        if (device != nullptr) rtcReleaseDevice(device);
    }
    Impl(const Impl&) = delete;
    Impl& operator=(const Impl&) = delete;

    ScenePrimitives surfaces;
    std::vector<VolumeData> volumes;
    RTCDevice device = nullptr;
    RTCScene embreeScene = nullptr;
    std::vector<ObjectGeometry> geometries;
    std::vector<std::vector<std::uint32_t>> members;  // of each geometry (ObjectGeometry::members)
    Bounds3 sceneBox;  // every surface over the shutter, padded like the primitives
    double pad = 0.0;
    // How far before the scene's box Embree's ray starts: the pad, and room
    // for Embree's nearest ribbon crossings (kRibbonRadiiBeforeTheBox).
    double startBeforeTheBox = 0.0;

    // Segments `segments` as Embree ribbons of two vertices each, at the
    // shutter's start and, when they move, its end; every radius is widened
    // by `pad`, so that Embree's float test meets every segment the exact
    // test crosses (the widening is orders beyond the rounding).
    void addRibbons(OwnedGeometry& g, const std::vector<std::uint32_t>& segments, const Vec3& motion, bool moving,
                    const std::string& what) {
        const auto& primitives = surfaces.all();
        const std::size_t count = segments.size();
        for (unsigned step = 0; step < (moving ? 2u : 1u); ++step) {
            auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g.handle, RTC_BUFFER_TYPE_VERTEX, step,
                                                                  RTC_FORMAT_FLOAT4, 4 * sizeof(float), 2 * count));
            throwIfEmbreeFailed(device, kWho, detail::concat("allocating the vertices of ", what));
            const Vec3 offset = scale(motion, static_cast<double>(step));
            for (std::uint32_t i : segments) {
                const ScenePrimitives::Segment& s = surfaces.segment(primitives[i]);
                for (const auto& [point, radius] : {std::pair{s.p0, s.r0}, std::pair{s.p1, s.r1}}) {
                    for (std::size_t a = 0; a < 3; ++a) *v++ = static_cast<float>(point[a] + offset[a]);
                    *v++ = static_cast<float>(radius + pad);
                }
            }
        }
        auto* index = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g.handle, RTC_BUFFER_TYPE_INDEX, 0,
                                                                     RTC_FORMAT_UINT, sizeof(unsigned), count));
        throwIfEmbreeFailed(device, kWho, detail::concat("allocating the segments of ", what));
        for (std::size_t k = 0; k < count; ++k) index[k] = static_cast<unsigned>(2 * k);
    }

    // One Embree geometry of `object`'s primitives `list`: ribbons, or boxes
    // crossed by the exact test.
    void addGeometry(std::uint32_t object, std::vector<std::uint32_t> list, bool ribbons, const std::string& what) {
        const Vec3& m = surfaces.motion(object);
        const bool moving = m[0] != 0.0 || m[1] != 0.0 || m[2] != 0.0;
        members.push_back(std::move(list));
        const std::vector<std::uint32_t>& mine = members.back();
        geometries.push_back({&surfaces, mine.data(), pad});
        OwnedGeometry g(rtcNewGeometry(device, ribbons ? RTC_GEOMETRY_TYPE_FLAT_LINEAR_CURVE : RTC_GEOMETRY_TYPE_USER));
        throwIfEmbreeFailed(device, kWho, detail::concat("creating the geometry of ", what));
        if (moving) rtcSetGeometryTimeStepCount(g.handle, 2);
        rtcSetGeometryUserData(g.handle, &geometries.back());
        if (ribbons) {
            addRibbons(g, mine, m, moving, what);
            rtcSetGeometryIntersectFilterFunction(g.handle, segmentHits);
        } else {
            rtcSetGeometryUserPrimitiveCount(g.handle, static_cast<unsigned>(mine.size()));
            rtcSetGeometryBoundsFunction(g.handle, primitiveBounds, nullptr);
            rtcSetGeometryIntersectFunction(g.handle, primitiveHits);
        }
        rtcCommitGeometry(g.handle);
        rtcAttachGeometry(embreeScene, g.handle);
        throwIfEmbreeFailed(device, kWho, detail::concat("on ", what));
    }

    // Embree's hierarchy over the surfaces: one geometry per object (two for
    // hair with wide segments), with a second time step for a moving one
    // (its boxes follow it).
    void build(const Scene& scene) {
        const auto& primitives = surfaces.all();
        if (primitives.empty()) return;
        for (const Primitive& p : primitives) sceneBox.grow(surfaces.bounds(p));
        double size = 0.0;
        for (std::size_t a = 0; a < 3; ++a) size = std::max({size, std::abs(sceneBox.lo[a]), std::abs(sceneBox.hi[a])});
        pad = kBoxSlack * size + std::numeric_limits<double>::min();
        sceneBox.pad(pad);
        double widestRibbon = 0.0;  // radius as Embree is given it

        device = newEmbreeDevice(kWho);
        embreeScene = rtcNewScene(device);
        throwIfEmbreeFailed(device, kWho, "creating a scene");
        // Robust traversal: conservative box tests, so no primitive in reach is skipped.
        rtcSetSceneFlags(embreeScene, RTC_SCENE_FLAG_ROBUST);
        std::size_t objects = 0;
        for (std::size_t i = 0; i < primitives.size(); ++i)
            if (i == 0 || primitives[i].object != primitives[i - 1].object) ++objects;
        geometries.reserve(2 * objects);  // the geometries point at their entries
        members.reserve(2 * objects);
        for (std::size_t first = 0; first < primitives.size();) {
            const std::uint32_t object = primitives[first].object;
            std::size_t end = first + 1;
            while (end < primitives.size() && primitives[end].object == object) ++end;
            const std::string what = detail::concat("object ", object, " '", detail::clip(scene.objects[object].name), "'");
            std::vector<std::uint32_t> ribbons, boxes;
            for (std::size_t i = first; i < end; ++i) {
                const Primitive& p = primitives[i];
                const ScenePrimitives::Segment* s = p.kind == PrimitiveKind::Segment ? &surfaces.segment(p) : nullptr;
                const bool ribbon = s != nullptr && !wideSegment(*s);
                (ribbon ? ribbons : boxes).push_back(static_cast<std::uint32_t>(i));
                if (ribbon) widestRibbon = std::max(widestRibbon, std::max(s->r0, s->r1) + pad);
            }
            if (!ribbons.empty()) addGeometry(object, std::move(ribbons), true, what);
            if (!boxes.empty()) addGeometry(object, std::move(boxes), false, what);
            first = end;
        }
        startBeforeTheBox = pad + kRibbonRadiiBeforeTheBox * widestRibbon;  // read only by surfaceHits()
        rtcCommitScene(embreeScene);
        throwIfEmbreeFailed(device, kWho, "building the hierarchy");
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
    if (surfaces == Surfaces::hierarchy) s.build(scene);
}

RayCaster::~RayCaster() = default;

bool RayCaster::hasVolumes() const { return !impl_->volumes.empty(); }
std::size_t RayCaster::primitiveCount() const { return impl_->surfaces.size(); }
const ScenePrimitives& RayCaster::surfaces() const { return impl_->surfaces; }

void RayCaster::surfaceHits(const Vec3& origin, const Vec3& direction, double time, double tMin,
                            RaySurfaceHits& out) const {
    const Impl& s = *impl_;
    if (s.embreeScene == nullptr) return;
    const Vec3 inv{1.0 / direction[0], 1.0 / direction[1], 1.0 / direction[2]};
    double t0, t1;
    if (!slabs(s.sceneBox, origin, inv, tMin, kInf, t0, t1)) return;
    // Embree's ray starts where this one enters the scene's box, so that its
    // rounding to floats is relative to the scene's size, not to the origin's
    // distance; the crossings' parameters are computed on the original ray.
    // It starts a little before, so that crossings just beyond tMin lie
    // well inside Embree's [0, infinity) whatever its float arithmetic, and
    // Embree does not pass over ribbons near its ray's origin.
    const Vec3 start = add(origin, scale(direction, t0 - s.startBeforeTheBox / std::sqrt(dot(direction, direction))));
    RTCRayHit rayHit{};
    rayHit.ray = embreeRay(start, direction, std::numeric_limits<double>::infinity(), std::clamp(time, 0.0, 1.0));
    rayHit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    HitContext c;
    rtcInitIntersectContext(&c.embree);
    c.origin = origin;
    c.direction = direction;
    c.time = time;
    c.tMin = tMin;
    c.out = &out;
    rtcIntersect1(s.embreeScene, &c.embree, &rayHit);
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
