// The build options a scene gets when the caller leaves them unset
// (dsm::resolvedBuildOptions): a scene with an area light is built for soft
// shadows (two layers with counts, a box filter of one pixel, half the
// automatic tolerance); any other scene keeps the plain deep shadow map's
// defaults; options the caller sets are kept.
#include <gtest/gtest.h>

#include <dsm/compressor.h>
#include <dsm/reader.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

using dsm::test::TempDir;

// An opaque square over a ground plane under a spot light, with an area
// light of radius `areaRadius` (0: none).
dsm::Scene squareScene(const TempDir& dir, double areaRadius) {
    const std::string json =
        R"({"light": {"type": "spot", "position": [0, 10, 0], "direction": [0, -1, 0], "up": [0, 0, 1], "fov": 60,
                      "resolution": 16, "area_radius": )" +
        std::to_string(areaRadius) + R"(},
            "objects": [{"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "size": 40},
                        {"type": "quad", "center": [0, 5, 0], "u": [1, 0, 0], "v": [0, 0, 1], "opacity": 0.6},
                        {"type": "quad", "center": [0, 4, 0], "u": [1.5, 0, 0], "v": [0, 0, 1.5]}]})";
    return dsm::parseScene(json, dir.path().string(), areaRadius > 0.0 ? "area" : "point");
}

dsm::BuildOptions smallBuild() {
    dsm::BuildOptions o;
    o.samplesPerPixel = 4;
    o.threads = 2;
    return o;
}

TEST(BuildDefaults, ASceneWithAnAreaLightIsBuiltForSoftShadows) {
    TempDir dir;
    const std::string path = (dir / "area.dsm").string();
    dsm::buildMap(squareScene(dir, 1.0), smallBuild(), path);
    const auto map = dsm::DeepShadowMap::open(path);
    const dsm::MapInfo& info = map->info();
    EXPECT_EQ(info.maxLayers, 2);
    EXPECT_TRUE(info.hasCounts);
    EXPECT_EQ(info.filter, dsm::PixelFilter::Box);
    EXPECT_EQ(info.filterWidth, 1.0);
    EXPECT_EQ(info.levels[0].tolerance, 0.5 * dsm::autoTolerance(4));
    // Two layers are used: behind the semi-transparent square the opaque
    // one ends the first layer and the ground starts the second.
    std::size_t twoLayers = 0;
    for (std::uint32_t y = 0; y < info.levels[0].height; ++y)
        for (std::uint32_t x = 0; x < info.levels[0].width; ++x) twoLayers += map->pixel(0, x, y)->layerCount() == 2;
    EXPECT_GT(twoLayers, 0u);
}

TEST(BuildDefaults, OptionsTheCallerSetsOverrideTheAreaLightDefaults) {
    TempDir dir;
    dsm::BuildOptions options = smallBuild();
    options.mtsmLayers = 1;
    options.filter = dsm::PixelFilter::Triangle;
    options.tolerance = 0.2;
    const std::string path = (dir / "area.dsm").string();
    dsm::buildMap(squareScene(dir, 1.0), options, path);
    const dsm::MapInfo& info = dsm::DeepShadowMap::open(path)->info();
    EXPECT_EQ(info.maxLayers, 1);
    EXPECT_FALSE(info.hasCounts);
    EXPECT_EQ(info.filter, dsm::PixelFilter::Triangle);
    EXPECT_EQ(info.filterWidth, 2.0);  // a filter other than the box keeps its usual width
    EXPECT_EQ(info.levels[0].tolerance, 0.2);
}

TEST(BuildDefaults, ASceneWithoutAnAreaLightKeepsThePlainDefaultsByteForByte) {
    TempDir dir;
    const dsm::Scene scene = squareScene(dir, 0.0);
    const std::string unset = (dir / "unset.dsm").string(), given = (dir / "given.dsm").string();
    dsm::buildMap(scene, smallBuild(), unset);
    dsm::BuildOptions options = smallBuild();
    options.mtsmLayers = 1;
    options.filter = dsm::PixelFilter::Gaussian;
    options.filterWidth = 2.0;
    options.tolerance = dsm::autoTolerance(4);
    dsm::buildMap(scene, options, given);
    EXPECT_EQ(dsm::test::readFile(unset), dsm::test::readFile(given));
    const dsm::MapInfo& info = dsm::DeepShadowMap::open(unset)->info();
    EXPECT_EQ(info.maxLayers, 1);
    EXPECT_FALSE(info.hasCounts);
    EXPECT_EQ(info.filter, dsm::PixelFilter::Gaussian);
    EXPECT_EQ(info.filterWidth, 2.0);
    EXPECT_EQ(info.levels[0].tolerance, dsm::autoTolerance(4));
}

TEST(BuildDefaults, ResolvedOptionsAreTheBuildsAndKeepWhatIsSet) {
    TempDir dir;
    dsm::BuildOptions options = smallBuild();
    options.filter = dsm::PixelFilter::Gaussian;
    options.samplesPerPixel = 64;
    const dsm::BuildOptions area = dsm::resolvedBuildOptions(squareScene(dir, 1.0), options);
    EXPECT_EQ(area.width, 16u);
    EXPECT_EQ(area.height, 16u);
    EXPECT_EQ(area.filter, dsm::PixelFilter::Gaussian);
    EXPECT_EQ(area.filterWidth, 2.0);
    EXPECT_EQ(area.mtsmLayers, 2);
    EXPECT_EQ(area.tolerance, 0.5 * dsm::autoTolerance(64));
    const dsm::BuildOptions plain = dsm::resolvedBuildOptions(squareScene(dir, 0.0), smallBuild());
    EXPECT_EQ(plain.filter, dsm::PixelFilter::Gaussian);
    EXPECT_EQ(plain.filterWidth, 2.0);
    EXPECT_EQ(plain.mtsmLayers, 1);
    EXPECT_EQ(plain.tolerance, dsm::autoTolerance(4));
}

}  // namespace

// --centred-compression: recorded in the metadata, and every level of the map
// within its stated error bound of the exact one (built from the same samples
// at tolerance 0, whose coarser levels are then exact averages).
TEST(BuildDefaults, CentredCompressionIsRecordedAndEveryLevelKeepsItsBound) {
    TempDir dir;
    const dsm::Scene scene = squareScene(dir, 0.0);
    const std::string exactPath = (dir / "exact.dsm").string(), centredPath = (dir / "centred.dsm").string();
    dsm::BuildOptions options = smallBuild();
    options.samplesPerPixel = 16;
    options.tileSize = 4;
    options.tolerance = 0.0;
    dsm::buildMap(scene, options, exactPath);
    options.tolerance.reset();
    options.centredCompression = true;
    dsm::buildMap(scene, options, centredPath);
    const auto exact = dsm::DeepShadowMap::open(exactPath);
    const auto centred = dsm::DeepShadowMap::open(centredPath);
    EXPECT_NE(centred->info().metadata.find(R"("compression":"centred")"), std::string::npos);
    EXPECT_EQ(exact->info().metadata.find(R"("compression")"), std::string::npos);
    ASSERT_EQ(centred->info().levels.size(), exact->info().levels.size());
    for (unsigned l = 0; l < centred->info().levels.size(); ++l) {
        const dsm::LevelInfo& L = centred->info().levels[l];
        double worst = 0.0;
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x) {
                const dsm::PixelFunction a = exact->pixel(l, x, y), b = centred->pixel(l, x, y);
                const dsm::VisibilityView va = a.view(), vb = b.view();
                for (const dsm::VisibilityView* f : {&va, &vb})
                    for (std::size_t i = 0; i < f->size(); ++i)
                        for (const double z : {double(f->z(i)), std::nextafter(double(f->z(i)), 0.0)})
                            worst = std::max(worst, std::abs(va.evaluate(z) - vb.evaluate(z)));
            }
        EXPECT_LE(worst, L.errorBound + 1e-6) << "level " << l;
        EXPECT_GT(worst, 0.0) << "level " << l;
    }
}
