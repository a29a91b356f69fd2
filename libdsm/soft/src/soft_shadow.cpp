#include "dsm/soft_shadow.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <vector>

#include "depth_hierarchy.h"
#include "dsm/auto_bias.h"
#include "dsm/error.h"
#include "reader_impl.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using detail::DepthRange;

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

// A ray between two light-space points, as its raster image r(u) = r0 + u dr,
// u in [0, 1], with 1/z linear in u (perspective-correct depth).
struct RasterRay {
    double r0x = 0.0, r0y = 0.0, drx = 0.0, dry = 0.0;
    double invZ0 = 0.0, dInvZ = 0.0;
    double z(double u) const { return 1.0 / (invZ0 + u * dInvZ); }
};

// Clips [ua, ub] to the part of the ray inside the closed box; false if none.
bool clip(const RasterRay& r, double x0, double y0, double x1, double y1, double& ua, double& ub) {
    auto slab = [&](double origin, double direction, double lo, double hi) {
        if (direction == 0.0) return origin >= lo && origin <= hi;
        double t0 = (lo - origin) / direction, t1 = (hi - origin) / direction;
        if (t0 > t1) std::swap(t0, t1);
        ua = std::max(ua, t0);
        ub = std::min(ub, t1);
        return true;
    };
    return slab(r.r0x, r.drx, x0, x1) && slab(r.r0y, r.dry, y0, y1) && ua <= ub;
}

// Estimated samples k = 1..count of the segment (z0, z1] at depths
// z0 + k (z1 - z0) / count that lie in [lo, hi] and beyond `consumed`.
// Returns how many, and the deepest in `deepest`.
std::uint64_t samplesInRange(double z0, double z1, std::uint64_t count, double lo, double hi, double consumed,
                             double& deepest) {
    const bool strict = consumed >= lo;
    const double from = strict ? consumed : lo;
    auto after = [&](double d) { return strict ? d > from : d >= from; };
    if (z1 <= z0) {  // a step: every sample at z1
        if (z1 > hi || !after(z1)) return 0;
        deepest = z1;
        return count;
    }
    const double h = (z1 - z0) / static_cast<double>(count);
    auto depth = [&](std::uint64_t k) { return k >= count ? z1 : z0 + static_cast<double>(k) * h; };
    if (!after(z1) || depth(1) > hi) return 0;
    // First guesses by division, then fixed up against the depths themselves
    // (rounding may put them one off).
    const double c = static_cast<double>(count);
    auto first = static_cast<std::uint64_t>(std::clamp(std::ceil((from - z0) / h), 1.0, c));
    while (first > 1 && after(depth(first - 1))) --first;
    while (first < count && !after(depth(first))) ++first;
    auto last = static_cast<std::uint64_t>(std::clamp(std::floor((hi - z0) / h), 1.0, c));
    while (last < count && depth(last + 1) <= hi) ++last;
    while (last > 1 && depth(last) > hi) --last;
    if (last < first || depth(last) > hi || !after(depth(first))) return 0;
    deepest = depth(last);
    return last - first + 1;
}

// The ray's progress along one raster axis of the quadtree walk's frame,
// set up once per ray: where it is in each half of a node split at `middle`.
struct RayAcrossAxis {
    bool fixed;       // the ray (almost) does not move along this axis
    float low, high;  // its span along the axis when fixed
    float origin, inverseStep, slack;
    int firstHalf;  // the half the ray is in before it crosses a middle

    // The ray's parameters [a[i], b[i]] within half i of the stretch [ta, tb]
    // (empty when a > b); returns where it enters the second half (-inf when fixed).
    float split(float ta, float tb, float middle, float a[2], float b[2]) const {
        constexpr float inf = std::numeric_limits<float>::infinity();
        if (fixed) {
            a[0] = a[1] = ta;
            b[0] = low <= middle ? tb : -inf;
            b[1] = high >= middle ? tb : -inf;
            return -inf;
        }
        const float t = (middle - origin) * inverseStep;
        a[firstHalf] = ta;
        b[firstHalf] = std::min(tb, t + slack);
        a[1 - firstHalf] = std::max(ta, t - slack);
        b[1 - firstHalf] = tb;
        return a[1 - firstHalf];
    }
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

    // The ray being traced.
    RasterRay ray;
    double vis[3] = {1.0, 1.0, 1.0};
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
        const format::DecodedTile* tile = nullptr;
        for (const CachedTile& c : microcache)
            if (c.index == index && c.tile) tile = c.tile.get();
        if (!tile) {
            CachedTile& slot = microcache[nextVictim];
            nextVictim = (nextVictim + 1) % kMicrocacheTiles;
            slot.index = index;
            slot.tile = shared->reader->getTile(0, tx, ty);
            tile = slot.tile.get();
        }
        return tile->pixel(std::size_t(y % T) * tile->width + x % T);
    }

    bool stopped() const {
        const double most = std::max({vis[0], vis[1], vis[2]});
        return most < stopBelow || (umbraEarlyOut && most <= 0.0);  // nothing left to lose
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
        const std::size_t layerCount = std::min(layers, f.layerCount());
        const auto depths = f.depths();
        const bool counted = f.hasCounts();
        double deepestHit = -std::numeric_limits<double>::infinity();
        for (std::size_t layer = 0; layer < layerCount && !stopped(); ++layer) {
            const std::size_t begin = f.layerBegin(layer), end = f.layerEnd(layer);
            if (begin == end || f.z(end - 1) < lo) continue;
            if (f.z(begin) > hi) break;  // layers lie in depth order
            if (umbraEarlyOut && f.z(begin) >= lo && f.z(begin) > consumed && f.z(end - 1) <= hi &&
                opaqueAt(f, end - 1)) {
                // Every sample of a layer that ends opaque: whatever the
                // attenuation rule, the drops add up to all the light.
                vis[0] = vis[1] = vis[2] = 0.0;
                ++stats.raysProvenOpaque;
                for (std::size_t i = begin; i < end; ++i) stats.samplesHit += counted ? f.count(i) : 1;
                return;
            }
            std::size_t i = static_cast<std::size_t>(
                std::lower_bound(depths.begin() + static_cast<std::ptrdiff_t>(begin),
                                 depths.begin() + static_cast<std::ptrdiff_t>(end), lo,
                                 [](float zk, double q) { return zk < q; }) -
                depths.begin());
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
                const std::uint64_t hits = samplesInRange(zPrev, f.z(i), count, lo, hi, consumed, deepest);
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

    // A monochrome pixel's one value applies to each of the ray's channels:
    // the ray may already carry colour from RGB pixels it crossed before.
    void attenuate(const VisibilityView& f, std::size_t i, std::size_t layerBegin, std::uint64_t hits,
                   std::uint64_t count) {
        const double share = static_cast<double>(hits) / static_cast<double>(count);
        const bool mono = f.channels() == 1;
        for (int c = 0; c < 3; ++c) {
            const int stored = mono ? 0 : c;
            const double before = i == layerBegin ? 1.0 : f.value(i - 1, stored);
            const double after = f.value(i, stored);
            auto& v = vis[c];
            if (attenuation == SampleAttenuation::Multiplicative) {
                if (before <= 0.0) continue;  // nothing left to learn in this layer
                const double ratio = std::clamp(after / before, 0.0, 1.0);
                v *= hits == count ? ratio : std::pow(ratio, share);
            } else {
                v = std::max(0.0, v - (before - after) * share);
            }
        }
    }

    // Every pixel the ray crosses, in order (Amanatides & Woo).
    void walkPixels(double ua, double ub) {
        const auto W = static_cast<long>(info().width), H = static_cast<long>(info().height);
        const double sx = ray.r0x + ua * ray.drx, sy = ray.r0y + ua * ray.dry;
        long x = std::clamp(static_cast<long>(std::floor(sx)), 0L, W - 1);
        long y = std::clamp(static_cast<long>(std::floor(sy)), 0L, H - 1);
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

    // Xie §4.3 / §5.2: descend only into nodes whose depth range the ray's
    // depth range meets, children in the order the ray enters them, starting
    // at the level g where the ray's raster box spans at most 2 x 2 nodes
    // (Curtis §3.5), not at the root: a ray shortened by the classification
    // covers only a few pixels. In single precision, relative to the corner
    // of those 2 x 2 nodes and to u = ua: per node two products give the
    // inverse depths at the ends of its stretch of the ray and two more the
    // children's stretches, where the ray crosses the node's middle column
    // and row (no division, no libm call). Each stretch is widened by a few
    // ulps, so rounding can add a pixel but never lose one; each pixel
    // reached is clipped again in double, so the pixels the ray crosses get
    // the same stretch as in walkPixels.
    void walkHierarchy(double ua, double ub) {
        const detail::DepthHierarchy& hierarchy = *shared->hierarchy;
        const MapInfo& m = info();
        const double ax = ray.r0x + ua * ray.drx, bx = ray.r0x + ub * ray.drx;
        const double ay = ray.r0y + ua * ray.dry, by = ray.r0y + ub * ray.dry;
        const auto pixel = [](double v, std::uint32_t n) {
            return std::min(static_cast<std::uint32_t>(std::max(0.0, std::floor(v))), n - 1);
        };
        const std::uint32_t px0 = pixel(std::min(ax, bx), m.width), px1 = pixel(std::max(ax, bx), m.width);
        const std::uint32_t py0 = pixel(std::min(ay, by), m.height), py1 = pixel(std::max(ay, by), m.height);
        const int g0 = std::min(static_cast<int>(std::bit_width(std::max(px1 - px0, py1 - py0))), hierarchy.topLevel());
        if (g0 == 0) {
            intersectPixel(px0, py0, ua, ub);
            return;
        }
        const int tileLevel = hierarchy.tileLevel();
        // The frame: the corner of the 2 x 2 nodes of level g0 from (bx0, by0).
        const std::uint32_t bx0 = px0 >> g0, by0 = py0 >> g0;
        const double fx = static_cast<double>(std::uint64_t{bx0} << g0), fy = static_cast<double>(std::uint64_t{by0} << g0);
        const auto ox = static_cast<float>(ax - fx), oy = static_cast<float>(ay - fy);
        const auto dx = static_cast<float>(ray.drx), dy = static_cast<float>(ray.dry);
        const auto length = static_cast<float>(ub - ua);
        // Rounding bounds: positions in the frame are below 2^(g0+2), so a few
        // ulps of that in raster units; inverse depths a few ulps of their
        // largest term.
        const float delta = 2e-6f * static_cast<float>(std::uint64_t{1} << g0);
        const bool alongY = std::abs(dx) * length <= delta, alongX = std::abs(dy) * length <= delta;
        const float invDx = alongY ? 0.0f : 1.0f / dx, invDy = alongX ? 0.0f : 1.0f / dy;
        const float slackX = delta * std::abs(invDx) + 1e-6f * length, slackY = delta * std::abs(invDy) + 1e-6f * length;
        // A ray (almost) parallel to an axis: its span across that axis.
        const float xLow = std::min(ox, ox + dx * length) - delta, xHigh = std::max(ox, ox + dx * length) + delta;
        const float yLow = std::min(oy, oy + dy * length) - delta, yHigh = std::max(oy, oy + dy * length) + delta;
        const auto w0 = static_cast<float>(ray.invZ0 + ua * ray.dInvZ), dw = static_cast<float>(ray.dInvZ);
        const float wError = 1e-6f * (std::abs(w0) + std::abs(dw) * length);
        const auto W = static_cast<float>(static_cast<double>(m.width) - fx);
        const auto H = static_cast<float>(static_cast<double>(m.height) - fy);
        const auto zT = static_cast<float>(zThreshold);
        const float inf = std::numeric_limits<float>::infinity();
        // The column (row) the ray is in before it crosses a node's middle.
        const int c0 = dx > 0.0f ? 0 : 1, r0 = dy > 0.0f ? 0 : 1;
        const RayAcrossAxis acrossX{alongY, xLow, xHigh, ox, invDx, slackX, c0};
        const RayAcrossAxis acrossY{alongX, yLow, yHigh, oy, invDy, slackY, r0};

        struct Node {
            float ta, tb;
            std::uint32_t x, y;
            int g;
        };
        Node stack[4 * 66];
        int top = 0;
        // Pushes the children (x + i, y + j) of level g of a stretch
        // [ta, tb], split at the middle (xm, ym) in the frame.
        const auto split = [&](float ta, float tb, float xm, float ym, std::uint32_t x, std::uint32_t y, int g) {
            float colA[2], colB[2], rowA[2], rowB[2];
            // Where the ray enters the second column (row).
            const float tx = acrossX.split(ta, tb, xm, colA, colB);
            const float ty = acrossY.split(ta, tb, ym, rowA, rowB);
            if (xm >= W) colB[1] = -inf;  // beyond the map's edge
            if (ym >= H) rowB[1] = -inf;
            const auto push = [&](int i, int j) {
                const float a = std::max(colA[i], rowA[j]), b = std::min(colB[i], rowB[j]);
                if (a <= b) stack[top++] = {a, b, x + static_cast<std::uint32_t>(i), y + static_cast<std::uint32_t>(j), g};
            };
            // Entered in the order: first column and row, then the crossing
            // that comes first, then the other; pushed last-first.
            push(1 - c0, 1 - r0);
            if (tx <= ty) {
                push(c0, 1 - r0);
                push(1 - c0, r0);
            } else {
                push(1 - c0, r0);
                push(c0, 1 - r0);
            }
            push(c0, r0);
        };
        const auto size = static_cast<float>(std::uint64_t{1} << g0);
        split(0.0f, length, size, size, bx0, by0, g0);

        const detail::DepthHierarchy::TilePyramid* tile = nullptr;  // the tile (tileX, tileY)
        std::uint32_t tileX = ~0u, tileY = ~0u;
        while (top > 0) {
            const Node e = stack[--top];
            if (e.g == 0) {
                double a = ua, b = ub;
                const double px = e.x, py = e.y;
                if (clip(ray, px, py, std::min(px + 1.0, double(m.width)), std::min(py + 1.0, double(m.height)), a, b)) {
                    intersectPixel(e.x, e.y, a, b);
                    if (stopped()) return;
                }
                continue;
            }
            ++stats.nodesVisited;
            DepthRange range;
            if (e.g >= tileLevel) {
                range = hierarchy.gridNode(e.g, e.x, e.y);
            } else {
                const int shift = tileLevel - e.g;
                const std::uint32_t tx = e.x >> shift, ty = e.y >> shift;
                if (tx != tileX || ty != tileY) {
                    tile = &hierarchy.tilePyramid(tx, ty);
                    tileX = tx;
                    tileY = ty;
                }
                range = tile->at(e.g, e.x - (tx << shift), e.y - (ty << shift));
            }
            if (range.empty()) continue;
            // The ray meets [min - zT, max + zT] where its depth 1/w does:
            // 1/wMin >= lo and 1/wMax <= hi, w > 0.
            const float wa = w0 + e.ta * dw, wb = w0 + e.tb * dw;
            const float wMin = std::min(wa, wb) - wError, wMax = std::max(wa, wb) + wError;
            if (wMin * (range.min - zT) > 1.0f + 1e-5f || wMax * (range.max + zT) < 1.0f - 1e-5f) continue;
            const int cg = e.g - 1;
            split(e.ta, e.tb, static_cast<float>(static_cast<double>(std::uint64_t{2 * e.x + 1} << cg) - fx),
                  static_cast<float>(static_cast<double>(std::uint64_t{2 * e.y + 1} << cg) - fy), 2 * e.x, 2 * e.y, cg);
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
    double sum[3] = {0.0, 0.0, 0.0};
    for (const Vec3& q : s.lightSamples) {
        s.vis[0] = s.vis[1] = s.vis[2] = 1.0;
        s.consumed = -std::numeric_limits<double>::infinity();
        ++result.rays;
        if (zStart < zEnd) {
            // The ray from the light sample q to P, cut to [zStart, zEnd].
            auto at = [&](double z) {
                const double t = (z - d) / (p[2] - d);
                return Vec3{q[0] + t * (p[0] - q[0]), q[1] + t * (p[1] - q[1]), z};
            };
            double ax, ay, bx, by, za, zb;
            m.camera.lightToRaster(at(zStart), int(m.width), int(m.height), ax, ay, za);
            m.camera.lightToRaster(at(zEnd), int(m.width), int(m.height), bx, by, zb);
            s.ray = {ax, ay, bx - ax, by - ay, 1.0 / zStart, 1.0 / zEnd - 1.0 / zStart};
            double ua = 0.0, ub = 1.0;
            if (clip(s.ray, 0.0, 0.0, m.width, m.height, ua, ub)) {
                if (options.hierarchy)
                    s.walkHierarchy(ua, ub);
                else
                    s.walkPixels(ua, ub);
            }
        }
        for (int c = 0; c < 3; ++c) sum[c] += s.vis[c];
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
