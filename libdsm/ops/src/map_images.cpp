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

PixelRect wholeLevel(const DeepShadowMap& map, unsigned level) {
    const LevelInfo& L = levelOf(map, level);
    return {0, 0, L.width, L.height};
}

}  // namespace

void checkPixelRect(const DeepShadowMap& map, unsigned level, const PixelRect& rect) {
    const LevelInfo& L = levelOf(map, level);
    if (rect.width == 0 || rect.height == 0 || rect.x >= L.width || rect.y >= L.height ||
        rect.width > L.width - rect.x || rect.height > L.height - rect.y)
        throw Error(ErrorCode::argument,
                    concat("'", map.path(), "': level ", level, ": pixels ", rect.x, ",", rect.y, " + ", rect.width,
                           " x ", rect.height, " are not a part of the level (", L.width, " x ", L.height, ")"),
                    map.path());
}

namespace {

/// Calls visit(x, y, function) for every pixel of `rect` (level pixel
/// coordinates), a tile at a time so each tile is decoded once whatever the
/// cache holds. Only the tiles the rectangle meets are read.
template <class Visit>
void forEachPixel(const DeepShadowMap& map, unsigned level, const PixelRect& rect, Visit&& visit) {
    checkPixelRect(map, level, rect);
    const std::uint32_t tile = map.info().tileSize;
    const std::uint32_t rx1 = rect.x + rect.width, ry1 = rect.y + rect.height;
    for (std::uint32_t ty = rect.y / tile; ty * tile < ry1; ++ty)
        for (std::uint32_t tx = rect.x / tile; tx * tile < rx1; ++tx) {
            const std::uint32_t x0 = std::max(rect.x, tx * tile), y0 = std::max(rect.y, ty * tile);
            const std::uint32_t x1 = std::min(rx1, tx * tile + tile), y1 = std::min(ry1, ty * tile + tile);
            for (std::uint32_t y = y0; y < y1; ++y)
                for (std::uint32_t x = x0; x < x1; ++x) {
                    const PixelFunction f = map.pixel(level, x, y);
                    visit(x, y, f.view());
                }
        }
}

/// V(z) per channel of the image; a monochrome pixel fills every channel.
FloatImage visibilityAt(const DeepShadowMap& map, unsigned level, double z, const PixelRect& rect) {
    checkPixelRect(map, level, rect);
    FloatImage image(rect.width, rect.height, map.info().channels, 1.0f);
    forEachPixel(map, level, rect, [&](std::uint32_t x, std::uint32_t y, const VisibilityView& f) {
        if (f.empty()) return;
        for (int c = 0; c < image.channels; ++c)
            image.at(x - rect.x, y - rect.y, c) = static_cast<float>(f.evaluate(z, std::min(c, f.channels() - 1)));
    });
    return image;
}

/// One value per pixel of `rect`: count(function).
template <class Count>
FloatImage countImage(const DeepShadowMap& map, unsigned level, const PixelRect& rect, Count&& count) {
    checkPixelRect(map, level, rect);
    FloatImage image(rect.width, rect.height, 1);
    forEachPixel(map, level, rect, [&](std::uint32_t x, std::uint32_t y, const VisibilityView& f) {
        image.at(x - rect.x, y - rect.y) = static_cast<float>(count(f));
    });
    return image;
}

}  // namespace

FloatImage visibilitySlice(const DeepShadowMap& map, unsigned level, double z) {
    return visibilitySlice(map, level, z, wholeLevel(map, level));
}

FloatImage visibilitySlice(const DeepShadowMap& map, unsigned level, double z, const PixelRect& rect) {
    if (std::isnan(z)) throw Error(ErrorCode::argument, concat("'", map.path(), "': slice depth is NaN"), map.path());
    return visibilityAt(map, level, z, rect);
}

FloatImage opacityImage(const DeepShadowMap& map, unsigned level) {
    return opacityImage(map, level, wholeLevel(map, level));
}

FloatImage opacityImage(const DeepShadowMap& map, unsigned level, const PixelRect& rect) {
    FloatImage image = visibilityAt(map, level, std::numeric_limits<double>::infinity(), rect);
    for (float& v : image.values) v = 1.0f - v;
    return image;
}

FloatImage vertexCountImage(const DeepShadowMap& map, unsigned level) {
    return vertexCountImage(map, level, wholeLevel(map, level));
}

FloatImage vertexCountImage(const DeepShadowMap& map, unsigned level, const PixelRect& rect) {
    return countImage(map, level, rect, [](const VisibilityView& f) { return f.size(); });
}

FloatImage layerCountImage(const DeepShadowMap& map, unsigned level, const PixelRect& rect) {
    return countImage(map, level, rect, [](const VisibilityView& f) { return f.empty() ? 0 : f.layerCount(); });
}

FloatImage differenceImage(const FloatImage& a, const FloatImage& b) {
    if (a.width != b.width || a.height != b.height)
        throw Error(ErrorCode::argument, concat("difference of pictures of different sizes (", a.width, " x ", a.height,
                                                " and ", b.width, " x ", b.height, ")"));
    const bool sameChannels = a.channels == b.channels;
    if (!sameChannels && a.channels != 1 && b.channels != 1)
        throw Error(ErrorCode::argument,
                    concat("difference of pictures of ", a.channels, " and ", b.channels, " channels"));
    FloatImage d(a.width, a.height, std::max(a.channels, b.channels));
    for (std::uint32_t y = 0; y < d.height; ++y)
        for (std::uint32_t x = 0; x < d.width; ++x)
            for (int c = 0; c < d.channels; ++c)
                d.at(x, y, c) = a.at(x, y, std::min(c, a.channels - 1)) - b.at(x, y, std::min(c, b.channels - 1));
    return d;
}

VertexHistogram vertexHistogram(const DeepShadowMap& map, unsigned level) {
    const LevelInfo& L = levelOf(map, level);
    // Exact counts first: few distinct values, whatever the map's size.
    std::map<std::uint32_t, std::uint64_t> pixelsWithCount;
    forEachPixel(map, level, wholeLevel(map, level), [&](std::uint32_t, std::uint32_t, const VisibilityView& f) {
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
