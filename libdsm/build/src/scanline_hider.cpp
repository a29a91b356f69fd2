#include "scanline_hider.h"

#include <algorithm>
#include <bit>
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

// How many bucket entries ahead tileHits() asks for a primitive's data.
constexpr std::size_t kPrefetchAhead = 8;

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

// How far, in raster units, a sample may lie from the projected axis of a
// still hair segment whose ray still passes the ribbon. A crossing point H lies
// within the half-width r of an axis point Q, so both lie in the segment's box
// (padded by its half-widths), where light depth z >= zMin and |x/z| <= uMax,
// |y/z| <= vMax. Along the way from Q to H a step dp moves the screen position
// (x/z, y/z) by (1/z) A M dp (perspective; M dp orthographic), with M the
// world-to-light rotation and scale and A = [1 0 -u; 0 1 -v] at u = x/z,
// v = y/z, whose largest singular value is sqrt(1 + u^2 + v^2). So raster
// positions move at most max(ax, ay) sqrt(1 + uMax^2 + vMax^2) |M| / zMin
// times |dp| (ax, ay: raster units per screen unit; |M| its largest singular
// value, bounded from above). The sample is H's projection and Q's projection
// lies on the projected axis, so the sample's distance from that axis is at
// most r times that stretch. The bound is widened by 1 % so rounding never
// rejects a crossing the exact test would find; the exact test still decides.
// The camera's part of that bound, the same for every primitive.
struct RasterStretch {
    double scale;  // max(ax, ay) |M|
    bool perspective;

    RasterStretch(const LightCamera& camera, std::uint32_t width, std::uint32_t height) {
        const auto& w = camera.screenWindow;
        const double ax = width / std::abs(w[1] - w[0]), ay = height / std::abs(w[3] - w[2]);
        scale = std::max(ax, ay) * largestSingularValueBound(camera.worldToLight);
        perspective = camera.projection == Projection::Perspective;
    }

    double at(double zMin, double uMax, double vMax) const {
        const double s = perspective ? scale * std::sqrt(1.0 + uMax * uMax + vMax * vMax) / zMin : scale;
        return 1.01 * s;
    }

    // An upper bound on the largest singular value of m's 3 x 3 linear part:
    // the square root of the largest absolute row sum of M^T M, which bounds
    // its largest eigenvalue (Gershgorin). Exact (1) for a rotation.
    static double largestSingularValueBound(const std::array<double, 16>& m) {
        double largest = 0.0;
        for (int i = 0; i < 3; ++i) {
            double row = 0.0;
            for (int j = 0; j < 3; ++j) {
                double mtm = 0.0;  // (M^T M)_ij: columns i and j of M
                for (int k = 0; k < 3; ++k) mtm += m[4 * k + i] * m[4 * k + j];
                row += std::abs(mtm);
            }
            largest = std::max(largest, row);
        }
        return std::sqrt(largest);
    }
};

// LightCamera::lightToRaster() for the ten projections of each primitive's
// bucketing, with one division a point where it has four (the inverse depth,
// which the footprint's bound uses too). Raster positions move by a few units
// in the last place, far inside the widening of raster bounds (kRasterSlack)
// and of footprints (1 %), and the exact crossing decides.
struct RasterProjection {
    double w0, w3, scaleX, scaleY;
    bool perspective;

    RasterProjection(const LightCamera& camera, std::uint32_t width, std::uint32_t height) {
        const auto& w = camera.screenWindow;
        w0 = w[0];
        w3 = w[3];
        scaleX = width / (w[1] - w[0]);
        scaleY = height / (w[3] - w[2]);
        perspective = camera.projection == Projection::Perspective;
    }

    // Screen position (x/z, y/z under a perspective light); false behind it.
    bool screen(const std::array<double, 3>& light, double& sx, double& sy) const {
        sx = light[0];
        sy = light[1];
        if (perspective) {
            if (!(light[2] > 0.0)) return false;
            const double inverse = 1.0 / light[2];
            sx *= inverse;
            sy *= inverse;
        }
        return true;
    }
    bool raster(double sx, double sy, double& rx, double& ry) const {
        rx = (sx - w0) * scaleX;
        ry = (w3 - sy) * scaleY;
        return std::isfinite(rx) && std::isfinite(ry);
    }
    bool operator()(const std::array<double, 3>& light, double& rx, double& ry) const {
        double sx, sy;
        return screen(light, sx, sy) && raster(sx, sy, rx, ry);
    }
};

}  // namespace

// Narrows [x0, x1] to the pixels of row y (samples with y <= sample y < y + 1)
// that a footprint reaches: those within `radius` of the part of the axis
// whose y lies within `radius` of the row. False when it misses the row.
// Multiplying by the stored 1 / dy moves the axis's ends by a few units in
// the last place, far inside the slack.
bool ScanlineHider::footprintRow(const SegmentFootprint& f, double radius, std::uint32_t y, std::uint32_t& x0,
                                 std::uint32_t& x1) {
    const double slack = 1e-9 * (1.0 + std::abs(f.x0) + std::abs(f.y0));
    const double lo = double(y) - radius - slack, hi = double(y) + 1.0 + radius + slack;
    double s0 = 0.0, s1 = 1.0;
    if (f.dy != 0.0) {
        s0 = (lo - f.y0) * f.invDy;
        s1 = (hi - f.y0) * f.invDy;
        if (s0 > s1) std::swap(s0, s1);
        s0 = std::max(s0, 0.0);
        s1 = std::min(s1, 1.0);
        if (s0 > s1) return false;
    } else if (f.y0 < lo || f.y0 > hi) {
        return false;
    }
    double xa = f.x0 + s0 * f.dx, xb = f.x0 + s1 * f.dx;
    if (xa > xb) std::swap(xa, xb);
    const double first = std::max(std::floor(xa - radius - slack), double(x0));
    const double last = std::min(std::floor(xb + radius + slack), double(x1));
    if (first > last) return false;
    x0 = static_cast<std::uint32_t>(first);
    x1 = static_cast<std::uint32_t>(last);
    return true;
}

ScanlineHider::ScanlineHider(const ScenePrimitives& surfaces, const LightCamera& camera, std::uint32_t width,
                             std::uint32_t height, std::uint32_t tileSize, std::uint32_t reach)
    : surfaces_(surfaces),
      frame_(detail::lightRayFrame(camera, width, height)),
      passing_(detail::rasterTestFinder()),
      tilesX_((width + tileSize - 1) / tileSize),
      tilesY_((height + tileSize - 1) / tileSize) {
    const auto& primitives = surfaces.all();
    // Per primitive, its tile rectangle (or none): counted first, then filed.
    struct TileRect {
        std::uint32_t x0, y0, x1, y1;
        bool any;
    };
    // Allocated unwritten: the parallel pass below writes every primitive's
    // entries, so the threads placing the primitives are the first to write
    // these pages (12 MB for the hair ball's 120,000 primitives, which one
    // thread zeroing them first took about 8 ms to touch).
    raster_.resize(primitives.size());
    footprints_.resize(primitives.size());
    detail::LargeVectorForOverwrite<TileRect> rects(primitives.size());
    const RasterStretch cameraStretch(camera, width, height);
    const RasterProjection project(camera, width, height);
    // Each primitive's raster bounds, footprint and tile rectangle, in
    // parallel (each writes only its own entries, so any split gives the same).
    auto place = [&](std::size_t i) {
        const Bounds3 b = surfaces.bounds(primitives[i]);
        RasterBounds r{kInf, kInf, -kInf, -kInf};
        bool inFront = false, behindLight = false;
        double zMin = kInf, uMax = 0.0, vMax = 0.0;  // over the box's corners (see RasterStretch)
        for (int corner = 0; corner < 8; ++corner) {
            const Vec3 world{(corner & 1) ? b.hi[0] : b.lo[0], (corner & 2) ? b.hi[1] : b.lo[1],
                             (corner & 4) ? b.hi[2] : b.lo[2]};
            const std::array<double, 3> light = camera.worldToLightSpace(world);
            if (light[2] > camera.nearPlane) inFront = true;
            zMin = std::min(zMin, light[2]);
            // A corner behind the light leaves no footprint: uMax and vMax
            // only count those in front.
            double sx, sy, rx, ry;
            if (!project.screen(light, sx, sy) || !project.raster(sx, sy, rx, ry)) {
                behindLight = true;
                continue;
            }
            uMax = std::max(uMax, std::abs(sx));
            vMax = std::max(vMax, std::abs(sy));
            r.x0 = std::min(r.x0, rx);
            r.y0 = std::min(r.y0, ry);
            r.x1 = std::max(r.x1, rx);
            r.y1 = std::max(r.y1, ry);
        }
        TileRect& t = rects[i];
        t.any = false;
        footprints_[i] = kNoFootprint;  // unless a still segment's is found below
        // Every point of the primitive lies at depth <= near: no crossing
        // has t > near. (The light-space box of the corners bounds it.)
        if (!inFront) {
            raster_[i] = r;
            return;
        }
        if (behindLight) r = {-kInf, -kInf, kInf, kInf};
        const auto slack = [](double v) { return kRasterSlack * std::max(1.0, std::abs(v)); };
        if (std::isfinite(r.x0)) r.x0 -= slack(r.x0);
        if (std::isfinite(r.y0)) r.y0 -= slack(r.y0);
        if (std::isfinite(r.x1)) r.x1 += slack(r.x1);
        if (std::isfinite(r.y1)) r.y1 += slack(r.y1);
        raster_[i] = r;
        const Primitive& p = primitives[i];
        if (p.kind == PrimitiveKind::Segment && !behindLight && zMin > 0.0 && surfaces.motion(p.object) == Vec3{}) {
            const ScenePrimitives::Segment& s = surfaces.segment(p);
            double x0, y0, x1, y1;
            const double stretch = cameraStretch.at(zMin, uMax, vMax);
            if (project(camera.worldToLightSpace(s.p0), x0, y0) && project(camera.worldToLightSpace(s.p1), x1, y1) &&
                std::isfinite(stretch)) {
                SegmentFootprint& f = footprints_[i];
                f.x0 = x0;
                f.y0 = y0;
                f.dx = x1 - x0;
                f.dy = y1 - y0;
                const double length2 = f.dx * f.dx + f.dy * f.dy;
                f.invLength2 = length2 > 0.0 ? 1.0 / length2 : 0.0;
                f.invDy = f.dy != 0.0 ? 1.0 / f.dy : 0.0;
                const double radius = std::max(s.r0, s.r1) * stretch + 1e-9 * (1.0 + std::abs(x0) + std::abs(y0));
                f.radius2 = radius * radius;
            }
        }
        t.any = tileRange(r.x0, r.x1, tileSize, reach, tilesX_, t.x0, t.x1) &&
                tileRange(r.y0, r.y1, tileSize, reach, tilesY_, t.y0, t.y1);
    };
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, primitives.size(), 1024),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t i = range.begin(); i != range.end(); ++i) place(i);
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
                             std::span<const Rgb> opacity, TileHits& out) const {
    out.found.clear();
    out.foundSample.clear();
    out.start.assign(samples.size() + 1, 0);
    if (tx >= tilesX_ || ty >= tilesY_) {
        out.hits.clear();
        return;
    }
    const std::size_t tile = std::size_t(ty) * tilesX_ + tx;
    const std::uint32_t sw = pixels[2] - pixels[0];
    // The samples' raster positions side by side, for the raster test (with
    // the positions past the last that it reads), and their screen positions,
    // from which a candidate's ray is quick to make.
    auto& xs = out.x;
    auto& ys = out.y;
    auto& sxs = out.screenX;
    auto& sys = out.screenY;
    xs.assign(samples.size() + detail::kRasterTestOverread, 0.0);
    ys.assign(samples.size() + detail::kRasterTestOverread, 0.0);
    sxs.resize(samples.size());
    sys.resize(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
        xs[i] = samples[i].x;
        ys[i] = samples[i].y;
        frame_.screen(samples[i].x, samples[i].y, sxs[i], sys[i]);
    }
    const auto& primitives = surfaces_.all();
    const std::size_t end = bucketStart_[tile + 1];
    for (std::size_t e = bucketStart_[tile]; e < end; ++e) {
        // A bucket's primitives lie scattered over the scene's arrays: ask
        // for the data of those a few entries on before they are needed.
        if (e + kPrefetchAhead < end) {
            const std::uint32_t ahead = bucketPrimitives_[e + kPrefetchAhead];
            __builtin_prefetch(&raster_[ahead]);
            __builtin_prefetch(&footprints_[ahead]);
            __builtin_prefetch(reinterpret_cast<const char*>(&footprints_[ahead]) + sizeof(SegmentFootprint) - 1);
            __builtin_prefetch(&primitives[ahead]);
        }
        if (e + kPrefetchAhead / 2 < end) {
            const Primitive& soon = primitives[bucketPrimitives_[e + kPrefetchAhead / 2]];
            if (soon.kind == PrimitiveKind::Segment) surfaces_.prefetchSegment(soon);
        }
        const std::uint32_t index = bucketPrimitives_[e];
        const RasterBounds& b = raster_[index];
        const Primitive& primitive = primitives[index];
        const SegmentFootprint& f = footprints_[index];
        // The sample pixels under the bounds (a sample of pixel p lies in
        // [p, p + 1)), clipped to the tile's.
        const double px0 = std::max(std::floor(b.x0), static_cast<double>(pixels[0]));
        const double px1 = std::min(std::floor(b.x1), static_cast<double>(pixels[2]) - 1.0);
        const double py0 = std::max(std::floor(b.y0), static_cast<double>(pixels[1]));
        const double py1 = std::min(std::floor(b.y1), static_cast<double>(pixels[3]) - 1.0);
        if (px0 > px1 || py0 > py1) continue;
        const auto x0 = static_cast<std::uint32_t>(px0), x1 = static_cast<std::uint32_t>(px1);
        const auto y0 = static_cast<std::uint32_t>(py0), y1 = static_cast<std::uint32_t>(py1);
        const double radius = f.radius2 >= 0.0 ? std::sqrt(f.radius2) : 0.0;
        const detail::RasterTest test{b.x0, b.y0, b.x1, b.y1, f.x0, f.y0, f.dx, f.dy, f.invLength2, f.radius2};
        // A still primitive is crossed alike at every time (moved by zero):
        // its candidates' times are not read (an array apart, often not in
        // the cache).
        const bool still = surfaces_.motion(primitive.object) == Vec3{};
        for (std::uint32_t y = y0; y <= y1; ++y) {
            std::uint32_t rowX0 = x0, rowX1 = x1;
            if (f.radius2 >= 0.0 && !footprintRow(f, radius, y, rowX0, rowX1)) continue;
            for (std::uint32_t x = rowX0; x <= rowX1; ++x) {
                const std::size_t first = (std::size_t(y - pixels[1]) * sw + (x - pixels[0])) * spp;
                for (std::size_t group = first; group < first + spp; group += 64) {
                    const std::size_t n = std::min<std::size_t>(64, first + spp - group);
                    for (std::uint64_t pass = passing_(&xs[group], &ys[group], n, test); pass != 0;
                         pass &= pass - 1) {
                        const std::size_t k = group + static_cast<std::size_t>(std::countr_zero(pass));
                        Vec3 origin, direction;
                        frame_.rayAt(sxs[k], sys[k], origin, direction);
                        surfaces_.intersect(primitive, origin, direction, still ? 0.0 : samples[k].time, tMin,
                                            out.found);
                        // A primitive yields at most two crossings: pushed, not resized
                        // (a call for a fill of 0, 1 or 2).
                        while (out.foundSample.size() < out.found.size())
                            out.foundSample.push_back(static_cast<std::uint32_t>(k));
                    }
                }
            }
        }
    }
    // Grouped by sample, each sample's in the order found (a counting sort).
    for (const std::uint32_t sample : out.foundSample) ++out.start[sample + 1];
    for (std::size_t i = 0; i < samples.size(); ++i) out.start[i + 1] += out.start[i];
    // Every slot is written below: resizing from the size the vector had
    // (not from empty) sets only the slots it gains.
    out.hits.resize(out.found.size());
    auto& next = out.start;  // each sample's next slot, then moved back below
    for (std::size_t f = 0; f < out.found.size(); ++f)
        out.hits[next[out.foundSample[f]]++] = samplerHit(out.found[f], opacity);
    for (std::size_t i = samples.size(); i > 0; --i) next[i] = next[i - 1];
    next[0] = 0;
}

DSM_NAMESPACE_END
