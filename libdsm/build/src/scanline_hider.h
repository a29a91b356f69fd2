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
#include "scene_primitives.h"

DSM_NAMESPACE_BEGIN

/// One sample of a tile: its raster position, shutter time and ray.
struct HiderSample {
    double x = 0.0, y = 0.0;
    double time = 0.0;
    Vec3 origin{}, direction{};
};

class DSM_TESTED_INTERNAL ScanlineHider {
public:
    /// Buckets `surfaces` into the tiles of a width x height map of
    /// tileSize² tiles seen through `camera`; `reach` is how many pixels
    /// beyond a tile its samples lie (the filter's reach). Primitives wholly
    /// at or before the near plane are left out (they cannot be crossed);
    /// one that reaches behind a perspective light goes into every tile.
    /// Projects the primitives in parallel in the caller's TBB arena; the
    /// buckets do not depend on the thread count.
    ScanlineHider(const ScenePrimitives& surfaces, const LightCamera& camera, std::uint32_t width,
                  std::uint32_t height, std::uint32_t tileSize, std::uint32_t reach);

    /// The crossings with t > tMin of the samples of tile (tx, ty). The tile's
    /// samples cover the sample pixels [x0, x1) x [y0, y1) (`pixels`), spp per
    /// pixel: pixel (x, y)'s k-th sample is samples[((y - y0) * (x1 - x0) +
    /// (x - x0)) * spp + k]. hits[i] is cleared, then receives samples[i]'s
    /// crossings in the order of the primitives. `hits` is grown to at least
    /// samples.size() but never shrunk, so that a caller reusing it from tile
    /// to tile keeps each entry's storage.
    void tileHits(std::uint32_t tx, std::uint32_t ty, const std::array<std::uint32_t, 4>& pixels, std::uint32_t spp,
                  std::span<const HiderSample> samples, double tMin,
                  std::vector<std::vector<RaySurfaceHit>>& hits) const;

    /// Primitive entries over all buckets (a primitive counts once per tile).
    std::size_t bucketEntries() const { return bucketPrimitives_.size(); }

private:
    struct RasterBounds {
        double x0, y0, x1, y1;
    };

    const ScenePrimitives& surfaces_;
    std::uint32_t tilesX_ = 0, tilesY_ = 0;
    std::vector<RasterBounds> raster_;           // per primitive
    std::vector<std::size_t> bucketStart_;       // per tile, and one past the last
    std::vector<std::uint32_t> bucketPrimitives_;
};

DSM_NAMESPACE_END
