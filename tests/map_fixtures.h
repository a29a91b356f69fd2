// Helpers shared by the tests of the .dsm writer, reader, mip-maps and lookups
// (test_format_roundtrip, test_mipmap, test_lookup, test_reader_errors):
// images of functions in memory, writing them as maps, bit-exact comparison,
// and the light-centre function and area-average oracles.
#pragma once

#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "oracle.h"

namespace dsm::test {

/// A level-0 image of functions in row order.
struct Image {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    std::vector<VisibilityFunction> pixels;
    const VisibilityFunction& at(std::uint32_t x, std::uint32_t y) const { return pixels[std::size_t(y) * width + x]; }
};

inline Image makeImage(std::uint32_t width, std::uint32_t height,
                       const std::function<VisibilityFunction(std::uint32_t, std::uint32_t)>& pixel) {
    Image image;
    image.width = width;
    image.height = height;
    image.pixels.reserve(std::size_t(width) * height);
    for (std::uint32_t y = 0; y < height; ++y)
        for (std::uint32_t x = 0; x < width; ++x) image.pixels.push_back(pixel(x, y));
    return image;
}

/// Writes `image` with `options` (width and height taken from the image),
/// tiles in a shuffled order when `seed` is non-zero (the writer accepts any
/// order), in row order otherwise.
inline void writeMap(const std::filesystem::path& path, WriterOptions options, const Image& image,
                     std::uint64_t seed = 0) {
    options.width = image.width;
    options.height = image.height;
    MapWriter writer(path.string(), options);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> order;
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) order.emplace_back(tx, ty);
    if (seed != 0) {
        std::mt19937_64 rng(seed);
        std::shuffle(order.begin(), order.end(), rng);
    }
    std::vector<VisibilityFunction> tile;
    for (const auto& [tx, ty] : order) {
        tile.clear();
        const std::uint32_t w = writer.tileWidth(tx), h = writer.tileHeight(ty);
        for (std::uint32_t y = 0; y < h; ++y)
            for (std::uint32_t x = 0; x < w; ++x) tile.push_back(image.at(tx * options.tileSize + x, ty * options.tileSize + y));
        writer.writeTile(tx, ty, tile);
    }
    writer.finish();
}

/// Bit-exact comparison of a stored pixel with the function written.
/// `mapHasCounts` false: the written counts are not stored, so not compared.
inline ::testing::AssertionResult sameFunction(const VisibilityView& got, const VisibilityFunction& want,
                                               bool mapHasCounts) {
    auto fail = [&] { return ::testing::AssertionFailure(); };
    // libdsm stores a grey pixel (no vertices, or channels equal at every
    // vertex) monochrome, other writers may not (spec section 4): the channel
    // counts may differ when the RGB one is grey, and values compare per channel.
    if (got.channels() != want.channels() &&
        !(got.channels() == 3 ? got.toFunction().isMonochrome() : want.isMonochrome()))
        return fail() << "channels " << got.channels() << " != " << want.channels();
    if (got.size() != want.size()) return fail() << "vertex count " << got.size() << " != " << want.size();
    if (got.layerCount() != want.layerCount())
        return fail() << "layer count " << got.layerCount() << " != " << want.layerCount();
    for (std::size_t l = 1; l < want.layerCount(); ++l)
        if (got.layerBegin(l) != want.layerBegin(l))
            return fail() << "layer " << l << " starts at " << got.layerBegin(l) << " != " << want.layerBegin(l);
    for (std::size_t i = 0; i < want.size(); ++i) {
        if (std::bit_cast<std::uint32_t>(got.z(i)) != std::bit_cast<std::uint32_t>(want.z(i)))
            return fail() << "vertex " << i << " depth " << got.z(i) << " != " << want.z(i);
        for (int c = 0; c < std::max(got.channels(), want.channels()); ++c) {
            const float g = got.value(i, std::min(c, got.channels() - 1));
            const float w = want.value(i, std::min(c, want.channels() - 1));
            if (std::bit_cast<std::uint32_t>(g) != std::bit_cast<std::uint32_t>(w))
                return fail() << "vertex " << i << " channel " << c << " value " << g << " != " << w;
        }
        const std::uint32_t wantCount = mapHasCounts ? want.count(i) : 0u;
        if (got.count(i) != wantCount) return fail() << "vertex " << i << " count " << got.count(i) << " != " << wantCount;
    }
    if (mapHasCounts && want.hasCounts() && !want.empty() && !got.hasCounts()) return fail() << "counts were lost";
    if (!mapHasCounts && got.hasCounts()) return fail() << "counts appeared in a map without counts";
    return ::testing::AssertionSuccess();
}

/// Every level-0 pixel of `got` is the same function as `want`'s, to the bit
/// (maps of one size; reports the first pixel that differs).
inline void expectSamePixels(const DeepShadowMap& got, const DeepShadowMap& want) {
    ASSERT_EQ(got.info().width, want.info().width);
    ASSERT_EQ(got.info().height, want.info().height);
    ASSERT_EQ(got.info().hasCounts, want.info().hasCounts);
    for (std::uint32_t y = 0; y < want.info().height; ++y)
        for (std::uint32_t x = 0; x < want.info().width; ++x)
            ASSERT_TRUE(sameFunction(got.pixel(0, x, y).view(), want.pixel(0, x, y).view().toFunction(),
                                     want.info().hasCounts))
                << "pixel " << x << "," << y;
}

/// A random valid function: `layers` layers (each at least one vertex), about
/// `vertices` vertices per layer, with vertical steps, depths from `zStart`.
inline VisibilityFunction randomFunction(std::mt19937_64& rng, int channels, bool counts, int layers, int vertices,
                                         float zStart = 0.5f) {
    std::uniform_real_distribution<float> gap(0.01f, 0.6f), drop(0.0f, 0.25f), start(0.55f, 1.0f);
    std::uniform_int_distribution<int> n(1, std::max(1, vertices)), cnt(0, 6);
    std::bernoulli_distribution step(0.25), separateChannels(0.7);
    VisibilityFunction f(channels, counts);
    float z = zStart;
    for (int layer = 0; layer < layers; ++layer) {
        if (layer > 0) f.beginLayer();
        float v[kMaxChannels];
        const bool separate = separateChannels(rng);
        for (int c = 0; c < channels; ++c) v[c] = (c == 0 || separate) ? start(rng) : v[0];
        const int count = n(rng);
        for (int i = 0; i < count; ++i) {
            if (!(i == 0 && layer == 0) && !step(rng)) z += gap(rng);
            f.append(z, v, counts ? static_cast<std::uint32_t>(cnt(rng)) : 0u);
            const float d = drop(rng);
            for (int c = 0; c < channels; ++c) v[c] = std::max(0.0f, v[c] - (separate ? drop(rng) : d));
        }
        z += gap(rng);
    }
    return f;
}

/// The light-centre function of `f` (layer 0, then 0 at and beyond its last
/// depth when other layers follow: the documented evaluation of a layered
/// function) as one layer with `channels` channels (monochrome repeated).
inline VisibilityFunction lightCentre(const VisibilityView& f, int channels) {
    VisibilityFunction out(channels, false);
    const std::size_t end = f.layerCount() > 1 ? f.layerBegin(1) : f.size();
    float v[kMaxChannels];
    for (std::size_t i = 0; i < end; ++i) {
        for (int c = 0; c < channels; ++c) v[c] = f.value(i, std::min(c, f.channels() - 1));
        out.append(f.z(i), v);
    }
    if (f.layerCount() > 1) {
        std::fill(v, v + channels, 0.0f);
        out.append(f.z(end - 1), v);
    }
    return out;
}

/// Light-centre visibility V(z) by the oracle's linear scan.
inline double lightCentreValue(const VisibilityView& f, double z, int channel) {
    return valueAt(lightCentre(f, f.channels()), z, std::min(channel, f.channels() - 1));
}

/// Level-0 pixels covered by pixel `x` of `level` along an axis of `fullExtent`.
inline double coveredPixels(std::uint32_t x, unsigned level, std::uint32_t fullExtent) {
    const std::uint64_t span = std::uint64_t(1) << level;
    return static_cast<double>(std::min<std::uint64_t>((x + 1) * span, fullExtent) - x * span);
}

inline std::vector<std::uint8_t> readFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline void writeFile(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

inline std::vector<std::string> listDirectory(const std::filesystem::path& dir) {
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

}  // namespace dsm::test
