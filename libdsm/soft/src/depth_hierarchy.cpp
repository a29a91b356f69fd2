#include "depth_hierarchy.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "reader_impl.h"

namespace dsm::detail {

namespace {

int ceilLog2(std::uint32_t n) { return n <= 1 ? 0 : std::bit_width(n - 1); }

}  // namespace

DepthHierarchy::DepthHierarchy(const DeepShadowMap& map) : map_(map) {
    const MapInfo& info = map.info();
    width_ = info.width;
    height_ = info.height;
    tileSize_ = info.tileSize;
    tileLevel_ = ceilLog2(tileSize_);
    tilesX_ = info.levels.at(0).tilesX;
    tilesY_ = info.levels.at(0).tilesY;
    topLevel_ = tileLevel_ + ceilLog2(std::max(tilesX_, tilesY_));

    GridLevel base;
    base.width = tilesX_;
    base.height = tilesY_;
    base.ranges.resize(std::size_t(tilesX_) * tilesY_);
    for (std::uint32_t ty = 0; ty < tilesY_; ++ty)
        for (std::uint32_t tx = 0; tx < tilesX_; ++tx) {
            const TileSummary s = map.tile(0, tx, ty);
            if (s.empty() || s.vertexCount == 0) continue;
            base.ranges[std::size_t(ty) * tilesX_ + tx] = {s.minZ, s.maxZ};
        }
    gridLevels_.push_back(std::move(base));
    while (gridLevels_.back().width > 1 || gridLevels_.back().height > 1) {
        const GridLevel& fine = gridLevels_.back();
        GridLevel coarse;
        coarse.width = (fine.width + 1) / 2;
        coarse.height = (fine.height + 1) / 2;
        coarse.ranges.resize(std::size_t(coarse.width) * coarse.height);
        for (std::uint32_t y = 0; y < fine.height; ++y)
            for (std::uint32_t x = 0; x < fine.width; ++x)
                coarse.ranges[std::size_t(y / 2) * coarse.width + x / 2].add(fine.ranges[std::size_t(y) * fine.width + x]);
        gridLevels_.push_back(std::move(coarse));
    }
    tiles_ = std::make_unique<std::atomic<const TilePyramid*>[]>(std::size_t(tilesX_) * tilesY_);
    for (std::size_t i = 0; i < std::size_t(tilesX_) * tilesY_; ++i) tiles_[i].store(nullptr);
}

DepthHierarchy::~DepthHierarchy() {
    for (std::size_t i = 0; i < std::size_t(tilesX_) * tilesY_; ++i) delete tiles_[i].load();
}

const DepthHierarchy::TilePyramid& DepthHierarchy::tilePyramid(std::uint32_t tx, std::uint32_t ty) const {
    std::atomic<const TilePyramid*>& slot = tiles_[std::size_t(ty) * tilesX_ + tx];
    if (const TilePyramid* p = slot.load(std::memory_order_acquire)) return *p;

    const auto tile = ImplAccess::of(map_).getTile(0, tx, ty);
    auto pyramid = std::make_unique<TilePyramid>();
    // Level 0 from the pixels, each coarser one from the level below.
    TilePyramid::Level pixels;
    pixels.width = tile->width;
    pixels.height = tile->height;
    pixels.ranges.resize(std::size_t(pixels.width) * pixels.height);
    for (std::size_t i = 0; i < pixels.ranges.size(); ++i) {
        const VisibilityView f = tile->pixel(i);
        if (!f.empty()) pixels.ranges[i] = {f.z(0), f.z(f.size() - 1)};
    }
    pyramid->levels.push_back(std::move(pixels));
    for (int g = 1; g < tileLevel_; ++g) {
        const TilePyramid::Level& fine = pyramid->levels.back();
        TilePyramid::Level level;
        level.width = (fine.width + 1) / 2;
        level.height = (fine.height + 1) / 2;
        level.ranges.resize(std::size_t(level.width) * level.height);
        for (std::uint32_t y = 0; y < fine.height; ++y)
            for (std::uint32_t x = 0; x < fine.width; ++x)
                level.ranges[std::size_t(y / 2) * level.width + x / 2].add(fine.ranges[std::size_t(y) * fine.width + x]);
        pyramid->levels.push_back(std::move(level));
    }
    const TilePyramid* expected = nullptr;
    if (slot.compare_exchange_strong(expected, pyramid.get(), std::memory_order_acq_rel, std::memory_order_acquire)) {
        built_.fetch_add(1, std::memory_order_relaxed);
        return *pyramid.release();
    }
    return *expected;  // another thread published first; ours is dropped
}

DepthRange DepthHierarchy::node(int g, std::uint32_t x, std::uint32_t y) const {
    if (g >= tileLevel_) return gridNode(g, x, y);
    const int shift = tileLevel_ - g;
    const std::uint32_t tx = x >> shift, ty = y >> shift;
    return tilePyramid(tx, ty).at(g, x - (tx << shift), y - (ty << shift));
}

float DepthHierarchy::minDepth(double x0, double y0, double x1, double y1) const {
    float best = std::numeric_limits<float>::infinity();
    const double W = width_, H = height_;
    if (!(x1 >= 0.0 && y1 >= 0.0 && x0 <= W && y0 <= H)) return best;
    const PixelRect rect{clampedPixel(x0, width_), clampedPixel(y0, height_), clampedPixel(x1, width_),
                          clampedPixel(y1, height_)};
    // The tiles the rectangle's edge crosses are looked into last, nearest
    // first, and only while they can still lower the bound: the tile
    // directory settles the rest, and a tile never reached is never decoded.
    // The bound is the same in any order (the smallest over one cover).
    std::vector<EdgeTile> edge;
    lowerMin(topLevel_, 0, 0, rect, best, &edge);
    std::sort(edge.begin(), edge.end(), [](const EdgeTile& a, const EdgeTile& b) { return a.min < b.min; });
    for (const EdgeTile& t : edge) {
        if (!(t.min < best)) break;
        lowerMin(tileLevel_, t.x, t.y, rect, best, nullptr);
    }
    return best;
}

void DepthHierarchy::lowerMin(int g, std::uint32_t x, std::uint32_t y, const PixelRect& rect, float& best,
                              std::vector<EdgeTile>* edge) const {
    const std::uint64_t nx0 = std::uint64_t(x) << g, ny0 = std::uint64_t(y) << g;
    const std::uint64_t nx1 = nx0 + (std::uint64_t(1) << g) - 1, ny1 = ny0 + (std::uint64_t(1) << g) - 1;
    if (nx0 > rect.x1 || ny0 > rect.y1 || nx1 < rect.x0 || ny1 < rect.y0) return;
    const DepthRange r = node(g, x, y);
    if (r.empty() || !(r.min < best)) return;  // nothing here can lower the bound
    const bool inside = nx0 >= rect.x0 && ny0 >= rect.y0 && nx1 <= rect.x1 && ny1 <= rect.y1;
    if (inside || g == 1) {  // level 1 may overhang the rectangle by a pixel: still a valid lower bound
        best = r.min;
        return;
    }
    if (edge && g == tileLevel_) {
        edge->push_back({r.min, x, y});
        return;
    }
    for (std::uint32_t j = 0; j < 2; ++j)
        for (std::uint32_t i = 0; i < 2; ++i) {
            const std::uint32_t cx = 2 * x + i, cy = 2 * y + j;
            if ((std::uint64_t(cx) << (g - 1)) >= width_ || (std::uint64_t(cy) << (g - 1)) >= height_) continue;
            lowerMin(g - 1, cx, cy, rect, best, edge);
        }
}

}  // namespace dsm::detail
