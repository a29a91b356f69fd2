#include "dsm/soft_shadow.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <vector>

#include "depth_hierarchy.h"
#include "ray_packet.h"
#include "sorted_depths.h"
#include "dsm/auto_bias.h"
#include "dsm/error.h"
#include "reader_impl.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using detail::clipRay;
using detail::DepthRange;
using detail::firstAtOrBeyond;
using detail::RasterRay;
using detail::RayPacket;

struct SoftShadowTracer::Impl {
    std::shared_ptr<const DeepShadowMap> map;
    AreaLight light;
    std::unique_ptr<detail::DepthHierarchy> hierarchy;
    const ImplAccess::Impl<DeepShadowMap>* reader = nullptr;
};

SoftShadowTracer::SoftShadowTracer(std::shared_ptr<const DeepShadowMap> map, const AreaLight& light)
    : impl_(std::make_unique<Impl>(Impl{nullptr, light, nullptr, nullptr})) {
    if (!map) throw Error(ErrorCode::argument, "soft shadow: no map given");
    const MapInfo& info = map->info();
    if (!(light.camera() == info.camera))
        throw Error(ErrorCode::argument,
                    concat("soft shadow: '", map->path(), "': the area light was made for another light camera"));
    if (info.width == 0 || info.height == 0 || info.levels.empty())
        throw Error(ErrorCode::argument, concat("soft shadow: '", map->path(), "': the map is empty"));
    impl_->hierarchy = std::make_unique<detail::DepthHierarchy>(*map);
    impl_->reader = &ImplAccess::of(*map);
    impl_->map = std::move(map);
}

SoftShadowTracer::~SoftShadowTracer() = default;
const DeepShadowMap& SoftShadowTracer::map() const { return *impl_->map; }
const AreaLight& SoftShadowTracer::light() const { return impl_->light; }
std::size_t SoftShadowTracer::hierarchyTilesBuilt() const { return impl_->hierarchy->tilesBuilt(); }

namespace {

constexpr int kMicrocacheTiles = 8;

// Estimated samples k = 1..count of the segment (z0, z1] at depths
// z0 + k (z1 - z0) / count that lie beyond `beyond` and at or before `hi`.
// Returns how many, and the deepest in `deepest`. A ray reading a pixel
// passes beyond = the larger of the depth its earlier pixels' samples reached
// and the double below its depth range's start (so that the start itself
// counts): one comparison per test, the same for every sample.
std::uint64_t samplesInRange(double z0, double z1, std::uint64_t count, double beyond, double hi, double& deepest) {
    // Every sample, with no division: a step (all of them at z1) or a
    // segment inside the range (depth(1) >= z0 and depth(count) = z1, so the
    // search below would find them all too).
    if (z1 <= hi && std::min(z0, z1) > beyond) {
        deepest = z1;
        return count;
    }
    // None: a step not taken whole, or a segment ending before the range or
    // beginning beyond it (the most common case).
    if (z1 <= z0 || !(z1 > beyond) || z0 > hi) return 0;
    const double h = (z1 - z0) / static_cast<double>(count);
    auto depth = [&](std::uint64_t k) { return k >= count ? z1 : z0 + static_cast<double>(k) * h; };
    if (depth(1) > hi) return 0;
    // First guesses (samples per unit of depth, a division beside h's rather
    // than after it; the ceiling and floor by truncation, cheap without a
    // rounding instruction), then fixed up against the depths themselves
    // (rounding may put them one off).
    const double c = static_cast<double>(count), perDepth = c / (z1 - z0);
    auto first = static_cast<std::uint64_t>(std::clamp((beyond - z0) * perDepth, 0.0, c - 1.0)) + 1;
    while (first > 1 && depth(first - 1) > beyond) --first;
    while (first < count && !(depth(first) > beyond)) ++first;
    auto last = static_cast<std::uint64_t>(std::clamp((hi - z0) * perDepth, 1.0, c));
    while (last < count && depth(last + 1) <= hi) ++last;
    while (last > 1 && depth(last) > hi) --last;
    if (last < first || depth(last) > hi || !(depth(first) > beyond)) return 0;
    deepest = depth(last);
    return last - first + 1;
}

// Raster positions of light-space points at one depth, as
// LightCamera::lightToRaster() gives them (to rounding), with its divisions
// done once for every point at that depth.
struct RasterAtDepth {
    RasterAtDepth(const MapInfo& m, double z) {
        const auto& w = m.camera.screenWindow;
        const double kx = m.width / (w[1] - w[0]), ky = m.height / (w[3] - w[2]);
        const double perDepth = m.camera.projection == Projection::Perspective ? 1.0 / z : 1.0;
        sx = kx * perDepth;
        ox = -w[0] * kx;
        sy = -ky * perDepth;
        oy = w[3] * ky;
    }
    double x(double lightX) const { return lightX * sx + ox; }
    double y(double lightY) const { return lightY * sy + oy; }
    double sx, ox, sy, oy;
};

}  // namespace

struct SoftShadowContext::Impl {
    std::shared_ptr<const SoftShadowTracer> tracer;
    const ImplAccess::Impl<SoftShadowTracer>* shared = nullptr;
    std::unique_ptr<LookupContext> lookup;
    SoftShadowStats stats;
    std::vector<Vec3> lightSamples;

    struct CachedTile {
        std::uint32_t index = ~0u;
        std::shared_ptr<const format::DecodedTile> tile;
    };
    CachedTile microcache[kMicrocacheTiles];
    int nextVictim = 0;
    // The tile read last (held in the microcache): a ray's next pixel is
    // mostly in it.
    std::uint32_t lastIndex = ~0u;
    const format::DecodedTile* lastTile = nullptr;

    // The ray being traced.
    RasterRay ray;
    double vis[3] = {1.0, 1.0, 1.0};
    double mostVisible = 1.0;  // the largest of vis, kept as it changes
    double consumed = -std::numeric_limits<double>::infinity();
    double zThreshold = 0.0;
    double bias = 0.0;  // of the current query
    double stopBelow = 0.0;
    std::size_t layers = 1;
    bool umbraEarlyOut = true;
    SampleAttenuation attenuation = SampleAttenuation::Subtractive;

    const MapInfo& info() const { return shared->reader->info; }

    VisibilityView pixel(std::uint32_t x, std::uint32_t y) {
        const std::uint32_t T = info().tileSize;
        const std::uint32_t tx = x / T, ty = y / T;
        const std::uint32_t index = ty * info().levels[0].tilesX + tx;
        if (index != lastIndex) {
            const format::DecodedTile* tile = nullptr;
            for (const CachedTile& c : microcache)
                if (c.index == index && c.tile) tile = c.tile.get();
            if (!tile) {
                CachedTile& slot = microcache[nextVictim];
                nextVictim = (nextVictim + 1) % kMicrocacheTiles;
                slot.tile = shared->reader->getTile(0, tx, ty);  // before the index: getTile() may throw
                slot.index = index;
                tile = slot.tile.get();
            }
            lastIndex = index;
            lastTile = tile;
        }
        return lastTile->pixel(std::size_t(y % T) * lastTile->width + x % T);
    }

    void startRay() {
        vis[0] = vis[1] = vis[2] = mostVisible = 1.0;
        consumed = -std::numeric_limits<double>::infinity();
    }

    bool stopped() const {
        return mostVisible < stopBelow || (umbraEarlyOut && mostVisible <= 0.0);  // nothing left to lose
    }

    // Xie §5.2 at one pixel: the ray's depth range across it, [z(ua), z(ub)],
    // widened by the z threshold, against the estimated samples of layers < K.
    void intersectPixel(std::uint32_t x, std::uint32_t y, double ua, double ub) {
        ++stats.pixelsVisited;
        const VisibilityView f = pixel(x, y);
        if (f.empty()) return;
        double za = ray.z(ua), zb = ray.z(ub);
        if (za > zb) std::swap(za, zb);
        const double lo = za - zThreshold, hi = zb + zThreshold;
        if (f.z(0) > hi || f.z(f.size() - 1) < lo) return;
        const double beyond = std::max(consumed, std::nextafter(lo, -std::numeric_limits<double>::infinity()));
        const std::size_t layerCount = std::min(layers, f.layerCount());
        const auto depths = f.depths();
        const bool counted = f.hasCounts();
        double deepestHit = -std::numeric_limits<double>::infinity();
        for (std::size_t layer = 0; layer < layerCount && !stopped(); ++layer) {
            const std::size_t begin = f.layerBegin(layer), end = f.layerEnd(layer);
            if (begin == end || f.z(end - 1) < lo) continue;
            if (f.z(begin) > hi) break;  // layers lie in depth order
            if (umbraEarlyOut && f.z(begin) > beyond && f.z(end - 1) <= hi &&
                opaqueAt(f, end - 1)) {
                // Every sample of a layer that ends opaque: whatever the
                // attenuation rule, the drops add up to all the light.
                vis[0] = vis[1] = vis[2] = mostVisible = 0.0;
                ++stats.raysProvenOpaque;
                for (std::size_t i = begin; i < end; ++i) stats.samplesHit += counted ? f.count(i) : 1;
                return;
            }
            std::size_t i = firstAtOrBeyond(depths.data(), begin, end, lo);
            for (; i < end; ++i) {
                const double zPrev = i == begin ? f.z(begin) : f.z(i - 1);
                if (zPrev > hi) break;
                std::uint64_t count = counted ? f.count(i) : 1;
                if (count == 0) {
                    // No samples recorded; should the value still drop, let
                    // one sample carry the change rather than lose it.
                    bool drops = false;
                    for (int c = 0; c < f.channels(); ++c)
                        drops |= f.value(i, c) < (i == begin ? 1.0f : f.value(i - 1, c));
                    if (!drops) continue;
                    count = 1;
                }
                double deepest = 0.0;
                const std::uint64_t hits = samplesInRange(zPrev, f.z(i), count, beyond, hi, deepest);
                if (hits == 0) continue;
                attenuate(f, i, begin, hits, count);
                stats.samplesHit += hits;
                deepestHit = std::max(deepestHit, deepest);
                if (stopped()) break;
            }
        }
        consumed = std::max(consumed, deepestHit);
    }

    static bool opaqueAt(const VisibilityView& f, std::size_t i) {
        for (int c = 0; c < f.channels(); ++c)
            if (f.value(i, c) > 0.0f) return false;
        return true;
    }

    // The drop of each stored channel is worked out once; a monochrome
    // pixel's one drop applies to each of the ray's channels, since the ray
    // may already carry colour from RGB pixels it crossed before.
    void attenuate(const VisibilityView& f, std::size_t i, std::size_t layerBegin, std::uint64_t hits,
                   std::uint64_t count) {
        const double share = hits == count ? 1.0 : static_cast<double>(hits) / static_cast<double>(count);
        const bool multiplicative = attenuation == SampleAttenuation::Multiplicative;
        const int stored = f.channels();
        double drop[kMaxChannels] = {0.0, 0.0, 0.0};  // subtracted from, or (multiplicative) a factor of, the visibility
        for (int c = 0; c < stored; ++c) {
            const double before = i == layerBegin ? 1.0 : f.value(i - 1, c);
            const double after = f.value(i, c);
            if (!multiplicative) {
                drop[c] = (before - after) * share;
            } else if (before <= 0.0) {
                drop[c] = 1.0;  // nothing left to learn in this layer
            } else {
                const double ratio = std::clamp(after / before, 0.0, 1.0);
                drop[c] = hits == count ? ratio : std::pow(ratio, share);
            }
        }
        for (int c = 0; c < 3; ++c) {
            const double d = drop[stored == 1 ? 0 : c];
            vis[c] = multiplicative ? vis[c] * d : std::max(0.0, vis[c] - d);
        }
        mostVisible = std::max({vis[0], vis[1], vis[2]});
    }

    // Every pixel the ray crosses, in order (Amanatides & Woo).
    void walkPixels(double ua, double ub) {
        const auto W = static_cast<long>(info().width), H = static_cast<long>(info().height);
        const double sx = ray.r0x + ua * ray.drx, sy = ray.r0y + ua * ray.dry;
        long x = detail::clampedPixel(sx, info().width), y = detail::clampedPixel(sy, info().height);
        const double inf = std::numeric_limits<double>::infinity();
        const long stepX = ray.drx > 0.0 ? 1 : -1, stepY = ray.dry > 0.0 ? 1 : -1;
        double nextX = ray.drx == 0.0 ? inf : (static_cast<double>(ray.drx > 0.0 ? x + 1 : x) - ray.r0x) / ray.drx;
        double nextY = ray.dry == 0.0 ? inf : (static_cast<double>(ray.dry > 0.0 ? y + 1 : y) - ray.r0y) / ray.dry;
        const double deltaX = ray.drx == 0.0 ? inf : 1.0 / std::abs(ray.drx);
        const double deltaY = ray.dry == 0.0 ? inf : 1.0 / std::abs(ray.dry);
        double u = ua;
        for (;;) {
            const double uNext = std::min({nextX, nextY, ub});
            intersectPixel(static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y), u, std::max(u, uNext));
            if (stopped() || uNext >= ub) return;
            if (nextX < nextY) {
                x += stepX;
                nextX += deltaX;
            } else {
                y += stepY;
                nextY += deltaY;
            }
            if (x < 0 || x >= W || y < 0 || y >= H) return;
            u = std::max(u, uNext);
        }
    }

    // Xie §4.3 / §5.2 for the rays of a query at once: the packet descends
    // only into nodes whose depth range some of its rays' depth ranges meet
    // (ray_packet.h), and finds each ray's pixels; each is then clipped in
    // double and read in the order the ray crosses them, as walkPixels() reads
    // them. A ray within one pixel reads it alone.
    struct PacketRay {
        RasterRay ray;
        detail::RayInverse inverse{ray};
        double ua = 0.0, ub = 0.0;
        bool traced = false;             // crosses the map
        int lane = -1;                   // in the packet, or -1
        std::uint32_t x = 0, y = 0;      // its pixel, when it has only one
    };
    std::vector<PacketRay> packetRays;
    RasterRay laneRays[RayPacket::kLanes];
    double laneUa[RayPacket::kLanes], laneUb[RayPacket::kLanes];
    RayPacket packet;
    struct Crossed {
        double a, b;
        std::uint32_t x, y;
    };
    std::vector<Crossed> crossed;

    // Sorts out the rays of packetRays[first, first + count), count <=
    // kLanes: those that cross more than one pixel go into the packet.
    void tracePacket(std::size_t first, std::size_t count) {
        const MapInfo& m = info();
        int lanes = 0;
        for (std::size_t k = first; k < first + count; ++k) {
            PacketRay& p = packetRays[k];
            p.lane = -1;
            if (!p.traced) continue;
            const double ax = p.ray.r0x + p.ua * p.ray.drx, bx = p.ray.r0x + p.ub * p.ray.drx;
            const double ay = p.ray.r0y + p.ua * p.ray.dry, by = p.ray.r0y + p.ub * p.ray.dry;
            p.x = detail::clampedPixel(std::min(ax, bx), m.width);
            p.y = detail::clampedPixel(std::min(ay, by), m.height);
            if (p.x == detail::clampedPixel(std::max(ax, bx), m.width) &&
                p.y == detail::clampedPixel(std::max(ay, by), m.height))
                continue;
            p.lane = lanes;
            laneRays[lanes] = p.ray;
            laneUa[lanes] = p.ua;
            laneUb[lanes] = p.ub;
            ++lanes;
        }
        packet.trace(*shared->hierarchy, laneRays, laneUa, laneUb, lanes, zThreshold);
        stats.nodesVisited += packet.nodeVisits();
        // Every pixel found, its arrays asked for now: the rays read them one
        // after another, and each pixel's depths, counts and values lie in
        // separate arrays of its tile, mostly outside the first-level cache.
        for (const RayPacket::Pixel& q : packet.allPixels()) {
            const VisibilityView f = pixel(q.x, q.y);
            __builtin_prefetch(f.depths().data());
            __builtin_prefetch(f.allValues().data());
            __builtin_prefetch(f.counts().data());
        }
    }

    // Ray p (already set as `ray`) through the pixels the packet found for it.
    void walkPacketRay(const PacketRay& p) {
        const MapInfo& m = info();
        if (p.lane < 0) {
            intersectPixel(p.x, p.y, p.ua, p.ub);
            return;
        }
        crossed.clear();
        for (const RayPacket::Pixel* q = packet.pixelsBegin(p.lane); q != packet.pixelsEnd(p.lane); ++q) {
            double a = p.ua, b = p.ub;
            const double px = q->x, py = q->y;
            if (clipRay(ray, p.inverse, px, py, std::min(px + 1.0, double(m.width)), std::min(py + 1.0, double(m.height)), a,
                        b))
                crossed.push_back({a, b, q->x, q->y});
        }
        // In the order the ray crosses them (few: by insertion).
        for (std::size_t i = 1; i < crossed.size(); ++i)
            for (std::size_t j = i; j > 0 && crossed[j].a < crossed[j - 1].a; --j) std::swap(crossed[j], crossed[j - 1]);
        for (const Crossed& c : crossed) {
            intersectPixel(c.x, c.y, c.a, c.b);
            if (stopped()) return;
        }
    }

    // Curtis §3.6: the smallest stored depth the light's rays to P can meet,
    // refined twice; returns false when P is provably lit.
    bool classify(const Vec3& p, double zEnd, double& zMin) {
        const AreaLight& light = shared->light;
        const MapInfo& m = info();
        const double d = light.planeDepth();
        // Raster box of the cross-section at depth z of the cone from P to
        // the light (a rectangle bounding the light, scaled towards P).
        auto section = [&](double z, double box[4]) {
            const double s = (p[2] - z) / (p[2] - d);
            const double cx = p[0] * (1.0 - s), cy = p[1] * (1.0 - s);
            const double hx = light.halfWidth() * s, hy = light.halfHeight() * s;
            double rx0, ry0, rx1, ry1, zz;
            m.camera.lightToRaster({cx - hx, cy + hy, z}, int(m.width), int(m.height), rx0, ry0, zz);
            m.camera.lightToRaster({cx + hx, cy - hy, z}, int(m.width), int(m.height), rx1, ry1, zz);
            box[0] = std::min(box[0], std::min(rx0, rx1));
            box[1] = std::min(box[1], std::min(ry0, ry1));
            box[2] = std::max(box[2], std::max(rx0, rx1));
            box[3] = std::max(box[3], std::max(ry0, ry1));
        };
        zMin = d;
        for (int pass = 0; pass < 3; ++pass) {
            const double inf = std::numeric_limits<double>::infinity();
            double box[4] = {inf, inf, -inf, -inf};
            section(std::max(zMin - zThreshold, d), box);
            section(zEnd, box);
            const double nearest = shared->hierarchy->minDepth(box[0], box[1], box[2], box[3]);
            if (zEnd < nearest - zThreshold) return false;  // also when nothing is there (infinity)
            zMin = std::max(zMin, nearest);
        }
        return true;
    }

    void check(const Vec3& p, const SoftShadowOptions& o) const {
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            throw Error(ErrorCode::argument,
                        concat("soft shadow: receiver ", p[0], ",", p[1], ",", p[2], " is not finite"));
        if (o.samples < 1 || o.samples > (1 << 20))
            throw Error(ErrorCode::argument,
                        concat("soft shadow: sample count ", o.samples, " is not in [1, 1048576]"));
        if (o.layers && *o.layers < 1)
            throw Error(ErrorCode::argument, concat("soft shadow: layer count ", *o.layers, " is not >= 1"));
        if (!(o.zThreshold >= 0.0) || !std::isfinite(o.zThreshold))
            throw Error(ErrorCode::argument,
                        concat("soft shadow: z threshold ", o.zThreshold, " is not a finite value >= 0"));
        if (o.bias && (!(*o.bias >= 0.0) || !std::isfinite(*o.bias)))
            throw Error(ErrorCode::argument, concat("soft shadow: bias ", *o.bias, " is not a finite value >= 0"));
        if (!(o.visibilityThreshold >= 0.0 && o.visibilityThreshold <= 1.0))
            throw Error(ErrorCode::argument,
                        concat("soft shadow: visibility threshold ", o.visibilityThreshold, " is not in [0, 1]"));
    }

    /// The start of every query: checks it, counts it, projects the
    /// receiver (light space p, raster rx, ry) and sets the bias. False when
    /// the receiver is lit by rule (outside the map, or not beyond the light's
    /// plane plus the bias); result is then the answer.
    bool begin(const Vec3& world, const SoftShadowOptions& o, SoftShadowResult& result, Vec3& p, double& rx,
               double& ry) {
        check(world, o);
        ++stats.queries;
        result.channels = info().channels;
        const MapInfo& m = info();
        p = m.camera.worldToLightSpace(world);
        double z;
        if (!m.camera.lightToRaster(p, int(m.width), int(m.height), rx, ry, z)) return false;
        if (!(rx >= 0.0 && rx <= m.width && ry >= 0.0 && ry <= m.height)) return false;
        zThreshold = o.zThreshold;
        bias = o.bias ? *o.bias
                      : o.zThreshold + automaticBias(m, rx, ry, p[2],
                                                     o.normal ? std::optional<Vec3>(lightSpaceNormal(m.camera, *o.normal))
                                                              : std::nullopt);
        return p[2] - bias > shared->light.planeDepth();
    }
};

SoftShadowContext::SoftShadowContext(std::shared_ptr<const SoftShadowTracer> tracer)
    : impl_(std::make_unique<Impl>()) {
    if (!tracer) throw Error(ErrorCode::argument, "soft shadow: no tracer given");
    impl_->shared = &ImplAccess::of(*tracer);
    impl_->lookup = std::make_unique<LookupContext>(impl_->shared->map);
    impl_->tracer = std::move(tracer);
}

SoftShadowContext::~SoftShadowContext() = default;
const SoftShadowStats& SoftShadowContext::stats() const { return impl_->stats; }
void SoftShadowContext::resetStats() { impl_->stats = {}; }

SoftShadowResult SoftShadowContext::visibility(const Vec3& receiverWorld, const SoftShadowOptions& options) {
    Impl& s = *impl_;
    const MapInfo& m = s.info();
    SoftShadowResult result;
    Vec3 p;
    double prx, pry;
    if (!s.begin(receiverWorld, options, result, p, prx, pry)) return result;
    s.stopBelow = options.visibilityThreshold;
    s.attenuation = options.attenuation;
    s.umbraEarlyOut = options.umbraEarlyOut;
    s.layers = static_cast<std::size_t>(std::min(options.layers.value_or(m.maxLayers), m.maxLayers));
    const double d = s.shared->light.planeDepth();
    const double zEnd = p[2] - s.bias;
    double zStart = d;
    if (options.classification) {
        double zMin;
        if (!s.classify(p, zEnd, zMin)) {
            result.classifiedLit = true;
            ++s.stats.classifiedLit;
            return result;
        }
        zStart = std::max(d, zMin - s.zThreshold);  // Curtis §3.7: nothing to meet before this
    }

    s.shared->light.lightSpaceSamples(receiverWorld, options.samples, options.seed, s.lightSamples);
    // Each light sample's ray to P, cut to [zStart, zEnd] and to the map: its
    // ends are points at those two depths, projected with the divisions
    // done once for every ray.
    const std::size_t n = s.lightSamples.size();
    s.packetRays.resize(n);
    const RasterAtDepth start(m, zStart), end(m, zEnd);
    const double tStart = (zStart - d) / (p[2] - d), tEnd = (zEnd - d) / (p[2] - d);
    const double invZStart = 1.0 / zStart, dInvZ = 1.0 / zEnd - invZStart;
    for (std::size_t k = 0; k < n; ++k) {
        Impl::PacketRay& r = s.packetRays[k];
        r.traced = false;
        if (!(zStart < zEnd)) continue;
        const Vec3& q = s.lightSamples[k];
        const double ax = start.x(q[0] + tStart * (p[0] - q[0])), ay = start.y(q[1] + tStart * (p[1] - q[1]));
        const double bx = end.x(q[0] + tEnd * (p[0] - q[0])), by = end.y(q[1] + tEnd * (p[1] - q[1]));
        r.ray = {ax, ay, bx - ax, by - ay, invZStart, dInvZ};
        r.inverse = detail::RayInverse(r.ray);
        r.ua = 0.0;
        r.ub = 1.0;
        r.traced = clipRay(r.ray, r.inverse, 0.0, 0.0, m.width, m.height, r.ua, r.ub);
    }
    double sum[3] = {0.0, 0.0, 0.0};
    for (std::size_t first = 0; first < n; first += RayPacket::kLanes) {
        const std::size_t count = std::min<std::size_t>(RayPacket::kLanes, n - first);
        if (options.hierarchy) s.tracePacket(first, count);
        for (std::size_t k = first; k < first + count; ++k) {
            const Impl::PacketRay& r = s.packetRays[k];
            s.startRay();
            ++result.rays;
            if (r.traced) {
                s.ray = r.ray;
                if (options.hierarchy)
                    s.walkPacketRay(r);
                else
                    s.walkPixels(r.ua, r.ub);
            }
            for (int c = 0; c < 3; ++c) sum[c] += s.vis[c];
        }
    }
    s.stats.rays += static_cast<std::uint64_t>(result.rays);
    for (int c = 0; c < 3; ++c) result.v[static_cast<std::size_t>(c)] = std::clamp(sum[c] / result.rays, 0.0, 1.0);
    return result;
}

SoftShadowResult SoftShadowContext::pcfVisibility(const Vec3& receiverWorld, const SoftShadowOptions& options) {
    Impl& s = *impl_;
    const MapInfo& m = s.info();
    SoftShadowResult result;
    Vec3 p;
    double prx, pry;
    if (!s.begin(receiverWorld, options, result, p, prx, pry)) return result;
    double zBlocker;
    if (!s.classify(p, p[2] - s.bias, zBlocker)) {
        result.classifiedLit = true;
        ++s.stats.classifiedLit;
        return result;
    }
    const AreaLight& light = s.shared->light;
    const double d = light.planeDepth();
    const double r = std::max(light.halfWidth(), light.halfHeight());
    const double screen = 2.0 * r * (p[2] - zBlocker) / ((p[2] - d) * zBlocker);
    const auto& w = m.camera.screenWindow;
    const double pixelsPerUnit = std::max(m.width / (w[1] - w[0]), m.height / (w[3] - w[2]));
    LookupOptions lookup;
    lookup.filter = PixelFilter::Box;
    lookup.filterWidth = std::max(1.0, screen * pixelsPerUnit);
    lookup.bias = s.bias;
    const LookupResult l = s.lookup->raster(prx, pry, p[2], lookup);
    result.v = l.v;
    result.blockerDepth = zBlocker;
    result.filterWidth = lookup.filterWidth;
    return result;
}

DSM_NAMESPACE_END
