#include "scanline_hider.h"

#include <algorithm>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

DSM_NAMESPACE_BEGIN

namespace {

constexpr double kInf = Bounds3::kInf;

// Raster bounds are widened by this much (relative, at least this many
// pixels), so that rounding in the projection never leaves out a sample
// whose ray crosses the primitive; the exact test decides.
constexpr double kRasterSlack = 1e-6;

// The tiles [first, last] whose samples, `reach` pixels beyond each tile,
// can lie in [lo, hi] along one axis of `tiles` tiles of `size` pixels.
bool tileRange(double lo, double hi, std::uint32_t size, std::uint32_t reach, std::uint32_t tiles,
               std::uint32_t& first, std::uint32_t& last) {
    const double a = std::floor((lo - reach) / size), b = std::floor((hi + reach) / size);
    if (b < 0.0 || a > static_cast<double>(tiles) - 1.0) return false;
    first = static_cast<std::uint32_t>(std::max(a, 0.0));
    last = static_cast<std::uint32_t>(std::min(b, static_cast<double>(tiles) - 1.0));
    return true;
}

}  // namespace

ScanlineHider::ScanlineHider(const ScenePrimitives& surfaces, const LightCamera& camera, std::uint32_t width,
                             std::uint32_t height, std::uint32_t tileSize, std::uint32_t reach)
    : surfaces_(surfaces),
      tilesX_((width + tileSize - 1) / tileSize),
      tilesY_((height + tileSize - 1) / tileSize) {
    const std::vector<Primitive>& primitives = surfaces.all();
    raster_.resize(primitives.size());
    // Per primitive, its tile rectangle (or none): counted first, then filed.
    struct TileRect {
        std::uint32_t x0, y0, x1, y1;
        bool any;
    };
    // Primitive i's raster bounds (into raster_) and tile rectangle.
    const auto project = [&](std::size_t i, TileRect& t) {
        t.any = false;
        const Bounds3 b = surfaces.bounds(primitives[i]);
        RasterBounds r{kInf, kInf, -kInf, -kInf};
        bool inFront = false, behindLight = false;
        for (int corner = 0; corner < 8; ++corner) {
            const Vec3 world{(corner & 1) ? b.hi[0] : b.lo[0], (corner & 2) ? b.hi[1] : b.lo[1],
                             (corner & 4) ? b.hi[2] : b.lo[2]};
            const std::array<double, 3> light = camera.worldToLightSpace(world);
            if (light[2] > camera.nearPlane) inFront = true;
            double rx, ry, z;
            if (!camera.lightToRaster(light, static_cast<int>(width), static_cast<int>(height), rx, ry, z)) {
                behindLight = true;
                continue;
            }
            r.x0 = std::min(r.x0, rx);
            r.y0 = std::min(r.y0, ry);
            r.x1 = std::max(r.x1, rx);
            r.y1 = std::max(r.y1, ry);
        }
        // Every point of the primitive lies at depth <= near: no crossing
        // has t > near. (The light-space box of the corners bounds it.)
        if (!inFront) return;
        if (behindLight) r = {-kInf, -kInf, kInf, kInf};
        const auto slack = [](double v) { return kRasterSlack * std::max(1.0, std::abs(v)); };
        if (std::isfinite(r.x0)) r.x0 -= slack(r.x0);
        if (std::isfinite(r.y0)) r.y0 -= slack(r.y0);
        if (std::isfinite(r.x1)) r.x1 += slack(r.x1);
        if (std::isfinite(r.y1)) r.y1 += slack(r.y1);
        raster_[i] = r;
        t.any = tileRange(r.x0, r.x1, tileSize, reach, tilesX_, t.x0, t.x1) &&
                tileRange(r.y0, r.y1, tileSize, reach, tilesY_, t.y0, t.y1);
    };
    std::vector<TileRect> rects(primitives.size());
    // Each primitive's bounds, projected: independent of the others, so shared
    // among the threads of the caller's arena (each writes only its own
    // entries: the result does not depend on the thread count).
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, primitives.size(), 1024), [&](const auto& range) {
        for (std::size_t i = range.begin(); i < range.end(); ++i) project(i, rects[i]);
    });
    std::vector<std::size_t> counts(std::size_t(tilesX_) * tilesY_ + 1, 0);
    for (const TileRect& t : rects) {
        if (!t.any) continue;
        for (std::uint32_t ty = t.y0; ty <= t.y1; ++ty)
            for (std::uint32_t tx = t.x0; tx <= t.x1; ++tx) ++counts[std::size_t(ty) * tilesX_ + tx];
    }
    bucketStart_.assign(counts.size(), 0);
    std::size_t total = 0;
    for (std::size_t k = 0; k < counts.size(); ++k) {
        bucketStart_[k] = total;
        total += counts[k];
    }
    bucketPrimitives_.resize(total);
    std::vector<std::size_t> next(bucketStart_.begin(), bucketStart_.end() - 1);
    for (std::size_t i = 0; i < primitives.size(); ++i) {
        const TileRect& t = rects[i];
        if (!t.any) continue;
        for (std::uint32_t ty = t.y0; ty <= t.y1; ++ty)
            for (std::uint32_t tx = t.x0; tx <= t.x1; ++tx)
                bucketPrimitives_[next[std::size_t(ty) * tilesX_ + tx]++] = static_cast<std::uint32_t>(i);
    }
}

void ScanlineHider::tileHits(std::uint32_t tx, std::uint32_t ty, const std::array<std::uint32_t, 4>& pixels,
                             std::uint32_t spp, std::span<const HiderSample> samples, double tMin,
                             std::vector<std::vector<RaySurfaceHit>>& hits) const {
    if (hits.size() < samples.size()) hits.resize(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) hits[i].clear();
    if (tx >= tilesX_ || ty >= tilesY_) return;
    const std::size_t tile = std::size_t(ty) * tilesX_ + tx;
    const std::uint32_t sw = pixels[2] - pixels[0];
    const std::vector<Primitive>& primitives = surfaces_.all();
    for (std::size_t e = bucketStart_[tile]; e < bucketStart_[tile + 1]; ++e) {
        const std::uint32_t index = bucketPrimitives_[e];
        const RasterBounds& b = raster_[index];
        const Primitive& primitive = primitives[index];
        // The sample pixels under the bounds (a sample of pixel p lies in
        // [p, p + 1)), clipped to the tile's.
        const double px0 = std::max(std::floor(b.x0), static_cast<double>(pixels[0]));
        const double px1 = std::min(std::floor(b.x1), static_cast<double>(pixels[2]) - 1.0);
        const double py0 = std::max(std::floor(b.y0), static_cast<double>(pixels[1]));
        const double py1 = std::min(std::floor(b.y1), static_cast<double>(pixels[3]) - 1.0);
        if (px0 > px1 || py0 > py1) continue;
        const auto x0 = static_cast<std::uint32_t>(px0), x1 = static_cast<std::uint32_t>(px1);
        const auto y0 = static_cast<std::uint32_t>(py0), y1 = static_cast<std::uint32_t>(py1);
        for (std::uint32_t y = y0; y <= y1; ++y)
            for (std::uint32_t x = x0; x <= x1; ++x) {
                const std::size_t first = (std::size_t(y - pixels[1]) * sw + (x - pixels[0])) * spp;
                for (std::size_t k = first; k < first + spp; ++k) {
                    const HiderSample& s = samples[k];
                    if (s.x < b.x0 || s.x > b.x1 || s.y < b.y0 || s.y > b.y1) continue;
                    surfaces_.intersect(primitive, s.origin, s.direction, s.time, tMin, hits[k]);
                }
            }
    }
}

DSM_NAMESPACE_END
