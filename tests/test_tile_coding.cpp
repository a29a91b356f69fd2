// Format 1.1 tile coding: value steps chosen from the tolerance, the stated
// bound holding for the values as stored, bit-exact round trips of coded
// tiles (with and without value steps), 1.0 files still read, and the codec,
// its level and the area light recorded in the header, and the decoder's
// checks agreeing with VisibilityView::validate().
#include <dsm/dsm.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <vector>
#include <atomic>
#include <thread>

#include <zlib.h>

#include "map_fixtures.h"
#include "oracle.h"
#include "temp_dir.h"
#include "byte_io.h"
#include "format_layout.h"
#include "tile_codec.h"

namespace {

using dsm::DeepShadowMap;
using dsm::VisibilityFunction;
using dsm::WriterOptions;
using dsm::test::Image;
using dsm::test::TempDir;

WriterOptions smallMap(double tolerance) {
    WriterOptions o;
    o.tileSize = 4;
    o.channels = 3;
    o.counts = true;
    o.maxLayers = 3;
    o.tolerance = tolerance;
    return o;
}

Image randomImage(std::uint32_t width, std::uint32_t height, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    return dsm::test::makeImage(width, height, [&](std::uint32_t, std::uint32_t) {
        if (std::bernoulli_distribution(0.15)(rng)) return VisibilityFunction(3, true);
        const int channels = std::bernoulli_distribution(0.5)(rng) ? 3 : 1;
        const int layers = std::uniform_int_distribution<int>(1, 3)(rng);
        return dsm::test::randomFunction(rng, channels, true, layers, 9);
    });
}

// The largest |a - b| over both functions' vertex depths, just before them and
// midway between them, per channel and per layer.
double largestDifference(const dsm::VisibilityView& a, const dsm::VisibilityView& b) {
    std::vector<double> probes;
    for (const auto* f : {&a, &b})
        for (float z : f->depths()) {
            probes.push_back(z);
            probes.push_back(std::nextafter(z, -1.0f));
        }
    std::sort(probes.begin(), probes.end());
    const std::size_t n = probes.size();
    for (std::size_t i = 0; i + 1 < n; ++i) probes.push_back(0.5 * (probes[i] + probes[i + 1]));
    double worst = 0.0;
    const int channels = std::max(a.channels(), b.channels());
    for (std::size_t layer = 0; layer < a.layerCount(); ++layer)
        for (double z : probes)
            for (int c = 0; c < channels; ++c)
                worst = std::max(worst, std::abs(a.evaluateLayer(layer, z, std::min(c, a.channels() - 1)) -
                                                 b.evaluateLayer(layer, z, std::min(c, b.channels() - 1))));
    return worst;
}

}  // namespace

// The CRC-32 of sections and tiles (folded 64 bytes at a time where the
// processor can) against its bitwise definition: every length up to 300 at
// every alignment within 16 bytes, and longer ranges with ragged ends.
TEST(TileCoding, Crc32MatchesItsBitwiseDefinitionAtEveryLengthAndAlignment) {
    const auto bitwise = [](const std::uint8_t* data, std::size_t size) {
        std::uint32_t crc = 0xFFFFFFFFu;
        for (std::size_t i = 0; i < size; ++i) {
            crc ^= data[i];
            for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
        }
        return ~crc;
    };
    std::mt19937 rng(7);
    std::vector<std::uint8_t> bytes(70000);
    for (std::uint8_t& b : bytes) b = static_cast<std::uint8_t>(rng());
    for (std::size_t offset = 0; offset < 16; ++offset)
        for (std::size_t size = 0; size <= 300; ++size)
            ASSERT_EQ(dsm::format::crc32(bytes.data() + offset, size), bitwise(bytes.data() + offset, size))
                << offset << " + " << size;
    for (const std::size_t size : {1023u, 4096u, 4101u, 65535u, 69984u})
        EXPECT_EQ(dsm::format::crc32(bytes.data() + 3, size), bitwise(bytes.data() + 3, size)) << size;
}

// The block read of a run (readInto) against as many byte-by-byte reads:
// the same values, flag and position after every length at its boundaries,
// values beyond 32 bits (a fifth byte above 0x0F, no end within 5 bytes),
// over-long encodings and random bytes, in runs long enough for several
// blocks and ending at every distance from the end of the data.
TEST(TileCoding, TheBlockReadOfARunMatchesValueByValueReads) {
    std::vector<std::vector<std::uint8_t>> encodings;
    for (const std::uint32_t v : {0u, 1u, 127u, 128u, 300u, 16383u, 16384u, (1u << 21) - 1, 1u << 21,
                                  (1u << 28) - 1, 1u << 28, 0x12345678u, 0xFFFFFFFFu}) {
        std::vector<std::uint8_t> bytes;
        dsm::detail::ByteWriter(bytes).varint(v);
        encodings.push_back(bytes);
    }
    encodings.push_back({0x80, 0x80, 0x80, 0x80, 0x10});        // 2^32: a fifth byte above 0x0F
    encodings.push_back({0xFF, 0xFF, 0xFF, 0xFF, 0x7F});        // beyond 32 bits
    encodings.push_back({0x80, 0x80, 0x80, 0x80, 0x80, 0x01});  // no end within 5 bytes
    encodings.push_back({0x81, 0x80, 0x00});                    // an over-long 1
    encodings.push_back({0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF,
                         0xFF, 0xFF, 0x00});  // no end within a block
    std::mt19937 rng(3);
    for (int trial = 0; trial < 4000; ++trial) {
        std::vector<std::uint8_t> bytes;
        const std::size_t encoded = rng() % 240;
        for (std::size_t k = 0; k < encoded; ++k) {
            if (rng() % 8 == 0) {
                bytes.push_back(static_cast<std::uint8_t>(rng()));  // a random byte
                continue;
            }
            // Mostly the lengths of real depths (1 to 3 bytes), now and then any.
            const auto& e = encodings[rng() % 4 == 0 ? rng() % encodings.size() : 3 + rng() % 6];
            bytes.insert(bytes.end(), e.begin(), e.end());
        }
        // Asked for more or fewer values than were written.
        const std::size_t count = rng() % (encoded + 8);
        std::vector<std::uint32_t> expected(count), got(count, 0xDEADBEEF);
        dsm::detail::VarintReader byOne(bytes.data(), bytes.data() + bytes.size());
        for (std::uint32_t& v : expected) v = byOne.next();
        dsm::detail::VarintReader inBlocks(bytes.data(), bytes.data() + bytes.size());
        inBlocks.readInto(got.data(), count);
        ASSERT_EQ(got, expected) << "trial " << trial;
        ASSERT_EQ(inBlocks.ok(), byOne.ok()) << "trial " << trial;
        ASSERT_EQ(inBlocks.remaining(), byOne.remaining()) << "trial " << trial;
    }
}

TEST(TileCoding, ValueStepIsThePowerOfTwoWithinAnEighthOfTheTolerance) {
    EXPECT_EQ(dsm::valueStep(0.0), 0.0);
    EXPECT_EQ(dsm::valueStep(-1.0), 0.0);
    EXPECT_EQ(dsm::valueStep(std::nan("")), 0.0);
    EXPECT_EQ(dsm::valueStep(0x1p-22), 0.0);      // an eighth of it is below 2^-24
    EXPECT_EQ(dsm::valueStep(0x1p-21), 0x1p-24);  // the finest step
    EXPECT_EQ(dsm::valueStep(0.01), 0x1p-10);     // 0.00125 -> 2^-10 = 0.00098...
    EXPECT_EQ(dsm::valueStep(0.125), 0x1p-6);
    EXPECT_EQ(dsm::valueStep(100.0), 0.5);        // never coarser than 1/2
    EXPECT_EQ(dsm::compressorTolerance(0.125), 0.125 - 0x1p-7);
    EXPECT_EQ(dsm::compressorTolerance(0.0), 0.0);
}

TEST(TileCoding, RoundedValuesStayInRangeAndNonIncreasing) {
    std::mt19937_64 rng(3);
    for (int i = 0; i < 200; ++i) {
        const VisibilityFunction f = dsm::test::randomFunction(rng, 3, true, 2, 12);
        const VisibilityFunction r = dsm::roundValues(f, 0x1p-3);
        EXPECT_NO_THROW(r.validate());
        ASSERT_EQ(r.size(), f.size());
        for (std::size_t v = 0; v < f.size(); ++v) {
            EXPECT_EQ(r.z(v), f.z(v));
            EXPECT_EQ(r.count(v), f.count(v));
            for (int c = 0; c < 3; ++c) {
                EXPECT_LE(std::abs(double(r.value(v, c)) - f.value(v, c)), 0x1p-4);
                EXPECT_EQ(std::fmod(double(r.value(v, c)), 0x1p-3), 0.0);
            }
        }
    }
}

// What the builder does: compress with compressorTolerance(epsilon), hand the
// result to a writer that stores values to the level's step. Read back, every
// stored function is within the stated epsilon of the input function.
TEST(TileCoding, TheStatedToleranceHoldsForTheValuesAsStored) {
    TempDir dir;
    std::mt19937_64 rng(17);
    for (double tolerance : {0.003, 0.02, 0.1, 0.3}) {
        const std::uint32_t width = 9, height = 7;
        std::vector<VisibilityFunction> inputs;
        Image image;
        image.width = width;
        image.height = height;
        dsm::CompressorOptions co;
        co.tolerance = dsm::compressorTolerance(tolerance);
        co.channels = 3;
        co.keepCounts = true;
        dsm::Compressor compressor(co);
        for (std::uint32_t p = 0; p < width * height; ++p) {
            VisibilityFunction input = dsm::test::randomFunction(rng, 3, true, 1, 60);
            for (std::size_t i = 0; i < input.size(); ++i) compressor.push(input.z(i), input.values(i), input.count(i));
            image.pixels.push_back(compressor.finish());
            inputs.push_back(std::move(input));
        }
        WriterOptions o = smallMap(tolerance);
        o.maxLayers = 1;
        o.quantiseValues = true;
        o.mipLevels = 1;
        const auto path = dir / "bound.dsm";
        dsm::test::writeMap(path, o, image);
        const auto map = DeepShadowMap::open(path.string());
        const dsm::LevelInfo& level = map->info().levels.at(0);
        ASSERT_EQ(level.valueStep, dsm::valueStep(tolerance));
        ASSERT_GT(level.valueStep, 0.0);
        ASSERT_EQ(level.tolerance, tolerance);
        double worst = 0.0;
        for (std::uint32_t y = 0; y < height; ++y)
            for (std::uint32_t x = 0; x < width; ++x) {
                const dsm::PixelFunction stored = map->pixel(0, x, y);
                for (float v : stored->allValues()) EXPECT_EQ(std::fmod(double(v), level.valueStep), 0.0);
                worst = std::max(worst, largestDifference(inputs[y * width + x].view(), stored.view()));
            }
        EXPECT_LE(worst, tolerance + 1e-12) << "tolerance " << tolerance;
        // The rounding is not free: without the room the compressor leaves
        // for it, the bound would be at risk.
        EXPECT_GT(worst, tolerance - level.valueStep) << "tolerance " << tolerance;
    }
}

// Coded tiles give back every function bit for bit: without a value step any
// float32 values, with one the multiples of it the writer stores.
TEST(TileCoding, CodedTilesRoundTripBitForBit) {
    TempDir dir;
    const Image image = randomImage(11, 6, 5);
    for (bool quantise : {false, true}) {
        for (int zlibLevel : {0, 6, -1}) {  // -1: zstd
            WriterOptions o = smallMap(0.05);
            o.quantiseValues = quantise;
            o.zlibLevel = std::max(zlibLevel, 0);
            if (zlibLevel < 0) {
                o.codec = dsm::TileCodec::Zstd;
                o.zstdLevel = 19;
            }
            const auto path = dir / "coded.dsm";
            dsm::test::writeMap(path, o, image, 7);
            EXPECT_NO_THROW(dsm::validate(path.string()));
            const auto map = DeepShadowMap::open(path.string());
            EXPECT_TRUE(map->info().codedTiles);
            EXPECT_EQ(map->info().codec, zlibLevel < 0 ? dsm::TileCodec::Zstd : dsm::TileCodec::Zlib);
            EXPECT_EQ(map->info().codecLevel, zlibLevel < 0 ? 19 : zlibLevel);
            const double step = map->info().levels[0].valueStep;
            EXPECT_EQ(step, quantise ? dsm::valueStep(0.05) : 0.0);
            for (std::uint32_t y = 0; y < image.height; ++y)
                for (std::uint32_t x = 0; x < image.width; ++x) {
                    const VisibilityFunction want = dsm::roundValues(image.at(x, y), step);
                    EXPECT_TRUE(dsm::test::sameFunction(map->pixel(0, x, y).view(), want, true))
                        << "pixel " << x << "," << y << " quantise " << quantise << " zlib " << zlibLevel;
                }
        }
    }
}

// A grey pixel (no vertices, or its channels equal at every vertex) is written
// monochrome in both layouts, so a map's bytes do not depend on the channels
// its grey pixels were made with: a stitch, whose parts store a tile without
// vertices as empty, relies on it.
TEST(TileCoding, GreyPixelsAreWrittenAlikeWhateverTheirChannels) {
    TempDir dir;
    const auto image = [](int greyChannels) {
        return dsm::test::makeImage(6, 5, [=](std::uint32_t x, std::uint32_t y) {
            if ((x + y) % 3 == 1) return VisibilityFunction(greyChannels, true);
            std::mt19937_64 rng(x * 7 + y);
            if ((x + y) % 3 == 2) {
                const VisibilityFunction grey = dsm::test::randomFunction(rng, 1, true, 1, 5);
                if (greyChannels == 1) return grey;
                VisibilityFunction rgb(3, true);
                for (std::size_t i = 0; i < grey.size(); ++i) {
                    const float v[3] = {grey.value(i, 0), grey.value(i, 0), grey.value(i, 0)};
                    rgb.append(grey.z(i), v, grey.count(i));
                }
                return rgb;
            }
            return dsm::test::randomFunction(rng, 3, true, 1, 5);
        });
    };
    for (bool coded : {true, false}) {
        WriterOptions o = smallMap(0.05);
        o.formatMinor = coded ? 1 : 0;
        const auto rgb = dir / "grey-rgb.dsm", mono = dir / "grey-mono.dsm";
        dsm::test::writeMap(rgb, o, image(3), 7);
        dsm::test::writeMap(mono, o, image(1), 7);
        EXPECT_TRUE(dsm::test::readFile(rgb) == dsm::test::readFile(mono)) << "coded " << coded;
        const auto map = DeepShadowMap::open(rgb.string());
        EXPECT_EQ(map->pixel(0, 1, 0)->channels(), 1) << "coded " << coded;  // no vertices
        EXPECT_EQ(map->pixel(0, 2, 0)->channels(), 1) << "coded " << coded;  // grey
        EXPECT_GT(map->pixel(0, 2, 0)->size(), 0u);
        EXPECT_EQ(map->pixel(0, 0, 0)->channels(), 3) << "coded " << coded;
    }
}

// The same content written as 1.0 and as 1.1 reads back the same, and the
// 1.1 tiles are smaller.
TEST(TileCoding, FormatOneZeroFilesStillReadAndOneOneTilesAreSmaller) {
    TempDir dir;
    const Image image = randomImage(16, 16, 9);
    WriterOptions o = smallMap(0.0);
    o.formatMinor = 0;
    dsm::test::writeMap(dir / "old.dsm", o, image);
    o.formatMinor = 1;
    dsm::test::writeMap(dir / "new.dsm", o, image);
    const auto older = DeepShadowMap::open((dir / "old.dsm").string());
    const auto newer = DeepShadowMap::open((dir / "new.dsm").string());
    EXPECT_EQ(older->info().versionMinor, 0);
    EXPECT_FALSE(older->info().codedTiles);
    EXPECT_EQ(older->info().codecLevel, -1);  // 1.0 records no level
    EXPECT_EQ(newer->info().versionMinor, 1);
    EXPECT_TRUE(newer->info().codedTiles);
    EXPECT_EQ(newer->info().codecLevel, 6);
    for (unsigned l = 0; l < older->info().levels.size(); ++l) {
        const dsm::LevelInfo& L = older->info().levels[l];
        EXPECT_LT(newer->info().levels[l].storedBytes, L.storedBytes) << "level " << l;
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x)
                EXPECT_TRUE(dsm::test::sameFunction(newer->pixel(l, x, y).view(),
                                                    older->pixel(l, x, y)->toFunction(), true))
                    << "level " << l << " pixel " << x << "," << y;
    }
}

TEST(TileCoding, TheHeaderRecordsTheCodecLevelAndTheAreaLight) {
    TempDir dir;
    const Image image = randomImage(5, 5, 2);
    WriterOptions o = smallMap(0.01);
    o.zlibLevel = 3;
    o.areaLightRadius = 0.25;
    o.areaLightPlaneDepth = 0.75;
    dsm::test::writeMap(dir / "light.dsm", o, image);
    const auto map = DeepShadowMap::open((dir / "light.dsm").string());
    EXPECT_EQ(map->info().codec, dsm::TileCodec::Zlib);
    EXPECT_EQ(map->info().codecLevel, 3);
    EXPECT_EQ(map->info().areaLightRadius, 0.25);
    EXPECT_EQ(map->info().areaLightPlaneDepth, 0.75);

    o.codec = dsm::TileCodec::Zstd;
    o.zstdLevel = 12;
    dsm::test::writeMap(dir / "zstd.dsm", o, image);
    const auto zstdMap = DeepShadowMap::open((dir / "zstd.dsm").string());
    EXPECT_EQ(zstdMap->info().codec, dsm::TileCodec::Zstd);
    EXPECT_EQ(zstdMap->info().codecLevel, 12);
    EXPECT_NO_THROW(dsm::validate((dir / "zstd.dsm").string()));
    o.zstdLevel = 23;
    EXPECT_THROW(dsm::test::writeMap(dir / "bad.dsm", o, image), dsm::Error);
    o.zstdLevel = 12;
    o.formatMinor = 0;  // 1.0 knows zlib alone
    EXPECT_THROW(dsm::test::writeMap(dir / "old.dsm", o, image), dsm::Error);
    o.codec = dsm::TileCodec::Zlib;

    // 1.0 has no place for the area light
    EXPECT_THROW(dsm::test::writeMap(dir / "old.dsm", o, image), dsm::Error);
    o.areaLightRadius = 0.0;
    o.quantiseValues = true;
    EXPECT_THROW(dsm::test::writeMap(dir / "old.dsm", o, image), dsm::Error);
    o.formatMinor = 2;
    o.quantiseValues = false;
    EXPECT_THROW(dsm::test::writeMap(dir / "new.dsm", o, image), dsm::Error);
}

// The coded decoder checks each function while it decodes it; whatever it
// lets through must be what VisibilityView::validate() accepts, and what it
// rejects must be reported as validate() reports it.
TEST(TileCoding, DecodingRejectsExactlyWhatValidationRejects) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    struct Case {
        const char* name;
        std::vector<std::vector<float>> layers;  // z, V pairs per layer
        int channels = 1;
    };
    const std::vector<Case> cases = {
        {"valid", {{1.0f, 0.5f, 2.0f, 0.25f}}},
        {"valid layers", {{1.0f, 0.5f, 2.0f, 0.0f}, {2.0f, 0.75f, 3.0f, 0.5f}}},
        {"negative zero depth", {{-0.0f, 0.5f, 1.0f, 0.25f}}},
        {"decreasing depth", {{2.0f, 0.5f, 1.0f, 0.25f}}},
        {"negative depth", {{-1.0f, 0.5f}}},
        {"negative depth later", {{1.0f, 0.5f, -1.0f, 0.25f}}},
        {"nan depth", {{1.0f, 0.5f, nan, 0.25f}}},
        {"infinite depth", {{1.0f, 0.5f, inf, 0.25f}}},
        {"increasing value", {{1.0f, 0.5f, 2.0f, 0.75f}}},
        {"value above one", {{1.0f, 1.5f}}},
        {"negative value", {{1.0f, -0.5f}}},
        {"nan value", {{1.0f, nan}}},
        {"empty layer", {{1.0f, 0.5f}, {}, {2.0f, 0.5f, 3.0f, 0.25f}}},
        {"trailing empty layer", {{1.0f, 0.5f, 2.0f, 0.25f}, {}}},
        {"rgb increasing", {{1.0f, 0.5f, 2.0f, 0.25f}}, 3},
    };
    for (const Case& c : cases) {
        for (const double step : {0.0, 1.0 / 128}) {
            VisibilityFunction f(c.channels);
            for (std::size_t l = 0; l < c.layers.size(); ++l) {
                if (l > 0) f.beginLayer();
                for (std::size_t i = 0; i + 1 < c.layers[l].size(); i += 2) {
                    float v[3] = {c.layers[l][i + 1], c.layers[l][i + 1], c.layers[l][i + 1]};
                    if (c.channels == 3 && i > 0) v[1] = 1.0f;  // green rises
                    f.append(c.layers[l][i], v);
                }
            }
            const auto values = f.allValues();
            if (step > 0.0 && std::any_of(values.begin(), values.end(), [](float v) { return !(v >= 0.0f && v < 2.0f); }))
                continue;  // no multiple of a step the coding can hold
            std::string validateError;
            try {
                f.validate();
            } catch (const dsm::Error& e) {
                validateError = e.what();
            }
            const dsm::format::TileLayout layout{c.channels, false, 3, true, step};
            const std::vector<VisibilityFunction> pixels = {VisibilityFunction(c.channels), f};
            const dsm::format::EncodedTile tile = dsm::format::encodeTile(pixels, layout, 0);
            std::string decodeError;
            try {
                const dsm::format::DecodedTile decoded = dsm::format::decodeTile(
                    tile.stored, tile.summary, 2, 1, layout, dsm::ReaderOptions{}, "tile", 0, 0);
                EXPECT_TRUE(dsm::test::sameFunction(decoded.pixel(1), f, false)) << c.name << " step " << step;
            } catch (const dsm::Error& e) {
                decodeError = e.what();
            }
            if (validateError.empty())
                EXPECT_EQ(decodeError, "") << c.name << " step " << step;
            else
                EXPECT_THAT(decodeError, testing::HasSubstr("tile: pixel 1,0: " + validateError))
                    << c.name << " step " << step;
        }
    }
}

// The decoder keeps zstd contexts for reuse across tiles and threads: tiles
// decoded from four threads at once, good ones among damaged ones (whose
// failure must hand the context back as well), decode as one thread does.
TEST(TileCoding, ZstdTilesDecodeAlikeFromManyThreadsAtOnce) {
    constexpr std::uint32_t width = 8, height = 8;
    std::vector<VisibilityFunction> pixels;
    for (std::uint32_t p = 0; p < width * height; ++p) {
        VisibilityFunction f(1);
        for (int i = 0; i < 12; ++i) {
            const float v = 1.0f - static_cast<float>(i) / 16.0f;
            f.append(1.0f + 0.25f * static_cast<float>(i) + 0.001f * static_cast<float>(p % 5), &v);
        }
        pixels.push_back(f);
    }
    dsm::format::TileLayout layout{1, false, 1, true, 0.0};
    layout.codec = dsm::TileCodec::Zstd;
    layout.predictedDepths = true;
    const dsm::format::EncodedTile good = dsm::format::encodeTile(pixels, layout, 3);
    ASSERT_LT(good.summary.storedBytes, good.summary.rawBytes);  // compressed: zstd decodes it
    dsm::format::EncodedTile damaged = good;
    damaged.stored.resize(damaged.stored.size() - 4);  // the frame cut short, resealed
    damaged.summary.storedBytes = damaged.stored.size();
    damaged.summary.crc32 = dsm::format::crc32(damaged.stored.data(), damaged.stored.size());

    const auto decodeGood = [&] {
        return dsm::format::decodeTile(good.stored, good.summary, width, height, layout, dsm::ReaderOptions{}, "tile",
                                       0, 0);
    };
    const dsm::format::DecodedTile once = decodeGood();
    for (std::uint32_t p = 0; p < width * height; ++p)
        ASSERT_TRUE(dsm::test::sameFunction(once.pixel(p), pixels[p], false)) << p;
    std::atomic<int> wrong{0}, damagedAccepted{0};
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&] {
            for (int k = 0; k < 200; ++k) {
                if (k % 3 == 0) {
                    try {
                        (void)dsm::format::decodeTile(damaged.stored, damaged.summary, width, height, layout,
                                                      dsm::ReaderOptions{}, "tile", 0, 0);
                        ++damagedAccepted;
                    } catch (const dsm::Error& e) {
                        if (std::string(e.what()).find("zstd cannot decompress") == std::string::npos) ++wrong;
                    }
                    continue;
                }
                const dsm::format::DecodedTile d = decodeGood();
                for (std::uint32_t p = 0; p < width * height; ++p)
                    if (!dsm::test::sameFunction(d.pixel(p), pixels[p], false)) ++wrong;
            }
        });
    for (std::thread& t : threads) t.join();
    EXPECT_EQ(wrong.load(), 0);
    EXPECT_EQ(damagedAccepted.load(), 0);
}

// The depths of a tile's pixels, whatever their vertex counts: 0 to 14 (a
// pixel's steps are written eight at a time, past its own, up to eight, and
// one by one beyond), in random order and at the tile's end, with depths
// anywhere in float32's range, come back bit for bit.
TEST(TileCoding, DepthsOfPixelsOfEveryVertexCountRoundTripBitForBit) {
    std::mt19937 rng(17);
    for (int trial = 0; trial < 40; ++trial) {
        const std::uint32_t width = 1 + rng() % 16, height = 1 + rng() % 16;
        std::vector<VisibilityFunction> pixels;
        for (std::uint32_t p = 0; p < width * height; ++p) {
            VisibilityFunction f(1);
            const int vertices = static_cast<int>(rng() % 15);
            float z = std::ldexp(1.0f + static_cast<float>(rng() % 1000) / 1000.0f, static_cast<int>(rng() % 40) - 20);
            float v = 1.0f;
            for (int i = 0; i < vertices; ++i) {
                z = std::nextafter(z, std::numeric_limits<float>::infinity()) * (1.0f + static_cast<float>(rng() % 64) / 256.0f);
                v *= static_cast<float>(rng() % 256) / 256.0f;
                f.append(z, &v);
            }
            pixels.push_back(f);
        }
        dsm::format::TileLayout layout{1, false, 1, true, 0.0};
        layout.predictedDepths = true;
        const dsm::format::EncodedTile tile = dsm::format::encodeTile(pixels, layout, 6);
        if (tile.stored.empty()) continue;  // every pixel empty
        const dsm::format::DecodedTile decoded = dsm::format::decodeTile(tile.stored, tile.summary, width, height, layout,
                                                                         dsm::ReaderOptions{}, "tile", 0, 0);
        for (std::uint32_t p = 0; p < width * height; ++p)
            ASSERT_TRUE(dsm::test::sameFunction(decoded.pixel(p), pixels[p], false)) << "trial " << trial << " pixel " << p;
    }
}

// Compressors (zlib streams, zstd contexts) are kept from one tile to the
// next: a tile encoded again after others, at other levels and with the
// other codec, must be byte for byte what its first encoding gave, carry
// its own level, and decode as such.
TEST(TileCoding, ATileIsEncodedAlikeWhateverWasEncodedBefore) {
    std::mt19937_64 rng(5);
    const auto randomTile = [&](std::uint32_t pixelCount) {
        std::vector<VisibilityFunction> pixels;
        for (std::uint32_t p = 0; p < pixelCount; ++p)
            pixels.push_back(dsm::test::randomFunction(rng, 1, false, 1, 12));
        return pixels;
    };
    struct Case {
        dsm::TileCodec codec;
        int level;
    };
    const std::vector<Case> cases{{dsm::TileCodec::Zlib, 6}, {dsm::TileCodec::Zlib, 1}, {dsm::TileCodec::Zstd, 19},
                                  {dsm::TileCodec::Zlib, 9}, {dsm::TileCodec::Zstd, 3}, {dsm::TileCodec::Zlib, 6}};
    const auto layoutOf = [](dsm::TileCodec codec) {
        dsm::format::TileLayout layout{1, false, 1, true, 0.0};
        layout.predictedDepths = true;
        layout.codec = codec;
        return layout;
    };
    constexpr std::uint32_t side = 16;
    const std::vector<VisibilityFunction> tile = randomTile(side * side);
    std::vector<std::vector<VisibilityFunction>> others;
    for (int k = 0; k < 4; ++k) others.push_back(randomTile(side * side / (k + 1)));
    for (const Case& c : cases) {
        const dsm::format::TileLayout layout = layoutOf(c.codec);
        const std::vector<std::uint8_t> fresh = dsm::format::encodeTile(tile, layout, c.level).stored;
        // The kept compressors have coded the other cases and other tiles by now.
        for (const auto& other : others)
            for (const Case& d : cases) (void)dsm::format::encodeTile(other, layoutOf(d.codec), d.level);
        const dsm::format::EncodedTile again = dsm::format::encodeTile(tile, layout, c.level);
        ASSERT_LT(again.stored.size(), again.summary.rawBytes) << "level " << c.level;  // compressed
        EXPECT_EQ(again.stored, fresh) << "level " << c.level;
        if (c.codec == dsm::TileCodec::Zlib) {
            // The stream was made for this level: RFC 1950's FLEVEL, the top
            // two bits of the header's second byte, as zlib sets it.
            const int flevel = c.level < 2 ? 0 : c.level < 6 ? 1 : c.level == 6 ? 2 : 3;
            EXPECT_EQ(again.stored[1] >> 6, flevel) << "level " << c.level;
        }
        const dsm::format::DecodedTile decoded = dsm::format::decodeTile(again.stored, again.summary, side, side,
                                                                         layout, dsm::ReaderOptions{}, "tile", 0, 0);
        for (std::uint32_t p = 0; p < side * side; ++p)
            ASSERT_TRUE(dsm::test::sameFunction(decoded.pixel(p), tile[p], false))
                << "level " << c.level << " pixel " << p;
    }
}

// Depth steps are deflated with runs alone unless their strings repeat: a tile
// whose pixels all hold the same depths (parallel cards under an orthographic
// light) must stay about as small as deflate's full search makes it, not
// become several times larger.
TEST(TileCoding, DepthStepsThatRepeatPixelAfterPixelKeepDeflatesSearch) {
    std::vector<VisibilityFunction> pixels;
    for (int p = 0; p < 256; ++p) {
        VisibilityFunction f(1);
        float v = 1.0f;
        for (int card = 0; card < 8; ++card) {
            v *= 0.625f;
            f.append(2.0f + 0.3125f * static_cast<float>(card) + 0.001f * static_cast<float>(card * card), &v);
        }
        pixels.push_back(f);
    }
    dsm::format::TileLayout layout{1, false, 1, true, 0.0};
    layout.predictedDepths = true;
    const dsm::format::EncodedTile storedTile = dsm::format::encodeTile(pixels, layout, 0);  // level 0: stored
    const std::vector<std::uint8_t>& raw = storedTile.stored;
    ASSERT_EQ(raw.size(), storedTile.summary.rawBytes);
    uLongf searched = compressBound(static_cast<uLong>(raw.size()));
    std::vector<std::uint8_t> packed(searched);
    ASSERT_EQ(compress2(packed.data(), &searched, raw.data(), static_cast<uLong>(raw.size()), 6), Z_OK);
    const dsm::format::EncodedTile tile = dsm::format::encodeTile(pixels, layout, 6);
    EXPECT_LT(tile.stored.size(), 2 * searched) << "raw " << raw.size();
    const dsm::format::DecodedTile decoded =
        dsm::format::decodeTile(tile.stored, tile.summary, 16, 16, layout, dsm::ReaderOptions{}, "tile", 0, 0);
    for (std::uint32_t p = 0; p < 256; ++p) ASSERT_TRUE(dsm::test::sameFunction(decoded.pixel(p), pixels[p], false));
}
