// Flat pictures of a deep shadow map, one value per pixel of a mip level:
// visibility at a depth, opacity, vertices per pixel; and the statistics of
// vertices per pixel. For looking at maps (dsm-info) and for tests; renderers
// use lookup.h.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "dsm/reader.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// A width x height image of `channels` floats per pixel, row by row from the
/// top (raster y down, as in the map), channels interleaved.
struct DSM_API FloatImage {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    int channels = 1;
    std::vector<float> values;  ///< width * height * channels floats

    FloatImage() = default;
    /// An image filled with `fill`.
    FloatImage(std::uint32_t width, std::uint32_t height, int channels, float fill = 0.0f);

    std::size_t index(std::uint32_t x, std::uint32_t y, int channel = 0) const {
        return (static_cast<std::size_t>(y) * width + x) * static_cast<std::size_t>(channels) +
               static_cast<std::size_t>(channel);
    }
    float at(std::uint32_t x, std::uint32_t y, int channel = 0) const { return values[index(x, y, channel)]; }
    float& at(std::uint32_t x, std::uint32_t y, int channel = 0) { return values[index(x, y, channel)]; }
};

/// Light-centre visibility V(z) of every pixel of a level at light depth `z`
/// (VisibilityView::evaluate), one channel per channel of the map (1 or 3).
/// A monochrome pixel of an RGB map gives the same value in R, G and B.
/// Reads every tile of the level. Throws dsm::Error naming the file when the
/// level does not exist or a tile cannot be read, and when z is NaN.
DSM_API FloatImage visibilitySlice(const DeepShadowMap& map, unsigned level, double z);

/// Opacity 1 - V(infinity) of every pixel of a level: how much light the pixel
/// stops in total, per channel of the map (0 for an empty pixel). For layered
/// (MTSM) pixels this is 1, as the light-centre function ends in 0.
/// Same reading and failures as visibilitySlice().
DSM_API FloatImage opacityImage(const DeepShadowMap& map, unsigned level);

/// Vertices stored per pixel of a level, all layers together, as one channel
/// (exact as float up to 2^24). Same reading and failures as visibilitySlice().
DSM_API FloatImage vertexCountImage(const DeepShadowMap& map, unsigned level);

/// A rectangle of a level's pixels: [x, x + width) x [y, y + height).
struct PixelRect {
    std::uint32_t x = 0;
    std::uint32_t y = 0;
    std::uint32_t width = 0;
    std::uint32_t height = 0;
};

/// Throws dsm::Error (argument) naming the file when `rect` is empty or
/// reaches outside the level, or the level does not exist.
DSM_API void checkPixelRect(const DeepShadowMap& map, unsigned level, const PixelRect& rect);

/// The pictures above for the pixels of `rect` only (pixel (rect.x, rect.y)
/// is the image's (0, 0)): reads only the tiles the rectangle meets, so a
/// viewer fetches a huge level piece by piece. Besides the failures of the
/// whole-level versions, throws dsm::Error (argument) naming the file when
/// `rect` is empty or reaches outside the level.
DSM_API FloatImage visibilitySlice(const DeepShadowMap& map, unsigned level, double z, const PixelRect& rect);
DSM_API FloatImage opacityImage(const DeepShadowMap& map, unsigned level, const PixelRect& rect);
DSM_API FloatImage vertexCountImage(const DeepShadowMap& map, unsigned level, const PixelRect& rect);

/// Layers per pixel of `rect` (MTSM layers; 1 for a non-empty one-layer
/// pixel, 0 for an empty one), as one channel. Same failures as above.
DSM_API FloatImage layerCountImage(const DeepShadowMap& map, unsigned level, const PixelRect& rect);

/// a - b per pixel and channel, for comparing two maps' pictures of the same
/// size. A one-channel picture against a three-channel one is compared in
/// each of the three channels. Throws dsm::Error (argument) when the sizes
/// differ or the channel counts are neither equal nor 1 and 3.
DSM_API FloatImage differenceImage(const FloatImage& a, const FloatImage& b);

/// Distribution of vertices per pixel over every pixel of a level, empty
/// pixels (0 vertices) included.
struct VertexHistogram {
    unsigned level = 0;
    std::uint64_t pixels = 0;          ///< width * height of the level
    std::uint64_t nonEmptyPixels = 0;  ///< pixels with at least one vertex
    std::uint64_t vertices = 0;        ///< sum over all pixels
    std::uint32_t min = 0;
    std::uint32_t max = 0;
    double mean = 0.0;
    /// Nearest-rank percentiles: the smallest count with at least half (99 %)
    /// of the pixels at or below it.
    std::uint32_t median = 0;
    std::uint32_t p99 = 0;
    /// Pixels per power-of-two bucket: buckets[0] counts pixels with 0
    /// vertices, buckets[k] (k >= 1) those with [2^(k-1), 2^k - 1] vertices.
    /// Ends with the bucket holding `max`.
    std::vector<std::uint64_t> buckets;

    /// Smallest and largest vertex count of bucket k.
    static std::uint64_t bucketMin(std::size_t k) { return k == 0 ? 0 : std::uint64_t{1} << (k - 1); }
    static std::uint64_t bucketMax(std::size_t k) { return k == 0 ? 0 : (std::uint64_t{1} << k) - 1; }
};

/// The histogram of a level. Reads every tile of the level; same failures as
/// visibilitySlice().
DSM_API VertexHistogram vertexHistogram(const DeepShadowMap& map, unsigned level);

DSM_NAMESPACE_END
