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
