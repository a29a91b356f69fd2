// The conventional depth shadow map baseline (bench/baseline/depth_shadow_map.h): its
// own sample path and percentage-closer filtering, checked on scenes with
// known answers under an orthographic light of one world unit per pixel.
#include <gtest/gtest.h>

#include "depth_shadow_map.h"
#include <dsm/error.h>
#include <dsm/scene.h>

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <vector>

#include "temp_dir.h"

namespace {

constexpr double kLightZ = 10.0;

// Orthographic light at world z = 10 looking down -z; light x = world x,
// light y = world y, depth = 10 - world z; raster (x + size/2, size/2 - y).
dsm::Scene sceneWith(std::uint32_t size, std::vector<dsm::SceneObject> objects) {
    dsm::Scene s;
    s.light.projection = dsm::Projection::Orthographic;
    s.light.position = {0.0, 0.0, kLightZ};
    s.light.direction = {0.0, 0.0, -1.0};
    s.light.up = {0.0, 1.0, 0.0};
    s.light.extent = 0.5 * size;
    s.light.width = s.light.height = size;
    s.objects = std::move(objects);
    return s;
}

// A card facing the light at `depth`, covering world x in [x0, x1], all y.
dsm::SceneObject card(double depth, double x0, double x1, float opacity) {
    dsm::SceneObject o;
    o.geometry = dsm::Quad{{0.5 * (x0 + x1), 0.0, kLightZ - depth}, {0.5 * (x1 - x0), 0.0, 0.0}, {0.0, 1000.0, 0.0}};
    o.opacity = {opacity, opacity, opacity};
    return o;
}

TEST(DepthShadowMap, StoresTheNearestSurfaceAndInfinityWhereNothingIsHit) {
    // Cards at depth 3 over world x in [-8, 0) and at depth 6 over [-4, 4).
    const dsm::Scene scene = sceneWith(16, {card(3.0, -8.0, 0.0, 1.0f), card(6.0, -4.0, 4.0, 1.0f)});
    dsm::DepthMapOptions options;
    options.jitter = false;
    const auto map = dsm::DepthShadowMap::render(scene, options);
    ASSERT_EQ(map.width(), 16u);
    EXPECT_FLOAT_EQ(map.depth(1, 5), 3.0f);   // world x = -6.5: first card only
    EXPECT_FLOAT_EQ(map.depth(5, 5), 3.0f);   // x = -2.5: both; the nearer wins
    EXPECT_FLOAT_EQ(map.depth(10, 5), 6.0f);  // x = 2.5: second card
    EXPECT_TRUE(std::isinf(map.depth(14, 5)));  // x = 6.5: nothing
    EXPECT_EQ(map.bytes(), 16u * 16u * sizeof(float));
}

TEST(DepthShadowMap, SemiTransparentSurfacesShadowAsIfOpaque) {
    const dsm::Scene scene = sceneWith(8, {card(2.0, -100.0, 100.0, 0.25f)});
    const auto map = dsm::DepthShadowMap::render(scene);
    EXPECT_DOUBLE_EQ(map.lookupRaster(4.0, 4.0, 1.0, 1.0), 1.0);
    // A deep shadow map would give 0.75 behind the card: the baseline cannot.
    EXPECT_DOUBLE_EQ(map.lookupRaster(4.0, 4.0, 3.0, 1.0), 0.0);
}

TEST(DepthShadowMap, PercentageCloserFilteringAveragesAcrossAnEdge) {
    // Opaque card over world x < 0, i.e. raster x < 16 of a 32 x 32 map.
    const dsm::Scene scene = sceneWith(32, {card(2.0, -100.0, 0.0, 1.0f)});
    dsm::DepthMapOptions options;
    options.jitter = false;
    const auto map = dsm::DepthShadowMap::render(scene, options);
    // A footprint of width 8 centred at raster x = 16 + d covers the lit side
    // over 4 + d pixels: visibility (4 + d) / 8, exactly (box weights).
    for (double d : {-3.5, -2.0, -0.25, 0.0, 1.0, 3.0}) {
        EXPECT_NEAR(map.lookupRaster(16.0 + d, 16.0, 5.0, 8.0), (4.0 + d) / 8.0, 1e-12) << d;
    }
    // In front of the card everything is lit; the bias moves the test depth.
    EXPECT_DOUBLE_EQ(map.lookupRaster(16.0, 16.0, 1.5, 8.0), 1.0);
    EXPECT_DOUBLE_EQ(map.lookupRaster(10.0, 16.0, 2.5, 1.0, 1.0), 1.0);
    EXPECT_DOUBLE_EQ(map.lookupRaster(10.0, 16.0, 2.5, 1.0, 0.0), 0.0);
    // Outside the image, or at a point without a raster position: lit.
    EXPECT_DOUBLE_EQ(map.lookupRaster(-10.0, 16.0, 5.0, 2.0), 1.0);
    EXPECT_DOUBLE_EQ(map.lookupRaster(std::nan(""), 16.0, 5.0, 2.0), 1.0);
    // World space: (x, y, z) = (-5, 0, 10 - 5) is behind the card.
    EXPECT_DOUBLE_EQ(map.lookupWorld({-5.0, 0.0, kLightZ - 5.0}, 1.0), 0.0);
    EXPECT_DOUBLE_EQ(map.lookupWorld({5.0, 0.0, kLightZ - 5.0}, 1.0), 1.0);
}

TEST(DepthShadowMap, SampledFilteringEstimatesTheExactFilter) {
    const dsm::Scene scene = sceneWith(32, {card(2.0, -100.0, 0.0, 1.0f)});
    dsm::DepthMapOptions options;
    options.jitter = false;
    const auto map = dsm::DepthShadowMap::render(scene, options);
    // Over many seeds the 4 x 4-sample estimate averages to the exact answer;
    // one estimate is a multiple of 1/16.
    double sum = 0.0;
    const int seeds = 400;
    for (int s = 0; s < seeds; ++s) {
        const double v = map.lookupRasterSampled(17.3, 16.0, 5.0, 8.0, 4, s);
        EXPECT_NEAR(v * 16.0, std::round(v * 16.0), 1e-12);
        sum += v;
    }
    const double exact = map.lookupRaster(17.3, 16.0, 5.0, 8.0);
    EXPECT_NEAR(sum / seeds, exact, 0.02);
    EXPECT_EQ(map.lookupRasterSampled(17.3, 16.0, 5.0, 8.0, 4, 7), map.lookupRasterSampled(17.3, 16.0, 5.0, 8.0, 4, 7));
    EXPECT_DOUBLE_EQ(map.lookupRasterSampled(17.3, 16.0, 1.0, 8.0, 4, 7), 1.0);
}

TEST(DepthShadowMap, JitteredSamplesEstimateCoverageOfASlantedEdge) {
    // Coverage of an edge through pixel centres' columns at a slant: the
    // fraction of jittered samples shadowed over a wide footprint approaches
    // the covered area (1/2 by symmetry) with the standard error of the count.
    dsm::SceneObject edge;
    const double angle = 0.3, L = 1000.0;
    edge.geometry = dsm::Quad{{-L * std::cos(angle), -L * std::sin(angle), kLightZ - 2.0},
                              {L * std::cos(angle), L * std::sin(angle), 0.0},
                              {-L * std::sin(angle), L * std::cos(angle), 0.0}};
    const dsm::Scene scene = sceneWith(64, {edge});
    const auto map = dsm::DepthShadowMap::render(scene);
    const double v = map.lookupRaster(32.0, 32.0, 5.0, 32.0);
    EXPECT_NEAR(v, 0.5, 4.0 * 0.5 / 32.0);
}

TEST(DepthShadowMap, IsDeterministicForASeedWhateverTheThreadCount) {
    const dsm::Scene scene = sceneWith(24, {card(2.0, -3.3, 5.1, 1.0f), card(4.0, -100.0, -6.2, 1.0f)});
    dsm::DepthMapOptions one, two;
    one.threads = 1;
    two.threads = 2;
    const auto a = dsm::DepthShadowMap::render(scene, one), b = dsm::DepthShadowMap::render(scene, two);
    for (std::uint32_t y = 0; y < 24; ++y)
        for (std::uint32_t x = 0; x < 24; ++x) ASSERT_EQ(a.depth(x, y), b.depth(x, y)) << x << "," << y;
}

TEST(DepthShadowMap, WritesAFloatExrThatReadsBack) {
    const dsm::Scene scene = sceneWith(16, {card(3.0, -8.0, 2.0, 1.0f)});
    const auto map = dsm::DepthShadowMap::render(scene);
    dsm::test::TempDir dir;
    const std::string path = (dir / "depth.exr").string();
    const std::uint64_t bytes = map.writeExr(path);
    EXPECT_EQ(bytes, std::filesystem::file_size(path));
    auto in = OIIO::ImageInput::open(path);
    ASSERT_TRUE(in);
    ASSERT_EQ(in->spec().width, 16);
    ASSERT_EQ(in->spec().nchannels, 1);
    std::vector<float> pixels(16 * 16);
    ASSERT_TRUE(in->read_image(0, 0, 0, 1, OIIO::TypeDesc::FLOAT, pixels.data()));
    for (std::uint32_t y = 0; y < 16; ++y)
        for (std::uint32_t x = 0; x < 16; ++x) ASSERT_EQ(pixels[y * 16 + x], map.depth(x, y));
    EXPECT_THROW(map.writeExr((dir / "no" / "such" / "dir.exr").string()), dsm::Error);
    EXPECT_FALSE(std::filesystem::exists(dir / "no"));
}

TEST(DepthShadowMap, RejectsAnEmptySize) {
    dsm::Scene scene = sceneWith(8, {});
    dsm::DepthMapOptions options;
    options.width = 0;
    scene.light.width = 0;
    EXPECT_THROW(dsm::DepthShadowMap::render(scene, options), dsm::Error);
}

}  // namespace
