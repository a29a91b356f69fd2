// The two samplers (dsm::SamplerMethod): the scanline sampler visits the
// primitives bucketed by tile, the ray-casting one a hierarchy per sample
// ray; both must give every sample the same crossings, so the same map.
#include <gtest/gtest.h>

#include <dsm/dsm.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <filesystem>
#include <string>

#include "map_fixtures.h"
#include "ray_caster.h"
#include "scanline_hider.h"
#include "temp_dir.h"

namespace {

using dsm::test::expectSamePixels;
using dsm::test::TempDir;

void expectBothSamplersAgree(const dsm::Scene& scene, dsm::BuildOptions options, const TempDir& dir,
                             const std::string& name) {
    SCOPED_TRACE(name);
    options.sampler = dsm::SamplerMethod::scanline;
    const std::string scanline = (dir / (name + "-scanline.dsm")).string();
    dsm::buildMap(scene, options, scanline);
    options.sampler = dsm::SamplerMethod::raytrace;
    const std::string raytrace = (dir / (name + "-raytrace.dsm")).string();
    dsm::buildMap(scene, options, raytrace);
    expectSamePixels(*dsm::DeepShadowMap::open(scanline), *dsm::DeepShadowMap::open(raytrace));
}

dsm::BuildOptions smallBuild() {
    dsm::BuildOptions o;
    o.width = 40;
    o.height = 40;
    o.samplesPerPixel = 4;
    o.tileSize = 16;  // tiles of 16, 16 and 8 pixels: a partial tile at the edges
    o.threads = 2;
    return o;
}

TEST(Samplers, EveryExampleGivesTheSameMapWithBothSamplers) {
    const TempDir dir;
    for (const auto& entry : std::filesystem::directory_iterator(DSM_SOURCE_DIR "/examples")) {
        if (entry.path().extension() != ".json") continue;
        const dsm::Scene scene = dsm::loadScene(entry.path().string());
        dsm::BuildOptions options = smallBuild();
        options.filterWidth = 3.0;  // samples a pixel beyond each tile
        expectBothSamplersAgree(scene, options, dir, entry.path().stem().string());
    }
}

TEST(Samplers, LayeredMapsWithCountsAgree) {
    const TempDir dir;
    const dsm::Scene scene = dsm::loadScene(DSM_SOURCE_DIR "/examples/area-light.json");
    dsm::BuildOptions options = smallBuild();
    options.mtsmLayers = 3;
    expectBothSamplersAgree(scene, options, dir, "layers");
}

// Surfaces that reach behind a perspective light have no bounded raster
// footprint: the scanline sampler files them in every tile.
TEST(Samplers, SurfacesReachingBehindThePerspectiveLightAgree) {
    const TempDir dir;
    const dsm::Scene scene = dsm::parseScene(R"({
      "light": {"type": "spot", "position": [0, 5, 0], "look_at": [0, 0, 0], "up": [0, 0, -1], "fov": 60,
                "resolution": [40, 40], "near": 0.01},
      "objects": [
        {"type": "sphere", "name": "around the light", "center": [0, 5, 0], "radius": 1.0, "opacity": 0.3},
        {"type": "plane", "name": "through the light's plane", "normal": [1, 1, 0], "size": 40, "opacity": 0.5},
        {"type": "sphere", "name": "ball", "center": [0.5, 1, 0], "radius": 0.7, "opacity": 0.8},
        {"type": "plane", "name": "ground", "normal": [0, 1, 0], "size": 10}
      ]})",
                                             dir.path().string(), "behind.json");
    expectBothSamplersAgree(scene, smallBuild(), dir, "behind");
}

TEST(Samplers, ARegionOfTheScanlineSamplerEqualsTheFullBuild) {
    const TempDir dir;
    const dsm::Scene scene = dsm::loadScene(DSM_SOURCE_DIR "/examples/hairball.json");
    dsm::BuildOptions options = smallBuild();
    const std::string full = (dir / "full.dsm").string(), part = (dir / "part.dsm").string();
    dsm::buildMap(scene, options, full);
    options.region = {8, 16, 33, 40};
    dsm::buildMap(scene, options, part);
    const auto a = dsm::DeepShadowMap::open(full), b = dsm::DeepShadowMap::open(part);
    for (std::uint32_t y = 16; y < 40; ++y)
        for (std::uint32_t x = 8; x < 33; ++x)
            ASSERT_TRUE(dsm::test::sameFunction(b->pixel(0, x, y).view(), a->pixel(0, x, y).view().toFunction(), false))
                << "pixel " << x << "," << y;
}

// A row of tiles is written while the next is built: an error in a later
// row must wait for that writing, then leave no file behind (not even a
// temporary one), and the progress must stop at the rows written.
TEST(Samplers, AnErrorWhileARowIsWrittenLeavesNoFile) {
    const TempDir dir;
    const dsm::Scene scene = dsm::loadScene(DSM_SOURCE_DIR "/examples/hairball.json");
    for (unsigned threads : {1u, 2u}) {
        dsm::BuildOptions options = smallBuild();
        options.threads = threads;
        options.sampleRays = [](std::uint32_t, std::uint32_t y, std::span<const dsm::SampleRay>) {
            if (y == 35) throw dsm::Error(dsm::ErrorCode::scene, "pixel row 35 refused");
        };
        double progress = 0.0;
        options.progress = [&](double done) { progress = done; };
        const std::string path = (dir / "refused.dsm").string();
        try {
            dsm::buildMap(scene, options, path);
            ADD_FAILURE() << "no error";
        } catch (const dsm::Error& e) {
            EXPECT_NE(std::string(e.what()).find("pixel row 35 refused"), std::string::npos) << e.what();
        }
        EXPECT_LE(progress, 2.0 / 3.0);  // rows of 16, 16 and 8 pixels: the third never completes
        EXPECT_TRUE(std::filesystem::is_empty(dir.path())) << "threads " << threads;
    }
}

// Each primitive is filed in the tiles its projected bounds reach and no
// others: a small ball in one tile's interior is in that tile's bucket only,
// and a ground plane covering the view in every tile's.
TEST(ScanlineHider, FilesEachPrimitiveInTheTilesItReaches) {
    const TempDir dir;
    const dsm::Scene scene = dsm::parseScene(R"({
      "light": {"type": "distant", "position": [0, 5, 0], "direction": [0, -1, 0], "up": [0, 0, -1],
                "extent": 4, "resolution": [64, 64]},
      "objects": [
        {"type": "sphere", "name": "ball", "center": [-2.5, 1, -2.5], "radius": 0.2},
        {"type": "plane", "name": "ground", "normal": [0, 1, 0], "size": 20}
      ]})",
                                             dir.path().string(), "buckets.json");
    const dsm::RayCaster caster(scene, dsm::RayCaster::Surfaces::none);
    const dsm::LightCamera camera = dsm::lightCamera(scene.light);
    const dsm::ScanlineHider hider(caster.surfaces(), camera, 64, 64, 16, 0);
    EXPECT_EQ(hider.bucketEntries(), 1u + 16u);
}

}  // namespace
