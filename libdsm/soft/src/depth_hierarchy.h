// A min/max depth quadtree over level 0 of a map, for ray tracing it
// (Xie et al. 2007 §4.3; Curtis 2009 §3.5) (internal).
//
// Node (g, x, y) covers the level-0 pixels [x 2^g, (x+1) 2^g) x [y 2^g,
// (y+1) 2^g) and holds the smallest and largest vertex depth of the functions
// in it (all layers). Three parts, so opening a map reads no tile:
//  - g >= tileLevel: a pyramid over the tile grid, built at construction from
//    the tile directory's minZ/maxZ;
//  - 0 <= g < tileLevel: a mini-pyramid per tile, built the first time a ray
//    or minDepth() descends into the tile and kept (published with an atomic pointer, so
//    any number of threads may ask at once; two threads may both build one
//    and one copy is dropped, which costs time, never correctness). Level 0
//    is each pixel's first and last depth: a ray packet's last test reads it
//    for every pixel it reaches, a plain array read where the pixel's own
//    arrays would need its tile found and its view built.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "dsm/reader.h"
#include "tested_internal.h"

namespace dsm::detail {

/// The pixel holding raster coordinate v along an axis of n pixels, clamped
/// to the axis (pixel 0 for NaN). Truncation is the floor for 0 < v < n, and
/// much cheaper where the processor has no rounding instruction (SSE2).
inline std::uint32_t clampedPixel(double v, std::uint32_t n) {
    if (!(v > 0.0)) return 0;
    return v < static_cast<double>(n) ? static_cast<std::uint32_t>(v) : n - 1;
}

struct DepthRange {
    float min = std::numeric_limits<float>::infinity();
    float max = -std::numeric_limits<float>::infinity();
    bool empty() const { return !(min <= max); }
    void add(const DepthRange& o) {
        min = std::min(min, o.min);
        max = std::max(max, o.max);
    }
};

class DSM_TESTED_INTERNAL DepthHierarchy {
public:
    /// Levels 0 .. tileLevel-1 of one tile, finest first, each row-major.
    struct TilePyramid {
        struct Level {
            std::uint32_t width = 0, height = 0;
            std::vector<DepthRange> ranges;
        };
        std::vector<Level> levels;  // levels[g]
        /// Node (g, x, y) of the tile, 0 <= g < tileLevel, x and y relative
        /// to the tile's first node of that level.
        DepthRange at(int g, std::uint32_t x, std::uint32_t y) const {
            const Level& level = levels[static_cast<std::size_t>(g)];
            return level.ranges[std::size_t(y) * level.width + x];
        }
    };

    /// Reads the tile directory of `map` (kept alive by the caller).
    explicit DepthHierarchy(const DeepShadowMap& map);
    ~DepthHierarchy();
    DepthHierarchy(const DepthHierarchy&) = delete;
    DepthHierarchy& operator=(const DepthHierarchy&) = delete;

    /// The level whose single node (0, 0) covers the whole map.
    int topLevel() const { return topLevel_; }
    int tileLevel() const { return tileLevel_; }
    std::uint32_t width() const { return width_; }
    std::uint32_t height() const { return height_; }

    /// Range of node (g, x, y), 0 <= g <= topLevel(), the node inside the map
    /// (at g = 0, pixel (x, y)'s first and last depth; empty for an empty pixel).
    /// May read and decode a tile (through the map's cache); throws what the
    /// reader throws.
    DepthRange node(int g, std::uint32_t x, std::uint32_t y) const;
    /// Range of node (g, x, y) for tileLevel() <= g <= topLevel(): reads no tile.
    DepthRange gridNode(int g, std::uint32_t x, std::uint32_t y) const {
        const GridLevel& level = gridLevels_[static_cast<std::size_t>(g - tileLevel_)];
        return level.ranges[std::size_t(y) * level.width + x];
    }
    /// The levels below the tile grid of tile (tx, ty), built on first use
    /// (as node()).
    const TilePyramid& tilePyramid(std::uint32_t tx, std::uint32_t ty) const;

    /// A lower bound on the depths of the pixels meeting the raster rectangle
    /// [x0, x1] x [y0, y1] (clamped to the map): the smallest node minimum over
    /// nodes inside the rectangle, descending where a node straddles its edge
    /// down to 2 x 2 pixel nodes (so the bound may include pixels one beyond
    /// the edge). Skips nodes that cannot lower the bound found so far, so the
    /// cost grows with the rectangle's perimeter, not its area. +infinity when
    /// the rectangle holds no vertex.
    float minDepth(double x0, double y0, double x1, double y1) const;

    /// Mini-pyramids built so far (for tests and statistics).
    std::size_t tilesBuilt() const { return built_.load(std::memory_order_relaxed); }

private:
    struct PixelRect {
        std::uint32_t x0, y0, x1, y1;  // inclusive
    };
    struct EdgeTile {
        float min;
        std::uint32_t x, y;
    };
    // Lowers `best` by the nodes of (g, x, y) meeting `rect`; with `edge`,
    // tiles the rectangle's edge crosses are left in it instead of opened.
    void lowerMin(int g, std::uint32_t x, std::uint32_t y, const PixelRect& rect, float& best,
                  std::vector<EdgeTile>* edge) const;

    const DeepShadowMap& map_;
    std::uint32_t width_ = 0, height_ = 0, tileSize_ = 0, tilesX_ = 0, tilesY_ = 0;
    int tileLevel_ = 0;
    int topLevel_ = 0;
    // Tile-grid pyramid: gridLevels_[h] has dims ceil(tilesX / 2^h) x ...
    struct GridLevel {
        std::uint32_t width = 0, height = 0;
        std::vector<DepthRange> ranges;
    };
    std::vector<GridLevel> gridLevels_;
    std::unique_ptr<std::atomic<const TilePyramid*>[]> tiles_;
    mutable std::atomic<std::size_t> built_{0};
};

}  // namespace dsm::detail
