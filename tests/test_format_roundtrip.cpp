// The .dsm format round trip: MapWriter -> DeepShadowMap gives back every
// level-0 function bit for bit (depths, values, counts, layer starts) for
// monochrome, mixed RGB/monochrome, counted, multilayer, odd-sized, tiny, long
// and empty maps, with zlib levels 0 to 9; validate() accepts every file; the
// MapInfo fields, the level table (sizes, tolerances, error bounds, totals)
// and the tile directories agree with what was written and with each other.
#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <random>
#include <ostream>
#include <string>
#include <vector>

#include "map_fixtures.h"
#include "oracle.h"
#include "temp_dir.h"

namespace {

using dsm::DeepShadowMap;
using dsm::LevelInfo;
using dsm::MapInfo;
using dsm::TileSummary;
using dsm::VisibilityFunction;
using dsm::WriterOptions;
using dsm::test::Image;
using dsm::test::TempDir;

constexpr double kStoreRounding = 0x1p-25;  // spec: errorBound sums max(tolerance, 2^-25)

using PixelMaker = std::function<VisibilityFunction(std::mt19937_64&, std::uint32_t, std::uint32_t)>;

struct RoundTripCase {
    std::string name;
    std::uint32_t width = 1, height = 1, tileSize = 8;
    int channels = 1;
    bool counts = false;
    int maxLayers = 1;
    int zlibLevel = 6;
    std::optional<unsigned> mipLevels;  // unset: the full pyramid
    double tolerance = 0.01;
    PixelMaker pixel;
};

// gtest prints parameters by name.
void PrintTo(const RoundTripCase& c, std::ostream* os) { *os << c.name; }

// Pixel makers. Each is deterministic given the generator state.
VisibilityFunction monoPixel(std::mt19937_64& rng, std::uint32_t, std::uint32_t) {
    if (std::bernoulli_distribution(0.2)(rng)) return VisibilityFunction(1);
    return dsm::test::randomFunction(rng, 1, false, 1, 8);
}

VisibilityFunction rgbMixedPixel(std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
    switch ((x + 2 * y) % 4) {
        case 0: return dsm::test::randomFunction(rng, 3, false, 1, 7);
        case 1: return dsm::test::randomFunction(rng, 1, false, 1, 7);
        case 2: return VisibilityFunction(3);  // empty RGB
        default: return (x % 3 == 0) ? VisibilityFunction(1) : dsm::test::randomFunction(rng, 3, false, 1, 3);
    }
}

VisibilityFunction countedPixel(std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
    if ((x * 7 + y * 3) % 9 == 0) return VisibilityFunction(1, true);
    return dsm::test::randomFunction(rng, 1, true, 1, 10);
}

VisibilityFunction layeredCountedPixel(std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
    const int layers = static_cast<int>((x + y) % 3) + 1;  // 1, 2 or 3
    if ((x + 3 * y) % 11 == 0) return VisibilityFunction(1, true);
    return dsm::test::randomFunction(rng, 1, true, layers, 4);
}

VisibilityFunction layeredRgbPixel(std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
    const int layers = static_cast<int>((x * 5 + y) % 3) + 1;
    return dsm::test::randomFunction(rng, (x + y) % 2 == 0 ? 3 : 1, false, layers, 3);
}

VisibilityFunction smallPixel(std::mt19937_64& rng, std::uint32_t x, std::uint32_t) {
    if (x % 5 == 4) return VisibilityFunction(1);
    return dsm::test::randomFunction(rng, 1, false, 1, 3);
}

// Tiles of the second tile column (tile size 8) and everything below row 16
// are empty.
VisibilityFunction holePixel(std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
    if ((x >= 8 && x < 16) || y >= 16) return VisibilityFunction(1);
    return dsm::test::randomFunction(rng, 1, false, 1, 5);
}

// Few distinct functions: compresses well with zlib.
VisibilityFunction repetitivePixel(std::mt19937_64&, std::uint32_t x, std::uint32_t y) {
    VisibilityFunction f(1);
    const float base = 1.0f + static_cast<float>((x / 4 + y / 4) % 3);
    for (int i = 0; i < 12; ++i) f.append(base + 0.25f * static_cast<float>(i), 1.0f - static_cast<float>(i) / 12.0f);
    return f;
}

Image makeImage(const RoundTripCase& c, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    return dsm::test::makeImage(c.width, c.height, [&](std::uint32_t x, std::uint32_t y) { return c.pixel(rng, x, y); });
}

WriterOptions optionsFor(const RoundTripCase& c) {
    WriterOptions o;
    o.width = c.width;
    o.height = c.height;
    o.tileSize = c.tileSize;
    o.channels = c.channels;
    o.counts = c.counts;
    o.maxLayers = c.maxLayers;
    o.zlibLevel = c.zlibLevel;
    o.mipLevels = c.mipLevels;
    o.tolerance = c.tolerance;
    o.camera.projection = dsm::Projection::Orthographic;
    o.camera.worldToLight = {0.0, 1.0, 0.0, 2.5, -1.0, 0.0, 0.0, -0.75, 0.0, 0.0, 1.0, 10.0, 0.0, 0.0, 0.0, 1.0};
    o.camera.screenWindow = {-3.0, 5.0, -2.0, 0.5};
    o.camera.nearPlane = 0.125;
    o.filter = dsm::PixelFilter::Gaussian;
    o.filterWidth = 2.75;
    o.metadata = "{\"case\":\"" + c.name + "\",\"text\":\"caf\xc3\xa9 \\u00e9\",\"list\":[1,2.5,null]}";
    return o;
}

// Everything the reader says about `path` is consistent with `options` and
// `image`; level-0 pixels are bit-exact.
void checkRoundTrip(const std::filesystem::path& path, const WriterOptions& options, const Image& image) {
    SCOPED_TRACE(path.string());
    ASSERT_NO_THROW(dsm::validate(path.string()));
    const auto map = DeepShadowMap::open(path.string());
    const MapInfo& info = map->info();
    EXPECT_EQ(info.versionMajor, 1);
    EXPECT_EQ(info.versionMinor, dsm::kFormatVersionMinor);
    EXPECT_TRUE(info.codedTiles);
    EXPECT_EQ(info.codecLevel, options.zlibLevel);
    EXPECT_EQ(info.width, image.width);
    EXPECT_EQ(info.height, image.height);
    EXPECT_EQ(info.tileSize, options.tileSize);
    EXPECT_EQ(info.channels, options.channels);
    EXPECT_EQ(info.hasCounts, options.counts);
    EXPECT_EQ(info.maxLayers, options.maxLayers);
    EXPECT_TRUE(info.camera == options.camera);
    EXPECT_EQ(info.filter, options.filter);
    EXPECT_EQ(info.filterWidth, options.filterWidth);
    EXPECT_EQ(info.metadata, options.metadata);
    EXPECT_EQ(info.fileBytes, std::filesystem::file_size(path));
    EXPECT_EQ(map->path(), path.string());

    const unsigned full = dsm::fullLevelCount(image.width, image.height);
    const unsigned expectedLevels = std::min(options.mipLevels.value_or(full), full);
    ASSERT_EQ(info.levels.size(), expectedLevels);

    // Tolerances halve (times the factor), error bounds add up (spec section 5).
    double tolerance = options.tolerance, bound = 0.0;
    std::uint64_t w = image.width, h = image.height;
    std::vector<std::pair<std::uint64_t, std::uint64_t>> extents;  // [offset, end) of stored tiles
    for (unsigned l = 0; l < info.levels.size(); ++l) {
        SCOPED_TRACE("level " + std::to_string(l));
        const LevelInfo& L = info.levels[l];
        EXPECT_EQ(L.width, w);
        EXPECT_EQ(L.height, h);
        EXPECT_EQ(L.width, dsm::levelExtent(image.width, l));
        EXPECT_EQ(L.height, dsm::levelExtent(image.height, l));
        EXPECT_EQ(L.tilesX, (w + options.tileSize - 1) / options.tileSize);
        EXPECT_EQ(L.tilesY, (h + options.tileSize - 1) / options.tileSize);
        EXPECT_EQ(L.tolerance, tolerance);
        bound += std::max(tolerance, kStoreRounding);
        EXPECT_DOUBLE_EQ(L.errorBound, bound);
        EXPECT_GE(L.errorBound, L.tolerance);

        std::uint64_t vertices = 0, nonEmpty = 0, stored = 0;
        std::uint64_t pixelVertices = 0, pixelNonEmpty = 0;
        for (std::uint32_t ty = 0; ty < L.tilesY; ++ty) {
            for (std::uint32_t tx = 0; tx < L.tilesX; ++tx) {
                SCOPED_TRACE("tile " + std::to_string(tx) + "," + std::to_string(ty));
                const TileSummary t = map->tile(l, tx, ty);
                vertices += t.vertexCount;
                nonEmpty += t.nonEmptyPixels;
                stored += t.storedBytes;
                // The tile's pixels agree with its directory entry.
                std::uint64_t tileVertices = 0, tileNonEmpty = 0;
                float minZ = std::numeric_limits<float>::infinity(), maxZ = -minZ;
                const std::uint32_t x0 = tx * options.tileSize, y0 = ty * options.tileSize;
                const std::uint32_t x1 = std::min<std::uint32_t>(x0 + options.tileSize, L.width);
                const std::uint32_t y1 = std::min<std::uint32_t>(y0 + options.tileSize, L.height);
                for (std::uint32_t y = y0; y < y1; ++y) {
                    for (std::uint32_t x = x0; x < x1; ++x) {
                        const dsm::PixelFunction p = map->pixel(l, x, y);
                        const dsm::VisibilityView& f = p.view();
                        tileVertices += f.size();
                        if (!f.empty()) {
                            ++tileNonEmpty;
                            minZ = std::min(minZ, f.z(0));
                            maxZ = std::max(maxZ, f.z(f.size() - 1));
                        }
                        if (l == 0) {
                            EXPECT_TRUE(dsm::test::sameFunction(f, image.at(x, y), options.counts))
                                << "pixel " << x << "," << y;
                        } else {
                            EXPECT_EQ(f.layerCount(), 1u) << "pixel " << x << "," << y;
                            EXPECT_LE(f.channels(), options.channels) << "pixel " << x << "," << y;
                            EXPECT_EQ(f.hasCounts(), options.counts && !f.empty()) << "pixel " << x << "," << y;
                        }
                    }
                }
                pixelVertices += tileVertices;
                pixelNonEmpty += tileNonEmpty;
                EXPECT_EQ(t.vertexCount, tileVertices);
                EXPECT_EQ(t.nonEmptyPixels, tileNonEmpty);
                EXPECT_EQ(t.empty(), tileVertices == 0);
                if (t.empty()) {
                    EXPECT_EQ(t.storedBytes, 0u);
                    EXPECT_EQ(t.rawBytes, 0u);
                    EXPECT_EQ(t.offset, 0u);
                    EXPECT_EQ(t.crc32, 0u);
                } else {
                    EXPECT_EQ(t.minZ, minZ);
                    EXPECT_EQ(t.maxZ, maxZ);
                    EXPECT_GT(t.storedBytes, 0u);
                    EXPECT_LE(t.storedBytes, t.rawBytes);
                    if (options.zlibLevel == 0) {
                        EXPECT_EQ(t.storedBytes, t.rawBytes);
                    }
                    EXPECT_GE(t.offset, 296u);  // the 1.1 header
                    EXPECT_LE(t.offset + t.storedBytes, info.fileBytes);
                    extents.emplace_back(t.offset, t.offset + t.storedBytes);
                }
            }
        }
        EXPECT_EQ(L.vertexCount, vertices);
        EXPECT_EQ(L.nonEmptyPixels, nonEmpty);
        EXPECT_EQ(L.storedBytes, stored);
        EXPECT_EQ(L.vertexCount, pixelVertices);
        EXPECT_EQ(L.nonEmptyPixels, pixelNonEmpty);
        if (l == 0) {
            std::uint64_t written = 0, writtenNonEmpty = 0;
            for (const VisibilityFunction& f : image.pixels) {
                written += f.size();
                writtenNonEmpty += f.empty() ? 0 : 1;
            }
            EXPECT_EQ(L.vertexCount, written);
            EXPECT_EQ(L.nonEmptyPixels, writtenNonEmpty);
        }
        tolerance *= options.levelToleranceFactor;
        w = (w + 1) / 2;
        h = (h + 1) / 2;
    }
    // Stored tiles do not overlap one another.
    std::sort(extents.begin(), extents.end());
    for (std::size_t i = 1; i < extents.size(); ++i) EXPECT_LE(extents[i - 1].second, extents[i].first);
}

class RoundTrip : public ::testing::TestWithParam<RoundTripCase> {};

TEST_P(RoundTrip, LevelZeroIsBitExactAndEverythingValidates) {
    const RoundTripCase& c = GetParam();
    TempDir dir;
    const Image image = makeImage(c, 0x5eed0000u + c.width * 131u + c.height);
    const WriterOptions options = optionsFor(c);
    const auto path = dir / (c.name + ".dsm");
    dsm::test::writeMap(path, options, image, /*seed=*/c.width + 7u * c.height);
    checkRoundTrip(path, options, image);
    // The same content written in row order reads back the same.
    const auto rowOrder = dir / (c.name + "-rows.dsm");
    dsm::test::writeMap(rowOrder, options, image, 0);
    checkRoundTrip(rowOrder, options, image);
}

RoundTripCase make(std::string name, std::uint32_t w, std::uint32_t h, std::uint32_t tile, PixelMaker pixel) {
    RoundTripCase c;
    c.name = std::move(name);
    c.width = w;
    c.height = h;
    c.tileSize = tile;
    c.pixel = std::move(pixel);
    return c;
}

std::vector<RoundTripCase> cases() {
    std::vector<RoundTripCase> out;
    out.push_back(make("mono", 24, 16, 8, monoPixel));
    {
        RoundTripCase c = make("rgb_with_mono_pixels", 20, 13, 4, rgbMixedPixel);
        c.channels = 3;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("counts", 16, 16, 8, countedPixel);
        c.counts = true;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("mtsm_counts", 13, 9, 4, layeredCountedPixel);
        c.counts = true;
        c.maxLayers = 3;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("mtsm_rgb", 10, 11, 8, layeredRgbPixel);
        c.channels = 3;
        c.maxLayers = 3;
        out.push_back(c);
    }
    out.push_back(make("odd_37x21_tile8", 37, 21, 8, monoPixel));
    out.push_back(make("one_by_one", 1, 1, 32, monoPixel));
    {
        RoundTripCase c = make("one_by_one_rgb", 1, 1, 2, rgbMixedPixel);
        c.channels = 3;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("long_4097x3_tile64", 4097, 3, 64, smallPixel);
        c.tolerance = 0.02;
        out.push_back(c);
    }
    out.push_back(make("tall_3x70_tile2", 3, 70, 2, smallPixel));
    out.push_back(make("empty_tiles", 40, 24, 8, holePixel));
    out.push_back(make("all_empty", 10, 9, 4, [](std::mt19937_64&, std::uint32_t, std::uint32_t) {
        return VisibilityFunction(1);
    }));
    {
        RoundTripCase c = make("zlib0_stored", 17, 12, 8, monoPixel);
        c.zlibLevel = 0;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("zlib9", 17, 12, 8, repetitivePixel);
        c.zlibLevel = 9;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("zlib0_rgb_counts_layers", 9, 9, 4, [](std::mt19937_64& rng, std::uint32_t x,
                                                                       std::uint32_t y) {
            return dsm::test::randomFunction(rng, (x + y) % 2 ? 3 : 1, true, 1 + static_cast<int>(x % 2), 4);
        });
        c.zlibLevel = 0;
        c.channels = 3;
        c.counts = true;
        c.maxLayers = 2;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("tolerance_zero", 11, 6, 4, monoPixel);
        c.tolerance = 0.0;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("no_mipmaps", 19, 5, 4, monoPixel);
        c.mipLevels = 1;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("three_levels", 19, 5, 4, monoPixel);
        c.mipLevels = 3;
        out.push_back(c);
    }
    {
        RoundTripCase c = make("mip_levels_capped", 6, 5, 2, monoPixel);
        c.mipLevels = 99;
        out.push_back(c);
    }
    return out;
}

INSTANTIATE_TEST_SUITE_P(Maps, RoundTrip, ::testing::ValuesIn(cases()),
                         [](const ::testing::TestParamInfo<RoundTripCase>& i) { return i.param.name; });

TEST(RoundTripDetails, EmptyTilesStoreNothing) {
    TempDir dir;
    std::mt19937_64 rng(3);
    const Image image = dsm::test::makeImage(40, 24, [&](std::uint32_t x, std::uint32_t y) { return holePixel(rng, x, y); });
    WriterOptions o;
    o.tileSize = 8;
    dsm::test::writeMap(dir / "holes.dsm", o, image);
    const auto map = DeepShadowMap::open((dir / "holes.dsm").string());
    for (std::uint32_t ty = 0; ty < 3; ++ty) {
        for (std::uint32_t tx = 0; tx < 5; ++tx) {
            const TileSummary t = map->tile(0, tx, ty);
            const bool shouldBeEmpty = tx == 1 || ty == 2;
            EXPECT_EQ(t.empty(), shouldBeEmpty) << tx << "," << ty;
            if (shouldBeEmpty) {
                EXPECT_EQ(t.storedBytes, 0u);
                EXPECT_EQ(t.vertexCount, 0u);
                EXPECT_EQ(t.nonEmptyPixels, 0u);
                // Every pixel of an empty tile is fully lit.
                const auto p = map->pixel(0, tx * 8 + 3, ty * 8 + 5);
                EXPECT_TRUE(p->empty());
                EXPECT_EQ(p->evaluate(1e6), 1.0);
            }
        }
    }
    // At level 1 the empty tile column (pixels 4..7) lies inside tile 0,0 and
    // the empty rows (8..11) fill tile row 1: those coarser tiles are empty.
    EXPECT_FALSE(map->tile(1, 0, 0).empty());
    EXPECT_TRUE(map->tile(1, 0, 1).empty());
    EXPECT_TRUE(map->pixel(1, 5, 2)->empty());
    EXPECT_FALSE(map->pixel(1, 3, 2)->empty());
}

TEST(RoundTripDetails, AllEmptyMapHasNoTileData) {
    TempDir dir;
    const Image image = dsm::test::makeImage(33, 7, [](std::uint32_t, std::uint32_t) { return VisibilityFunction(3); });
    WriterOptions o;
    o.tileSize = 4;
    o.channels = 3;
    dsm::test::writeMap(dir / "empty.dsm", o, image);
    ASSERT_NO_THROW(dsm::validate((dir / "empty.dsm").string()));
    const auto map = DeepShadowMap::open((dir / "empty.dsm").string());
    for (const LevelInfo& L : map->info().levels) {
        EXPECT_EQ(L.vertexCount, 0u);
        EXPECT_EQ(L.nonEmptyPixels, 0u);
        EXPECT_EQ(L.storedBytes, 0u);
    }
    // Header, directories, level table and metadata only.
    std::uint64_t directoryBytes = 0;
    for (const LevelInfo& L : map->info().levels) directoryBytes += std::uint64_t(L.tilesX) * L.tilesY * 40;
    // The 1.1 header (296 bytes) and level entries (80 bytes).
    EXPECT_EQ(map->info().fileBytes, 296 + directoryBytes + 80 * map->info().levels.size() + o.metadata.size());
}

TEST(RoundTripDetails, ZlibLevelsChangeOnlyTheStoredBytes) {
    TempDir dir;
    std::mt19937_64 rng(9);
    const Image image = dsm::test::makeImage(17, 12, [&](std::uint32_t x, std::uint32_t y) { return repetitivePixel(rng, x, y); });
    WriterOptions stored, packed;
    stored.tileSize = packed.tileSize = 8;
    stored.zlibLevel = 0;
    packed.zlibLevel = 9;
    dsm::test::writeMap(dir / "stored.dsm", stored, image);
    dsm::test::writeMap(dir / "packed.dsm", packed, image);
    const auto a = DeepShadowMap::open((dir / "stored.dsm").string());
    const auto b = DeepShadowMap::open((dir / "packed.dsm").string());
    EXPECT_LT(b->info().fileBytes, a->info().fileBytes);
    bool anyCompressed = false;
    for (unsigned l = 0; l < a->info().levels.size(); ++l) {
        const LevelInfo& L = a->info().levels[l];
        for (std::uint32_t ty = 0; ty < L.tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < L.tilesX; ++tx) {
                const TileSummary ta = a->tile(l, tx, ty), tb = b->tile(l, tx, ty);
                EXPECT_EQ(ta.storedBytes, ta.rawBytes);
                EXPECT_EQ(ta.rawBytes, tb.rawBytes);
                EXPECT_LE(tb.storedBytes, tb.rawBytes);
                anyCompressed = anyCompressed || tb.storedBytes < tb.rawBytes;
                EXPECT_EQ(ta.vertexCount, tb.vertexCount);
            }
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x)
                EXPECT_TRUE(dsm::test::sameFunction(a->pixel(l, x, y).view(), b->pixel(l, x, y)->toFunction(), false));
    }
    EXPECT_TRUE(anyCompressed);
}

TEST(RoundTripDetails, CountsOfFunctionsAreDroppedByAMapWithoutCounts) {
    TempDir dir;
    std::mt19937_64 rng(4);
    const Image image = dsm::test::makeImage(6, 6, [&](std::uint32_t, std::uint32_t) {
        return dsm::test::randomFunction(rng, 1, true, 1, 5);
    });
    WriterOptions o;
    o.tileSize = 4;
    dsm::test::writeMap(dir / "nocounts.dsm", o, image);
    const auto map = DeepShadowMap::open((dir / "nocounts.dsm").string());
    EXPECT_FALSE(map->info().hasCounts);
    for (std::uint32_t y = 0; y < 6; ++y)
        for (std::uint32_t x = 0; x < 6; ++x)
            EXPECT_TRUE(dsm::test::sameFunction(map->pixel(0, x, y).view(), image.at(x, y), false));
}

TEST(RoundTripDetails, CameraAndMetadataRoundTripForAPerspectiveLight) {
    TempDir dir;
    WriterOptions o;
    o.tileSize = 2;
    o.camera.projection = dsm::Projection::Perspective;
    o.camera.worldToLight = {0.8, 0.0, -0.6, 1.0, 0.0, 1.0, 0.0, -2.0, 0.6, 0.0, 0.8, 3.0, 0.0, 0.0, 0.0, 1.0};
    o.camera.screenWindow = {-0.3, 0.7, -0.2, 0.45};
    o.camera.nearPlane = 0.01;
    o.filter = dsm::PixelFilter::Triangle;
    o.filterWidth = 0.0;  // allowed: >= 0
    o.metadata = std::string(5000, 'x') + "\n{}";
    std::mt19937_64 rng(1);
    const Image image = dsm::test::makeImage(3, 2, [&](std::uint32_t x, std::uint32_t y) { return monoPixel(rng, x, y); });
    dsm::test::writeMap(dir / "camera.dsm", o, image);
    const auto map = DeepShadowMap::open((dir / "camera.dsm").string());
    EXPECT_TRUE(map->info().camera == o.camera);
    EXPECT_EQ(map->info().filter, dsm::PixelFilter::Triangle);
    EXPECT_EQ(map->info().filterWidth, 0.0);
    EXPECT_EQ(map->info().metadata, o.metadata);
    checkRoundTrip(dir / "camera.dsm", o, image);
}

}  // namespace
