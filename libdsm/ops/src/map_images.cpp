#include "dsm/map_images.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <map>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

FloatImage::FloatImage(std::uint32_t w, std::uint32_t h, int c, float fill)
    : width(w), height(h), channels(c), values(static_cast<std::size_t>(w) * h * static_cast<std::size_t>(c), fill) {}

namespace {

const LevelInfo& levelOf(const DeepShadowMap& map, unsigned level) {
    const auto& levels = map.info().levels;
    if (level >= levels.size())
        throw Error(ErrorCode::argument, concat("'", map.path(), "': level ", level, " does not exist (", levels.size(),
                                                levels.size() == 1 ? " level)" : " levels)"),
                    map.path());
    return levels[level];
}

/// Calls visit(x, y, function) for every pixel of a level, a tile at a time so
/// each tile is decoded once whatever the cache holds.
template <class Visit>
void forEachPixel(const DeepShadowMap& map, unsigned level, Visit&& visit) {
    const LevelInfo& L = levelOf(map, level);
    const std::uint32_t tile = map.info().tileSize;
    for (std::uint32_t ty = 0; ty < L.tilesY; ++ty)
        for (std::uint32_t tx = 0; tx < L.tilesX; ++tx) {
            const std::uint32_t x0 = tx * tile, y0 = ty * tile;
            const std::uint32_t x1 = std::min(L.width, x0 + tile), y1 = std::min(L.height, y0 + tile);
            for (std::uint32_t y = y0; y < y1; ++y)
                for (std::uint32_t x = x0; x < x1; ++x) {
                    const PixelFunction f = map.pixel(level, x, y);
                    visit(x, y, f.view());
                }
        }
}

/// V(z) per channel of the image; a monochrome pixel fills every channel.
FloatImage visibilityAt(const DeepShadowMap& map, unsigned level, double z) {
    const LevelInfo& L = levelOf(map, level);
    FloatImage image(L.width, L.height, map.info().channels, 1.0f);
    forEachPixel(map, level, [&](std::uint32_t x, std::uint32_t y, const VisibilityView& f) {
        if (f.empty()) return;
        for (int c = 0; c < image.channels; ++c)
            image.at(x, y, c) = static_cast<float>(f.evaluate(z, std::min(c, f.channels() - 1)));
    });
    return image;
}

}  // namespace

FloatImage visibilitySlice(const DeepShadowMap& map, unsigned level, double z) {
    if (std::isnan(z)) throw Error(ErrorCode::argument, concat("'", map.path(), "': slice depth is NaN"), map.path());
    return visibilityAt(map, level, z);
}

FloatImage opacityImage(const DeepShadowMap& map, unsigned level) {
    FloatImage image = visibilityAt(map, level, std::numeric_limits<double>::infinity());
    for (float& v : image.values) v = 1.0f - v;
    return image;
}

FloatImage vertexCountImage(const DeepShadowMap& map, unsigned level) {
    const LevelInfo& L = levelOf(map, level);
    FloatImage image(L.width, L.height, 1);
    forEachPixel(map, level, [&](std::uint32_t x, std::uint32_t y, const VisibilityView& f) {
        image.at(x, y) = static_cast<float>(f.size());
    });
    return image;
}

VertexHistogram vertexHistogram(const DeepShadowMap& map, unsigned level) {
    const LevelInfo& L = levelOf(map, level);
    // Exact counts first: few distinct values, whatever the map's size.
    std::map<std::uint32_t, std::uint64_t> pixelsWithCount;
    forEachPixel(map, level, [&](std::uint32_t, std::uint32_t, const VisibilityView& f) {
        ++pixelsWithCount[static_cast<std::uint32_t>(f.size())];
    });

    VertexHistogram h;
    h.level = level;
    h.pixels = static_cast<std::uint64_t>(L.width) * L.height;
    if (pixelsWithCount.empty()) return h;
    h.min = pixelsWithCount.begin()->first;
    h.max = pixelsWithCount.rbegin()->first;
    const auto rank = [&](double fraction) {
        return static_cast<std::uint64_t>(std::ceil(fraction * static_cast<double>(h.pixels)));
    };
    const std::uint64_t medianRank = std::max<std::uint64_t>(1, rank(0.5));
    const std::uint64_t p99Rank = std::max<std::uint64_t>(1, rank(0.99));
    std::uint64_t seen = 0;
    bool medianFound = false, p99Found = false;
    for (const auto& [count, pixels] : pixelsWithCount) {
        h.vertices += static_cast<std::uint64_t>(count) * pixels;
        if (count > 0) h.nonEmptyPixels += pixels;
        seen += pixels;
        if (!medianFound && seen >= medianRank) h.median = count, medianFound = true;
        if (!p99Found && seen >= p99Rank) h.p99 = count, p99Found = true;
        const std::size_t bucket = count == 0 ? 0 : static_cast<std::size_t>(std::bit_width(count));
        if (h.buckets.size() <= bucket) h.buckets.resize(bucket + 1, 0);
        h.buckets[bucket] += pixels;
    }
    h.mean = static_cast<double>(h.vertices) / static_cast<double>(h.pixels);
    return h;
}

DSM_NAMESPACE_END
