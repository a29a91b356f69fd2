// The scanline sampler's visibility (internal). Every surface primitive is
// bucketed once into the map tiles whose samples it can reach (its bounds over
// the shutter, projected to raster, widened by the filter's reach); a tile's
// samples then meet only the primitives of its bucket, and each primitive only
// the samples inside its raster bounds. Where a sample meets a primitive is the
// exact crossing of the sample's ray (ScenePrimitives::intersect) at the
// sample's time, so the hider finds what a ray cast through the sample would,
// primitive by primitive instead of ray by ray (Lokovic & Veach §5.1: a
// scanline renderer that keeps every surface crossing of every sample).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/scene.h"
#include "dsm/transmittance.h"
#include "light_rays.h"
#include "raster_test.h"
#include "scene_primitives.h"

DSM_NAMESPACE_BEGIN

/// One sample of a tile: its raster position and shutter time. Its ray is
/// the light's ray through that position (detail::LightRayFrame::ray()),
/// worked out by the hider for the primitives that may cross it: a tile's
/// samples then fit the processor's caches three times better than with
/// their rays kept.
struct HiderSample {
    double x = 0.0, y = 0.0;
    double time = 0.0;
};

class DSM_TESTED_INTERNAL ScanlineHider {
public:
    /// Buckets `surfaces` into the tiles of a width x height map of
    /// tileSize² tiles seen through `camera`; `reach` is how many pixels
    /// beyond a tile its samples lie (the filter's reach). Primitives wholly
    /// at or before the near plane are left out (they cannot be crossed);
    /// one that reaches behind a perspective light goes into every tile.
    /// Runs in parallel in the calling thread's task arena.
    ScanlineHider(const ScenePrimitives& surfaces, const LightCamera& camera, std::uint32_t width,
                  std::uint32_t height, std::uint32_t tileSize, std::uint32_t reach);

    /// The crossings of a tile's samples, each sample's in one run: sample
    /// i's are hits[start[i], start[i + 1]), in the order of the primitives,
    /// each as the sampler takes it (its depth as a float and its object's
    /// opacity). A caller reusing one from tile to tile keeps its storage.
    struct TileHits {
        detail::LargeVector<std::size_t> start;
        detail::LargeVector<SurfaceHit> hits;
        std::span<const SurfaceHit> of(std::size_t i) const {
            return std::span<const SurfaceHit>(hits).subspan(start[i], start[i + 1] - start[i]);
        }
        // Found in the order of the primitives, with their samples, then
        // grouped by sample into `hits`.
        RaySurfaceHits found;
        detail::LargeVector<std::uint32_t> foundSample;
        detail::LargeVector<double> x, y, screenX, screenY;  // the samples' positions side by side
    };
    /// The crossings with t > tMin of the samples of tile (tx, ty). The tile's
    /// samples cover the sample pixels [x0, x1) x [y0, y1) (`pixels`), spp per
    /// pixel: pixel (x, y)'s k-th sample is samples[((y - y0) * (x1 - x0) +
    /// (x - x0)) * spp + k]. `opacity` holds each object's opacity, by object
    /// index. `out` receives them all, replacing what it held.
    void tileHits(std::uint32_t tx, std::uint32_t ty, const std::array<std::uint32_t, 4>& pixels, std::uint32_t spp,
                  std::span<const HiderSample> samples, double tMin, std::span<const Rgb> opacity,
                  TileHits& out) const;

    /// Primitive entries over all buckets (a primitive counts once per tile).
    std::size_t bucketEntries() const { return bucketPrimitives_.size(); }

private:
    struct RasterBounds {
        double x0, y0, x1, y1;
    };
    /// A still hair segment's axis in raster space, P(s) = (x0, y0) + s (dx, dy)
    /// for s in [0, 1], and the squared raster distance from it beyond which
    /// no sample's ray can pass the ribbon (radius2 < 0: no such bound, the
    /// exact test decides alone).
    struct SegmentFootprint {
        double x0, y0, dx, dy, invLength2, radius2;
        double invDy;  // 1 / dy (0 when dy is), for footprintRow()
    };
    static constexpr SegmentFootprint kNoFootprint{0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0};

    static bool footprintRow(const SegmentFootprint& f, double radius, std::uint32_t y, std::uint32_t& x0,
                             std::uint32_t& x1);

    const ScenePrimitives& surfaces_;
    detail::LightRayFrame frame_;  // the samples' rays
    detail::RasterTestFinder passing_;  // the raster test this processor runs fastest
    std::uint32_t tilesX_ = 0, tilesY_ = 0;
    // Per primitive, each written once, by the thread that places it.
    detail::LargeVectorForOverwrite<RasterBounds> raster_;
    detail::LargeVectorForOverwrite<SegmentFootprint> footprints_;
    std::vector<std::size_t> bucketStart_;  // per tile, and one past the last
    detail::LargeVector<std::uint32_t> bucketPrimitives_;
};

DSM_NAMESPACE_END
