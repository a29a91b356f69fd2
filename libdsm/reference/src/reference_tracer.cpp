// The reference tracer on Embree 3 (dsm/reference_tracer.h).
//
// One Embree device and scene per tracer. A shadow ray is one rtcOccluded1
// call whose occlusion filter, set on every geometry, records each crossing
// and rejects it, so traversal goes on to every surface on the segment; the
// filter lets a crossing stand (ending traversal) only once every channel has
// met an opaque one. The recorded crossings are de-duplicated and multiplied
// in depth order after traversal, so the answer does not depend on the order
// Embree visits them: the same bits on every thread. Spheres are user
// geometry intersected here in double precision; volumes are marched here,
// outside Embree.
#include "dsm/reference_tracer.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include "density.h"
#include "embree_device.h"
#include "dsm/error.h"
#include "affine.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

using namespace detail;  // affine.h

constexpr double kInf = std::numeric_limits<double>::infinity();
// Crossings of one object closer than this (relative to max(1, distance)) are
// one crossing reported twice: a shared edge, a curve joint, a spatial split.
constexpr double kSameCrossing = 1e-6;
// Beyond this many march steps along one ray the volume's step is unusable.
constexpr double kMaxMarchSteps = 1e8;

bool isZero(const Vec3& a) { return a[0] == 0.0 && a[1] == 0.0 && a[2] == 0.0; }
bool isFinite(const Vec3& a) { return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]); }

// Errors of the tracer's device, named as the tracer's.
void throwIfEmbreeFailed(RTCDevice device, const std::string& doing) {
    dsm::throwIfEmbreeFailed(device, "reference tracer", doing);
}

// ---- What the callbacks see ----------------------------------------------

struct GeometryInfo {
    std::uint32_t object = 0;
    Rgb opacity{1.0f, 1.0f, 1.0f};
};

struct SphereData {
    Affine worldToObject;  // at shutter time 0
    Affine objectToWorld;
    Vec3 centre;           // object space
    double radius;
    Vec3 motion;
};

struct Crossing {
    double distance;
    unsigned geometry;
    unsigned primitive;
};

// The context handed to Embree: Embree's part first, so the callbacks can
// recover the rest from the RTCIntersectContext pointer they are given.
struct TraceContext {
    RTCIntersectContext embree;
    const std::vector<GeometryInfo>* geometries = nullptr;
    // The ray in double precision (only single rays are traced).
    Vec3 origin{};
    Vec3 direction{};  // unit
    double time = 0.0;
    // Shadow rays: crossings strictly inside (0, end) are recorded.
    double end = 0.0;
    std::vector<Crossing>* crossings = nullptr;
    std::array<bool, 3> opaque{false, false, false};
    // Nearest-hit rays: the last sphere hit committed, in double precision.
    unsigned sphereGeometry = RTC_INVALID_GEOMETRY_ID;
    double sphereDistance = 0.0;
    Vec3 sphereNormal{};
};
static_assert(std::is_standard_layout_v<TraceContext>);

TraceContext& contextOf(RTCIntersectContext* context) { return *reinterpret_cast<TraceContext*>(context); }

// Records a crossing of a shadow ray; true when every channel is now blocked.
bool recordCrossing(TraceContext& c, unsigned geometry, unsigned primitive, double distance) {
    if (!(distance > 0.0 && distance < c.end)) return false;
    c.crossings->push_back({distance, geometry, primitive});
    const Rgb& opacity = (*c.geometries)[geometry].opacity;
    bool blocked = true;
    for (std::size_t k = 0; k < 3; ++k) {
        if (opacity[k] >= 1.0f) c.opaque[k] = true;
        blocked = blocked && c.opaque[k];
    }
    return blocked;
}

void occlusionFilter(const RTCFilterFunctionNArguments* args) {
    TraceContext& c = contextOf(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        const double distance = RTCRayN_tfar(args->ray, args->N, i);
        const unsigned geometry = RTCHitN_geomID(args->hit, args->N, i);
        const unsigned primitive = RTCHitN_primID(args->hit, args->N, i);
        if (!recordCrossing(c, geometry, primitive, distance)) args->valid[i] = 0;  // go on
    }
}

// Where the ray (in double precision, from the context) meets the sphere:
// distances near <= far; false when it misses.
bool sphereRoots(const SphereData& s, const TraceContext& c, double& near, double& far, Vec3& objectOrigin,
                 Vec3& objectDirection) {
    objectOrigin = sub(transformPoint(s.worldToObject, sub(c.origin, scale(s.motion, c.time))), s.centre);
    objectDirection = transformVector(s.worldToObject, c.direction);
    const double a = dot(objectDirection, objectDirection), b = dot(objectOrigin, objectDirection);
    const double cc = dot(objectOrigin, objectOrigin) - s.radius * s.radius;
    const double disc = b * b - a * cc;
    if (!(disc >= 0.0) || a == 0.0) return false;
    const double root = std::sqrt(disc);
    // Both roots without cancellation.
    const double q = b >= 0.0 ? -(b + root) : -(b - root);
    near = q / a;
    far = q != 0.0 ? cc / q : near;
    if (near > far) std::swap(near, far);
    return true;
}

void sphereBounds(const RTCBoundsFunctionArguments* args) {
    const SphereData& s = *static_cast<const SphereData*>(args->geometryUserPtr);
    const Vec3 centre = add(transformPoint(s.objectToWorld, s.centre), scale(s.motion, args->timeStep));
    const Affine& m = s.objectToWorld;
    float lo[3], hi[3];
    for (std::size_t axis = 0; axis < 3; ++axis) {
        // The ellipsoid's half-extent along a world axis is r |row of M|.
        const double* row = &m[4 * axis];
        const double half = s.radius * std::sqrt(row[0] * row[0] + row[1] * row[1] + row[2] * row[2]);
        lo[axis] = std::nextafter(static_cast<float>(centre[axis] - half), -std::numeric_limits<float>::infinity());
        hi[axis] = std::nextafter(static_cast<float>(centre[axis] + half), std::numeric_limits<float>::infinity());
    }
    RTCBounds& b = *args->bounds_o;
    b.lower_x = lo[0];
    b.lower_y = lo[1];
    b.lower_z = lo[2];
    b.upper_x = hi[0];
    b.upper_y = hi[1];
    b.upper_z = hi[2];
}

void sphereOccluded(const RTCOccludedFunctionNArguments* args) {
    const SphereData& s = *static_cast<const SphereData*>(args->geometryUserPtr);
    TraceContext& c = contextOf(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        double near, far;
        Vec3 o, d;
        if (!sphereRoots(s, c, near, far, o, d)) continue;
        if (recordCrossing(c, args->geomID, args->primID, near) ||
            (far != near && recordCrossing(c, args->geomID, args->primID, far)))
            RTCRayN_tfar(args->ray, args->N, i) = -std::numeric_limits<float>::infinity();
    }
}

void sphereIntersect(const RTCIntersectFunctionNArguments* args) {
    const SphereData& s = *static_cast<const SphereData*>(args->geometryUserPtr);
    TraceContext& c = contextOf(args->context);
    RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, args->N);
    RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, args->N);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        double near, far;
        Vec3 o, d;
        if (!sphereRoots(s, c, near, far, o, d)) continue;
        const double tnear = RTCRayN_tnear(ray, args->N, i), tfar = RTCRayN_tfar(ray, args->N, i);
        double distance = kInf;
        if (near >= tnear && near <= tfar)
            distance = near;
        else if (far >= tnear && far <= tfar)
            distance = far;
        else
            continue;
        // The object-space normal is the point on the sphere; world normals
        // transform with the inverse transpose.
        const Vec3 normal = transposedVector(s.worldToObject, add(o, scale(d, distance)));
        RTCRayN_tfar(ray, args->N, i) = static_cast<float>(distance);
        RTCHitN_Ng_x(hit, args->N, i) = static_cast<float>(normal[0]);
        RTCHitN_Ng_y(hit, args->N, i) = static_cast<float>(normal[1]);
        RTCHitN_Ng_z(hit, args->N, i) = static_cast<float>(normal[2]);
        RTCHitN_u(hit, args->N, i) = 0.0f;
        RTCHitN_v(hit, args->N, i) = 0.0f;
        RTCHitN_primID(hit, args->N, i) = args->primID;
        RTCHitN_geomID(hit, args->N, i) = args->geomID;
        RTCHitN_instID(hit, args->N, i, 0) = args->context->instID[0];
        c.sphereGeometry = args->geomID;
        c.sphereDistance = distance;
        c.sphereNormal = normal;
    }
}

struct VolumeData {
    std::uint32_t object;
    Affine worldToObject;  // at shutter time 0
    Vec3 boundsMin, boundsMax;
    std::unique_ptr<DensityField> field;
    double scale;
    double step;
    Vec3 motion;
};

}  // namespace

struct ReferenceTracer::Impl {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::vector<GeometryInfo> geometries;  // by Embree geometry id
    std::vector<std::unique_ptr<SphereData>> spheres;
    std::vector<VolumeData> volumes;
    std::size_t primitives = 0;
    int volumeStepDivisor = 8;

    ~Impl() {
        if (scene != nullptr) rtcReleaseScene(scene);
        if (device != nullptr) rtcReleaseDevice(device);
    }

    void attach(OwnedGeometry& g, std::uint32_t object, const SceneObject& o, std::size_t count,
                const std::string& what) {
        rtcCommitGeometry(g.handle);
        const unsigned id = rtcAttachGeometry(scene, g.handle);
        throwIfEmbreeFailed(device, detail::concat("on ", what));
        if (geometries.size() <= id) geometries.resize(std::size_t(id) + 1);
        geometries[id] = {object, o.opacity};
        primitives += count;
    }

    // Vertex buffers for time steps 0 and, when the object moves, 1.
    template <typename Fill>
    void vertexBuffers(OwnedGeometry& g, const SceneObject& o, RTCFormat format, std::size_t stride,
                       std::size_t count, const std::string& what, Fill fill) {
        const bool moving = !isZero(o.motion);
        if (moving) rtcSetGeometryTimeStepCount(g.handle, 2);
        for (unsigned step = 0; step < (moving ? 2u : 1u); ++step) {
            auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g.handle, RTC_BUFFER_TYPE_VERTEX, step, format,
                                                                  stride, count));
            throwIfEmbreeFailed(device, detail::concat("allocating vertices of ", what));
            fill(v, scale(o.motion, step));
        }
    }

    void addTriangles(std::uint32_t object, const SceneObject& o, const std::vector<Vec3>& world,
                      const std::vector<std::array<std::uint32_t, 3>>& triangles, const std::string& what) {
        if (triangles.empty()) return;
        OwnedGeometry g(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE));
        throwIfEmbreeFailed(device, detail::concat("creating ", what));
        vertexBuffers(g, o, RTC_FORMAT_FLOAT3, 3 * sizeof(float), world.size(), what,
                      [&](float* v, const Vec3& offset) {
                          for (const Vec3& p : world)
                              for (std::size_t a = 0; a < 3; ++a) *v++ = static_cast<float>(p[a] + offset[a]);
                      });
        auto* index = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g.handle, RTC_BUFFER_TYPE_INDEX, 0,
                                                                     RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                                     triangles.size()));
        throwIfEmbreeFailed(device, detail::concat("allocating triangles of ", what));
        for (const auto& t : triangles)
            for (std::uint32_t k : t) *index++ = k;
        rtcSetGeometryOccludedFilterFunction(g.handle, occlusionFilter);
        attach(g, object, o, triangles.size(), what);
    }

    void addMesh(std::uint32_t object, const SceneObject& o, const TriangleMesh& mesh, const std::string& what) {
        const Affine toWorld = affineOf(o.objectToWorld);
        for (const auto& t : mesh.triangles)
            for (std::uint32_t k : t)
                if (k >= mesh.positions.size())
                    throw Error(ErrorCode::scene, detail::concat(what, ": triangle index ", k, " beyond ",
                                                                 mesh.positions.size(), " positions"));
        std::vector<Vec3> world;
        world.reserve(mesh.positions.size());
        for (const auto& p : mesh.positions) world.push_back(transformPoint(toWorld, Vec3{p[0], p[1], p[2]}));
        addTriangles(object, o, world, mesh.triangles, what);
    }

    void addQuad(std::uint32_t object, const SceneObject& o, const Quad& quad, const std::string& what) {
        const Affine toWorld = affineOf(o.objectToWorld);
        const Vec3 c = transformPoint(toWorld, quad.center);
        const Vec3 u = transformVector(toWorld, quad.halfU), v = transformVector(toWorld, quad.halfV);
        const std::vector<Vec3> corners{sub(sub(c, u), v), sub(add(c, u), v), add(add(c, u), v), add(sub(c, u), v)};
        addTriangles(object, o, corners, {{0, 1, 2}, {0, 2, 3}}, what);
    }

    void addSphere(std::uint32_t object, const SceneObject& o, const Sphere& sphere, const std::string& what) {
        const Affine toWorld = affineOf(o.objectToWorld);
        spheres.push_back(std::make_unique<SphereData>(
            SphereData{inverseAffine(toWorld, what), toWorld, sphere.center, sphere.radius, o.motion}));
        OwnedGeometry g(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER));
        throwIfEmbreeFailed(device, detail::concat("creating ", what));
        rtcSetGeometryUserPrimitiveCount(g.handle, 1);
        if (!isZero(o.motion)) rtcSetGeometryTimeStepCount(g.handle, 2);
        rtcSetGeometryUserData(g.handle, spheres.back().get());
        rtcSetGeometryBoundsFunction(g.handle, sphereBounds, nullptr);
        rtcSetGeometryIntersectFunction(g.handle, sphereIntersect);
        rtcSetGeometryOccludedFunction(g.handle, sphereOccluded);
        attach(g, object, o, 1, what);
    }

    void addCurves(std::uint32_t object, const SceneObject& o, const Curves& curves, const std::string& what) {
        const Affine toWorld = affineOf(o.objectToWorld);
        if (curves.widths.size() != 1 && curves.widths.size() != curves.points.size())
            throw Error(ErrorCode::scene, detail::concat(what, ": ", curves.widths.size(), " widths for ",
                                                         curves.points.size(), " points (need 1 or one per point)"));
        std::vector<unsigned> firstOfSegment;
        std::size_t first = 0;
        for (std::uint32_t n : curves.pointsPerCurve) {
            if (first + n > curves.points.size())
                throw Error(ErrorCode::scene,
                            detail::concat(what, ": curves need ", first + n, " points, have ", curves.points.size()));
            for (std::uint32_t k = 0; k + 1 < n; ++k) firstOfSegment.push_back(static_cast<unsigned>(first + k));
            first += n;
        }
        if (firstOfSegment.empty()) return;
        // Radius = half the width, scaled by the transform's mean linear
        // scale, as the sampler's ray caster does.
        const double radiusScale = 0.5 * std::cbrt(std::abs(determinant3(toWorld)));
        OwnedGeometry g(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_FLAT_LINEAR_CURVE));
        throwIfEmbreeFailed(device, detail::concat("creating ", what));
        vertexBuffers(g, o, RTC_FORMAT_FLOAT4, 4 * sizeof(float), first, what, [&](float* v, const Vec3& offset) {
            for (std::size_t i = 0; i < first; ++i) {
                const auto& p = curves.points[i];
                const Vec3 w = add(transformPoint(toWorld, Vec3{p[0], p[1], p[2]}), offset);
                const double width = curves.widths.size() == 1 ? curves.widths[0] : curves.widths[i];
                *v++ = static_cast<float>(w[0]);
                *v++ = static_cast<float>(w[1]);
                *v++ = static_cast<float>(w[2]);
                *v++ = static_cast<float>(width * radiusScale);
            }
        });
        auto* index = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g.handle, RTC_BUFFER_TYPE_INDEX, 0,
                                                                     RTC_FORMAT_UINT, sizeof(unsigned),
                                                                     firstOfSegment.size()));
        throwIfEmbreeFailed(device, detail::concat("allocating segments of ", what));
        std::copy(firstOfSegment.begin(), firstOfSegment.end(), index);
        rtcSetGeometryOccludedFilterFunction(g.handle, occlusionFilter);
        attach(g, object, o, firstOfSegment.size(), what);
    }

    void addVolume(std::uint32_t object, const SceneObject& o, const Volume& volume, const std::string& what) {
        if (!(volume.step > 0.0))
            throw Error(ErrorCode::scene, detail::concat(what, ": volume step ", volume.step, " is not > 0"));
        volumes.push_back({object, inverseAffine(affineOf(o.objectToWorld), what), volume.boundsMin, volume.boundsMax,
                           makeDensityField(volume), volume.scale, volume.step, o.motion});
    }

    // Optical depth of one volume along from + s * delta, s in [0, 1].
    double opticalDepth(const VolumeData& v, const Vec3& from, const Vec3& delta, double length, double time) const {
        const Vec3 o = transformPoint(v.worldToObject, sub(from, scale(v.motion, time)));
        const Vec3 d = transformVector(v.worldToObject, delta);
        double s0 = 0.0, s1 = 1.0;
        for (std::size_t a = 0; a < 3; ++a) {
            if (d[a] == 0.0) {
                if (o[a] < v.boundsMin[a] || o[a] > v.boundsMax[a]) return 0.0;
                continue;
            }
            double enter = (v.boundsMin[a] - o[a]) / d[a], leave = (v.boundsMax[a] - o[a]) / d[a];
            if (enter > leave) std::swap(enter, leave);
            s0 = std::max(s0, enter);
            s1 = std::min(s1, leave);
        }
        if (!(s1 > s0)) return 0.0;
        const double step = v.step / volumeStepDivisor;
        const double steps = std::max(1.0, std::ceil((s1 - s0) * length / step));
        if (steps > kMaxMarchSteps)
            throw Error(ErrorCode::limit, detail::concat("reference tracer: volume of object ", v.object, ": ", steps,
                                                         " march steps along one ray; raise its step"));
        const auto n = static_cast<std::uint64_t>(steps);
        const double ds = (s1 - s0) / steps;
        double sum = 0.0;
        for (std::uint64_t k = 0; k < n; ++k) {
            const double s = s0 + (static_cast<double>(k) + 0.5) * ds;
            sum += std::max(0.0, v.field->density(add(o, scale(d, s))));
        }
        return sum * ds * length * v.scale;
    }
};

ReferenceTracer::ReferenceTracer(const Scene& scene, const ReferenceTracerOptions& options)
    : impl_(std::make_unique<Impl>()) {
    Impl& s = *impl_;
    if (options.volumeStepDivisor < 1)
        throw Error(ErrorCode::argument,
                    detail::concat("reference tracer: volumeStepDivisor ", options.volumeStepDivisor, " is not >= 1"));
    s.volumeStepDivisor = options.volumeStepDivisor;
    s.device = newEmbreeDevice("reference tracer");
    s.scene = rtcNewScene(s.device);
    throwIfEmbreeFailed(s.device, "creating a scene");
    // Robust: watertight edges, for an oracle rather than speed.
    rtcSetSceneFlags(s.scene, RTC_SCENE_FLAG_ROBUST);
    for (std::uint32_t o = 0; o < scene.objects.size(); ++o) {
        const SceneObject& object = scene.objects[o];
        const std::string what = detail::concat("object ", o, " '", object.name, "'");
        if (!isFinite(object.motion)) throw Error(ErrorCode::scene, detail::concat(what, ": motion is not finite"));
        std::visit(
            [&](const auto& g) {
                using G = std::decay_t<decltype(g)>;
                if constexpr (std::is_same_v<G, TriangleMesh>)
                    s.addMesh(o, object, g, what);
                else if constexpr (std::is_same_v<G, Sphere>)
                    s.addSphere(o, object, g, what);
                else if constexpr (std::is_same_v<G, Quad>)
                    s.addQuad(o, object, g, what);
                else if constexpr (std::is_same_v<G, Curves>)
                    s.addCurves(o, object, g, what);
                else if constexpr (std::is_same_v<G, Volume>)
                    s.addVolume(o, object, g, what);
            },
            object.geometry);
    }
    rtcCommitScene(s.scene);
    throwIfEmbreeFailed(s.device, "building the scene");
}

ReferenceTracer::~ReferenceTracer() = default;

std::size_t ReferenceTracer::primitiveCount() const { return impl_->primitives; }

namespace {

void checkTime(double time, const char* what) {
    if (!(time >= 0.0 && time <= 1.0))
        throw Error(ErrorCode::argument,
                    detail::concat("reference tracer: ", what, ": time ", time, " is outside [0, 1]"));
}

}  // namespace

std::array<double, 3> ReferenceTracer::transmittance(const Vec3& from, const Vec3& to, double time) const {
    const Impl& s = *impl_;
    if (!isFinite(from) || !isFinite(to))
        throw Error(ErrorCode::argument, "reference tracer: transmittance: a segment end is not finite");
    checkTime(time, "transmittance");
    const Vec3 delta = sub(to, from);
    const double length = std::sqrt(dot(delta, delta));
    if (length == 0.0) return {1.0, 1.0, 1.0};
    if (!std::isfinite(length))
        throw Error(ErrorCode::argument, "reference tracer: transmittance: the segment is too long");

    // Reused per thread: no allocation per ray once warm.
    thread_local std::vector<Crossing> crossings;
    crossings.clear();
    TraceContext c;
    rtcInitIntersectContext(&c.embree);
    c.geometries = &s.geometries;
    c.origin = from;
    c.direction = scale(delta, 1.0 / length);
    c.time = time;
    c.end = length;
    c.crossings = &crossings;
    RTCRay ray = embreeRay(from, c.direction, length, time);
    rtcOccluded1(s.scene, &c.embree, &ray);
    throwIfEmbreeFailed(s.device, "tracing a shadow ray");
    if (c.opaque[0] && c.opaque[1] && c.opaque[2]) return {0.0, 0.0, 0.0};

    // One crossing per object per place, then a fixed order for the product.
    std::sort(crossings.begin(), crossings.end(), [](const Crossing& a, const Crossing& b) {
        if (a.geometry != b.geometry) return a.geometry < b.geometry;
        if (a.distance != b.distance) return a.distance < b.distance;
        return a.primitive < b.primitive;
    });
    std::size_t kept = 0;
    for (const Crossing& x : crossings) {
        if (kept > 0) {
            const Crossing& last = crossings[kept - 1];
            if (last.geometry == x.geometry && x.distance - last.distance <= kSameCrossing * std::max(1.0, x.distance))
                continue;
        }
        crossings[kept++] = x;
    }
    crossings.resize(kept);
    std::sort(crossings.begin(), crossings.end(), [](const Crossing& a, const Crossing& b) {
        if (a.distance != b.distance) return a.distance < b.distance;
        if (a.geometry != b.geometry) return a.geometry < b.geometry;
        return a.primitive < b.primitive;
    });
    std::array<double, 3> result{1.0, 1.0, 1.0};
    for (const Crossing& x : crossings) {
        const Rgb& opacity = s.geometries[x.geometry].opacity;
        for (std::size_t k = 0; k < 3; ++k) result[k] *= 1.0 - static_cast<double>(opacity[k]);
    }
    if (result[0] == 0.0 && result[1] == 0.0 && result[2] == 0.0) return result;

    double depth = 0.0;
    for (const VolumeData& v : s.volumes) depth += s.opticalDepth(v, from, delta, length, time);
    const double volumeTransmittance = std::exp(-depth);
    for (double& r : result) r *= volumeTransmittance;
    return result;
}

std::optional<RayHit> ReferenceTracer::closestHit(const Vec3& origin, const Vec3& direction, double tMax,
                                                  double time) const {
    const Impl& s = *impl_;
    if (!isFinite(origin)) throw Error(ErrorCode::argument, "reference tracer: closestHit: the origin is not finite");
    const double length = std::sqrt(dot(direction, direction));
    if (!(length > 0.0) || !std::isfinite(length))
        throw Error(ErrorCode::argument, "reference tracer: closestHit: the direction is zero or not finite");
    if (!(tMax >= 0.0))
        throw Error(ErrorCode::argument, detail::concat("reference tracer: closestHit: tMax ", tMax, " is not >= 0"));
    checkTime(time, "closestHit");

    TraceContext c;
    rtcInitIntersectContext(&c.embree);
    c.geometries = &s.geometries;
    c.origin = origin;
    c.direction = scale(direction, 1.0 / length);
    c.time = time;
    RTCRayHit rayHit{};
    rayHit.ray = embreeRay(origin, c.direction, tMax, time);
    rayHit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rayHit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(s.scene, &c.embree, &rayHit);
    throwIfEmbreeFailed(s.device, "tracing a ray");
    if (rayHit.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;

    RayHit hit;
    hit.object = s.geometries[rayHit.hit.geomID].object;
    Vec3 normal{rayHit.hit.Ng_x, rayHit.hit.Ng_y, rayHit.hit.Ng_z};
    hit.distance = rayHit.ray.tfar;
    if (rayHit.hit.geomID == c.sphereGeometry) {  // keep the double-precision answer
        hit.distance = c.sphereDistance;
        normal = c.sphereNormal;
    }
    hit.position = add(origin, scale(c.direction, hit.distance));
    const double n = std::sqrt(dot(normal, normal));
    if (n > 0.0 && std::isfinite(n)) {
        normal = scale(normal, 1.0 / n);
        if (dot(normal, c.direction) > 0.0) normal = scale(normal, -1.0);
        hit.normal = normal;
    } else {
        hit.normal = scale(c.direction, -1.0);
    }
    return hit;
}

DSM_NAMESPACE_END
