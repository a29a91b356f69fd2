// Pictures of a map (map_images.h) against per-pixel evaluations through
// DeepShadowMap::pixel(), and writing pictures (image_io.h) read back through
// OpenImageIO.
#include <dsm/dsm.h>
#include "colour_ramp.h"
#include "image_io.h"
#include <dsm/map_images.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace dsm {
namespace {

constexpr std::uint32_t kWidth = 20;
constexpr std::uint32_t kHeight = 12;

/// Random RGB functions (some grey, some layered, every fifth pixel empty), so
/// the pictures of both levels are far from constant.
test::Image sampleImage(int layers) {
    std::mt19937_64 rng(1234 + static_cast<std::uint64_t>(layers));
    return test::makeImage(kWidth, kHeight, [&](std::uint32_t x, std::uint32_t y) {
        if ((x + 3 * y) % 5 == 0) return VisibilityFunction(3, false);
        return test::randomFunction(rng, 3, false, 1 + static_cast<int>((x + y) % static_cast<unsigned>(layers)), 4);
    });
}

std::shared_ptr<DeepShadowMap> writeSample(const std::filesystem::path& path, int layers) {
    WriterOptions options;
    options.tileSize = 8;
    options.channels = 3;
    options.maxLayers = layers;
    options.mipLevels = 2;
    options.tolerance = 0.0;
    test::writeMap(path, options, sampleImage(layers));
    return DeepShadowMap::open(path.string());
}

class MapImagesTest : public ::testing::TestWithParam<int> {  // parameter: most layers per pixel
protected:
    test::TempDir dir;
    std::shared_ptr<DeepShadowMap> map = writeSample(dir / "sample.dsm", GetParam());
};

TEST_P(MapImagesTest, SliceIsEachPixelsVisibilityAtTheDepth) {
    for (unsigned level = 0; level < 2; ++level) {
        const LevelInfo& L = map->info().levels[level];
        for (const double z : {0.0, 0.7, 1.3, 2.9, 100.0}) {
            const FloatImage image = visibilitySlice(*map, level, z);
            ASSERT_EQ(image.width, L.width);
            ASSERT_EQ(image.height, L.height);
            ASSERT_EQ(image.channels, 3);
            bool notAllOne = false;
            for (std::uint32_t y = 0; y < L.height; ++y)
                for (std::uint32_t x = 0; x < L.width; ++x) {
                    const PixelFunction f = map->pixel(level, x, y);
                    for (int c = 0; c < 3; ++c) {
                        const double want = f->empty() ? 1.0 : test::lightCentreValue(f.view(), z, c);
                        EXPECT_NEAR(image.at(x, y, c), want, 1e-6)
                            << "level " << level << " pixel " << x << "," << y << " channel " << c << " z " << z;
                        notAllOne |= image.at(x, y, c) < 0.999f;
                    }
                }
            if (z > 1.0) {
                EXPECT_TRUE(notAllOne) << "level " << level << " z " << z;
            }
        }
    }
}

TEST_P(MapImagesTest, OpacityIsOneMinusVisibilityAtInfinity) {
    for (unsigned level = 0; level < 2; ++level) {
        const FloatImage image = opacityImage(*map, level);
        const LevelInfo& L = map->info().levels[level];
        ASSERT_EQ(image.width, L.width);
        ASSERT_EQ(image.channels, 3);
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x) {
                const PixelFunction f = map->pixel(level, x, y);
                for (int c = 0; c < 3; ++c) {
                    const double atInfinity =
                        f->empty() ? 1.0 : test::lightCentreValue(f.view(), std::numeric_limits<double>::max(), c);
                    EXPECT_NEAR(image.at(x, y, c), 1.0 - atInfinity, 1e-6)
                        << "level " << level << " pixel " << x << "," << y << " channel " << c;
                    if (f->layerCount() > 1) {
                        EXPECT_EQ(image.at(x, y, c), 1.0f);
                    }
                }
            }
    }
}

TEST_P(MapImagesTest, VertexCountsAndHistogramMatchThePixels) {
    for (unsigned level = 0; level < 2; ++level) {
        const FloatImage counts = vertexCountImage(*map, level);
        const VertexHistogram h = vertexHistogram(*map, level);
        const LevelInfo& L = map->info().levels[level];
        ASSERT_EQ(counts.channels, 1);
        std::vector<std::uint32_t> all;
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x) {
                const auto n = static_cast<std::uint32_t>(map->pixel(level, x, y)->size());
                EXPECT_EQ(counts.at(x, y), static_cast<float>(n)) << "level " << level << " pixel " << x << "," << y;
                all.push_back(n);
            }
        std::sort(all.begin(), all.end());
        const auto nearestRank = [&](double p) {
            return all[static_cast<std::size_t>(std::ceil(p * static_cast<double>(all.size()))) - 1];
        };
        EXPECT_EQ(h.level, level);
        EXPECT_EQ(h.pixels, all.size());
        EXPECT_EQ(h.vertices, L.vertexCount);
        EXPECT_EQ(h.nonEmptyPixels, L.nonEmptyPixels);
        EXPECT_EQ(h.min, all.front());
        EXPECT_EQ(h.max, all.back());
        EXPECT_EQ(h.median, nearestRank(0.5));
        EXPECT_EQ(h.p99, nearestRank(0.99));
        EXPECT_DOUBLE_EQ(h.mean, static_cast<double>(L.vertexCount) / static_cast<double>(all.size()));
        ASSERT_FALSE(h.buckets.empty());
        std::uint64_t total = 0;
        for (std::size_t k = 0; k < h.buckets.size(); ++k) {
            const auto inBucket = std::count_if(all.begin(), all.end(), [&](std::uint32_t n) {
                return n >= VertexHistogram::bucketMin(k) && n <= VertexHistogram::bucketMax(k);
            });
            EXPECT_EQ(h.buckets[k], static_cast<std::uint64_t>(inBucket)) << "level " << level << " bucket " << k;
            total += h.buckets[k];
        }
        EXPECT_EQ(total, h.pixels);
        EXPECT_LE(h.max, VertexHistogram::bucketMax(h.buckets.size() - 1));
        EXPECT_GE(h.max, VertexHistogram::bucketMin(h.buckets.size() - 1));
    }
}

TEST_P(MapImagesTest, MissingLevelAndNanDepthThrowNamingTheFile) {
    for (const auto& call : std::vector<std::function<void()>>{
             [&] { visibilitySlice(*map, 2, 1.0); }, [&] { opacityImage(*map, 7); },
             [&] { vertexCountImage(*map, 2); }, [&] { vertexHistogram(*map, 2); },
             [&] { visibilitySlice(*map, 0, std::nan("")); }}) {
        try {
            call();
            ADD_FAILURE() << "no error";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("sample.dsm"), std::string::npos) << e.what();
        }
    }
}

TEST_P(MapImagesTest, RectanglesAreTheWholeLevelsPictureCut) {
    // Rectangles that start and end inside tiles (8 x 8) and across them.
    for (unsigned level = 0; level < 2; ++level) {
        const LevelInfo& L = map->info().levels[level];
        const FloatImage slice = visibilitySlice(*map, level, 1.3), opacity = opacityImage(*map, level),
                         vertices = vertexCountImage(*map, level);
        for (const PixelRect rect : {PixelRect{0, 0, L.width, L.height}, PixelRect{3, 1, L.width - 4, L.height - 2},
                                     PixelRect{L.width - 1, L.height - 1, 1, 1}, PixelRect{7, 0, 2, L.height}}) {
            const FloatImage part[] = {visibilitySlice(*map, level, 1.3, rect), opacityImage(*map, level, rect),
                                       vertexCountImage(*map, level, rect), layerCountImage(*map, level, rect)};
            for (const FloatImage& p : part) {
                ASSERT_EQ(p.width, rect.width);
                ASSERT_EQ(p.height, rect.height);
            }
            for (std::uint32_t y = 0; y < rect.height; ++y)
                for (std::uint32_t x = 0; x < rect.width; ++x) {
                    const std::uint32_t X = rect.x + x, Y = rect.y + y;
                    for (int c = 0; c < 3; ++c) {
                        EXPECT_EQ(part[0].at(x, y, c), slice.at(X, Y, c)) << X << "," << Y;
                        EXPECT_EQ(part[1].at(x, y, c), opacity.at(X, Y, c)) << X << "," << Y;
                    }
                    EXPECT_EQ(part[2].at(x, y), vertices.at(X, Y));
                    const PixelFunction f = map->pixel(level, X, Y);
                    EXPECT_EQ(part[3].at(x, y), f->empty() ? 0.0f : static_cast<float>(f->layerCount()))
                        << X << "," << Y;
                }
        }
    }
}

TEST_P(MapImagesTest, RectanglesOutsideTheLevelThrowNamingTheFile) {
    const LevelInfo& L = map->info().levels[0];
    for (const PixelRect rect : {PixelRect{0, 0, 0, 1}, PixelRect{0, 0, L.width + 1, 1}, PixelRect{L.width, 0, 1, 1},
                                 PixelRect{1, 0, UINT32_MAX, 1}, PixelRect{0, L.height - 1, 1, 2}}) {
        try {
            opacityImage(*map, 0, rect);
            ADD_FAILURE() << "no error for " << rect.x << "," << rect.y << " + " << rect.width << " x " << rect.height;
        } catch (const Error& e) {
            EXPECT_EQ(e.code(), ErrorCode::argument);
            EXPECT_NE(std::string(e.what()).find("sample.dsm"), std::string::npos) << e.what();
        }
    }
}

INSTANTIATE_TEST_SUITE_P(Layers, MapImagesTest, ::testing::Values(1, 2));

TEST(DifferenceImage, SubtractsPerChannelAndSpreadsOneChannel) {
    FloatImage rgb(2, 1, 3), mono(2, 1, 1);
    rgb.values = {0.5f, 0.25f, 1.0f, 0.0f, 0.125f, 0.75f};
    mono.values = {0.25f, 0.5f};
    const FloatImage d = differenceImage(rgb, mono);
    ASSERT_EQ(d.channels, 3);
    EXPECT_EQ(d.values, (std::vector<float>{0.25f, 0.0f, 0.75f, -0.5f, -0.375f, 0.25f}));
    const FloatImage e = differenceImage(mono, rgb);
    EXPECT_EQ(e.values, (std::vector<float>{-0.25f, 0.0f, -0.75f, 0.5f, 0.375f, -0.25f}));
    EXPECT_THROW(differenceImage(rgb, FloatImage(3, 1, 3)), Error);
    EXPECT_THROW(differenceImage(FloatImage(2, 1, 2), rgb), Error);
}

TEST(ColourRamp, RunsFromBlackToWhiteWithRisingLuminance) {
    FloatImage counts(11, 1, 1);
    for (std::uint32_t x = 0; x < 11; ++x) counts.at(x, 0) = static_cast<float>(x);
    const FloatImage rgb = colourRamp(counts, 10.0f);
    ASSERT_EQ(rgb.channels, 3);
    for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(rgb.at(0, 0, c), 0.0f);
        EXPECT_EQ(rgb.at(10, 0, c), 1.0f);
    }
    float previous = -1.0f;
    for (std::uint32_t x = 0; x < 11; ++x) {
        // Rec. 709 luminance: the ramp must still read in grey.
        const float brightness = 0.2126f * rgb.at(x, 0, 0) + 0.7152f * rgb.at(x, 0, 1) + 0.0722f * rgb.at(x, 0, 2);
        EXPECT_GT(brightness, previous) << x;
        previous = brightness;
    }
    EXPECT_THROW(colourRamp(rgb, 1.0f), Error);
}

/// A picture with values across [0, 1] and beyond, different per channel.
FloatImage gradient(int channels) {
    FloatImage image(13, 7, channels);
    for (std::uint32_t y = 0; y < image.height; ++y)
        for (std::uint32_t x = 0; x < image.width; ++x)
            for (int c = 0; c < channels; ++c)
                image.at(x, y, c) = static_cast<float>(x) / 11.0f + 0.37f * static_cast<float>(c) -
                                    0.013f * static_cast<float>(y);
    return image;
}

TEST(ImageIo, ExrRoundTripsExactly) {
    test::TempDir dir;
    for (const int channels : {1, 3}) {
        const std::string path = (dir / ("picture" + std::to_string(channels) + ".exr")).string();
        FloatImage image = gradient(channels);
        image.at(0, 0) = 12345.678f;  // counts are not limited to [0, 1]
        EXPECT_TRUE(imageFormatKeepsFloats(path));
        writeImage(path, image);
        const FloatImage back = readImage(path);
        EXPECT_EQ(back.width, image.width);
        EXPECT_EQ(back.height, image.height);
        EXPECT_EQ(back.channels, image.channels);
        EXPECT_EQ(back.values, image.values);
    }
}

TEST(ImageIo, PngIsLinearEightBit) {
    test::TempDir dir;
    for (const int channels : {1, 3}) {
        const std::string path = (dir / ("picture" + std::to_string(channels) + ".png")).string();
        const FloatImage image = gradient(channels);
        EXPECT_FALSE(imageFormatKeepsFloats(path));
        writeImage(path, image);
        const FloatImage back = readImage(path);
        ASSERT_EQ(back.width, image.width);
        ASSERT_EQ(back.height, image.height);
        ASSERT_EQ(back.channels, image.channels);
        for (std::size_t i = 0; i < image.values.size(); ++i) {
            const float want = std::clamp(image.values[i], 0.0f, 1.0f);
            EXPECT_NEAR(back.values[i], want, 0.5f / 255.0f + 1e-6f) << "value " << i;
        }
    }
}

TEST(ImageIo, FailuresNameTheFileAndLeaveNothing) {
    test::TempDir dir;
    const auto expectError = [](const std::string& path, auto&& call) {
        try {
            call();
            ADD_FAILURE() << "no error for " << path;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("'" + path + "'"), std::string::npos) << e.what();
        }
    };
    const std::string unknown = (dir / "picture.no-such-format").string();
    expectError(unknown, [&] { writeImage(unknown, gradient(1)); });
    expectError(unknown, [&] { imageFormatKeepsFloats(unknown); });
    const std::string missingDir = (dir / "no such dir" / "picture.png").string();
    expectError(missingDir, [&] { writeImage(missingDir, gradient(3)); });
    const std::string empty = (dir / "empty.exr").string();
    expectError(empty, [&] { writeImage(empty, FloatImage()); });
    const std::string notAnImage = (dir / "text.png").string();
    test::writeFile(notAnImage, {'n', 'o', 't', ' ', 'a', ' ', 'p', 'n', 'g'});
    expectError(notAnImage, [&] { readImage(notAnImage); });
    EXPECT_EQ(test::listDirectory(dir.path()), std::vector<std::string>{"text.png"});
}

TEST(ImageIo, ReplacesAnExistingPicture) {
    test::TempDir dir;
    const std::string path = (dir / "picture.exr").string();
    writeImage(path, gradient(3));
    FloatImage second = gradient(1);
    second.values.assign(second.values.size(), 0.25f);
    writeImage(path, second);
    EXPECT_EQ(readImage(path).values, second.values);
    EXPECT_EQ(test::listDirectory(dir.path()), std::vector<std::string>{"picture.exr"});
}

}  // namespace
}  // namespace dsm
