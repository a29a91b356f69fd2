// The two samplers (dsm::SamplerMethod): the scanline sampler visits the
// primitives bucketed by tile, the ray-casting one Embree's hierarchy per
// sample ray. Both cross each primitive they visit with the same exact test
// in double precision (ScenePrimitives::intersect) on the same ray, so every
// sample gets the same crossings to the bit, and so the maps are the same to
// the bit: they are compared for identity, not within sampling noise.
#include <gtest/gtest.h>

#include <dsm/dsm.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "map_fixtures.h"
#include "light_rays.h"
#include "raster_test.h"
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

// The scanline sampler tests a pixel's samples against a primitive in
// groups of 64, two at a time and the last one of an odd group alone: sample
// counts of one, odd and above 64 take every path, still and moving hair, and
// must find what rays cast one by one find.
TEST(Samplers, SampleCountsOfEveryGroupShapeAgree) {
    const TempDir dir;
    for (const char* example : {"hairball", "motion"}) {
        const dsm::Scene scene = dsm::loadScene(std::string(DSM_SOURCE_DIR "/examples/") + example + ".json");
        for (const std::uint32_t spp : {1u, 3u, 67u}) {
            dsm::BuildOptions options = smallBuild();
            options.width = options.height = 24;
            options.samplesPerPixel = spp;
            expectBothSamplersAgree(scene, options, dir, std::string(example) + "-" + std::to_string(spp) + "spp");
        }
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

// A quad is the image of the scene's rectangle under its transform: under
// a scale unequal along its axes, a parallelogram. Both samplers reach it
// through the bounds of its corners, so its crossing test must keep to them.
TEST(Samplers, QuadsUnderUnequalScalesAgree) {
    const TempDir dir;
    const dsm::Scene scene = dsm::parseScene(R"({
      "light": {"type": "spot", "position": [2, 6, 1.5], "look_at": [0, 0, 0], "fov": 70, "resolution": [40, 40]},
      "objects": [
        {"type": "quad", "name": "rhombus", "u": [1, 0, 1], "v": [-1, 0, 1], "opacity": 0.6,
         "transform": {"scale": [3, 1, 1]}},
        {"type": "quad", "name": "sheared", "center": [0, 1, 0], "u": [0.5, 0.5, 0], "v": [0, 0, 1],
         "opacity": 0.4,
         "transform": [{"scale": [2.5, 0.3, 1]}, {"rotate": {"axis": [1, 1, 0], "angle": 40}}]}
      ]})",
                                             dir.path().string(), "sheared.json");
    expectBothSamplersAgree(scene, smallBuild(), dir, "sheared");
}

// The rhombus with corners (+-6, 0, 0) and (0, 0, +-2): rays straight down
// cross it just inside each corner and edge and miss it just outside, as they
// do the two triangles of its corners (the reference tracer's quad).
TEST(ScenePrimitives, AQuadUnderAnUnequalScaleIsTheParallelogramOfItsCorners) {
    const TempDir dir;
    const dsm::Scene scene = dsm::parseScene(R"({
      "light": {"type": "distant", "position": [0, 5, 0], "direction": [0, -1, 0], "up": [0, 0, -1], "extent": 8},
      "objects": [{"type": "quad", "u": [1, 0, 1], "v": [-1, 0, 1], "transform": {"scale": [3, 1, 1]}}]})",
                                             dir.path().string(), "rhombus.json");
    const dsm::ScenePrimitives surfaces(scene);
    ASSERT_EQ(surfaces.size(), 1u);
    const dsm::Vec3 corners[] = {{6, 0, 0}, {0, 0, 2}, {-6, 0, 0}, {0, 0, -2}};
    for (int k = 0; k < 4; ++k) {
        const dsm::Vec3& a = corners[k];
        const dsm::Vec3& b = corners[(k + 1) % 4];
        for (double along : {0.0, 0.03, 0.5, 0.97})  // from corner a toward b
            for (double fromCentre : {0.97, 1.03}) {  // the point on the edge, scaled about the centre
                const double x = (a[0] + along * (b[0] - a[0])) * fromCentre;
                const double z = (a[2] + along * (b[2] - a[2])) * fromCentre;
                dsm::RaySurfaceHits hits;
                surfaces.intersect(surfaces.all()[0], dsm::Vec3{x, 5, z}, dsm::Vec3{0, -1, 0}, 0.0, 0.0, hits);
                ASSERT_EQ(hits.size(), fromCentre < 1.0 ? 1u : 0u) << "at " << x << ", " << z;
                for (const dsm::RaySurfaceHit& hit : hits) EXPECT_DOUBLE_EQ(hit.t, 5.0);
            }
    }
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

// The hider skips the samples of a still hair segment that lie farther in
// raster space from its projected axis than its ribbon can reach; that bound
// must never skip a crossing the exact test finds. Samples placed where rays
// pass segments just inside their half-width, anywhere along them up to their
// ends, under a perspective and an orthographic light, must each get the
// exact test's crossing of that segment.
void expectHiderFindsRibbonEdges(const dsm::Scene& scene, std::uint32_t size) {
    const dsm::RayCaster caster(scene, dsm::RayCaster::Surfaces::none);
    const dsm::ScenePrimitives& surfaces = caster.surfaces();
    const auto& all = surfaces.all();
    dsm::LightDescription light = scene.light;
    light.width = light.height = size;
    const dsm::LightCamera camera = dsm::lightCamera(light);
    const dsm::detail::LightRayFrame frame = dsm::detail::lightRayFrame(camera, size, size);
    constexpr std::uint32_t kTile = 16;
    const dsm::ScanlineHider hider(surfaces, camera, size, size, kTile, 0);
    std::vector<dsm::Rgb> opacity;
    for (const dsm::SceneObject& object : scene.objects) opacity.push_back(object.opacity);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const dsm::Vec3 toLight{camera.worldToLight[8], camera.worldToLight[9], camera.worldToLight[10]};
    std::size_t edgeCrossings = 0;
    for (int r = 0; r < 2000; ++r) {
        const dsm::Primitive& p = all[rng() % all.size()];
        if (p.kind != dsm::PrimitiveKind::Segment) continue;
        const dsm::ScenePrimitives::Segment& seg = surfaces.segment(p);
        const double along = r % 10 == 0 ? 0.0 : r % 10 == 1 ? 1.0 - 1e-12 : unit(rng);
        dsm::Vec3 axis, point;
        for (std::size_t a = 0; a < 3; ++a) axis[a] = seg.p1[a] - seg.p0[a];
        for (std::size_t a = 0; a < 3; ++a) point[a] = seg.p0[a] + along * axis[a];
        // Sideways from the axis, across the light's view: where the ribbon's edge shows.
        dsm::Vec3 side{axis[1] * toLight[2] - axis[2] * toLight[1], axis[2] * toLight[0] - axis[0] * toLight[2],
                       axis[0] * toLight[1] - axis[1] * toLight[0]};
        const double sideLength = std::sqrt(side[0] * side[0] + side[1] * side[1] + side[2] * side[2]);
        if (!(sideLength > 0.0)) continue;
        const double gap = (seg.r0 + along * (seg.r1 - seg.r0)) * (r % 2 ? 0.999 : -0.999);
        for (std::size_t a = 0; a < 3; ++a) point[a] += side[a] / sideLength * gap;
        double rx, ry, depth;
        if (!camera.lightToRaster(camera.worldToLightSpace(point), int(size), int(size), rx, ry, depth)) continue;
        if (!(rx >= 0.0 && rx < size && ry >= 0.0 && ry < size)) continue;
        const auto px = static_cast<std::uint32_t>(rx), py = static_cast<std::uint32_t>(ry);
        dsm::HiderSample sample;
        sample.x = rx;
        sample.y = ry;
        dsm::Vec3 origin, direction;
        frame.ray(rx, ry, origin, direction);
        dsm::RaySurfaceHits exact;
        surfaces.intersect(p, origin, direction, 0.0, camera.nearPlane, exact);
        if (exact.empty()) continue;  // rounding put the ray just outside
        ++edgeCrossings;
        dsm::ScanlineHider::TileHits hits;
        hider.tileHits(px / kTile, py / kTile, {px, py, px + 1, py + 1}, 1, std::span(&sample, 1), camera.nearPlane,
                       opacity, hits);
        const auto crossings = hits.of(0);
        const dsm::Rgb& expectedOpacity = opacity[exact[0].object];
        const bool present = std::any_of(crossings.begin(), crossings.end(), [&](const dsm::SurfaceHit& h) {
            return h.z == static_cast<float>(exact[0].t) && h.opacity[0] == expectedOpacity[0] &&
                   h.opacity[1] == expectedOpacity[1] && h.opacity[2] == expectedOpacity[2];
        });
        ASSERT_TRUE(present) << "sample " << r << " at " << rx << ", " << ry;
    }
    EXPECT_GT(edgeCrossings, 1000u);
}

TEST(ScanlineHider, FindsHairCrossingsAtTheRibbonsEdges) {
    const TempDir dir;
    const dsm::Scene spot = dsm::loadScene(DSM_SOURCE_DIR "/examples/hairball.json");
    {
        SCOPED_TRACE("perspective");
        expectHiderFindsRibbonEdges(spot, 512);
    }
    // A wide light looking 56 degrees past the ball, which then lies near
    // its view's edge, where a step across a ribbon moves the projection most.
    dsm::Scene wide = spot;
    wide.light.fieldOfViewDegrees = 150.0;
    wide.light.direction = {3.0, -3.0, -4.0};
    {
        SCOPED_TRACE("perspective, wide and off-axis");
        expectHiderFindsRibbonEdges(wide, 512);
    }
    dsm::Scene distant = dsm::parseScene(R"({
      "light": {"type": "distant", "position": [1.5, 5, 2], "direction": [-1.5, -4.4, -2], "up": [0, 0, -1],
                "extent": 1.2, "resolution": [64, 64]},
      "objects": []})",
                                         dir.path().string(), "distant.json");
    distant.objects = spot.objects;
    {
        SCOPED_TRACE("orthographic");
        expectHiderFindsRibbonEdges(distant, 512);
    }
}

// A tile holding more samples than a worker keeps at once is built in bands
// of rows, each sampling its border rows again: its pixels must equal those
// of a build whose smaller tiles fit whole (18² x 4096 samples against
// 10² x 4096).
TEST(Samplers, TilesBuiltInBandsGiveTheSamePixels) {
    const TempDir dir;
    const dsm::Scene scene = dsm::parseScene(R"({
      "light": {"type": "spot", "position": [0, 4, 0], "look_at": [0, 0, 0], "up": [0, 0, -1], "fov": 30,
                "resolution": [16, 16]},
      "objects": [
        {"type": "sphere", "name": "ball", "center": [0.2, 1, 0], "radius": 0.5, "opacity": 0.6},
        {"type": "plane", "name": "ground", "normal": [0, 1, 0], "size": 20}
      ]})",
                                             dir.path().string(), "bands.json");
    dsm::BuildOptions options;
    options.samplesPerPixel = 4096;
    options.threads = 2;
    options.tileSize = 16;  // one tile of 18² sample pixels: 1.3 M samples, in bands
    const std::string banded = (dir / "banded.dsm").string();
    dsm::buildMap(scene, options, banded);
    options.tileSize = 8;  // tiles of 10² sample pixels: 410 k samples each, whole
    const std::string whole = (dir / "whole.dsm").string();
    dsm::buildMap(scene, options, whole);
    expectSamePixels(*dsm::DeepShadowMap::open(banded), *dsm::DeepShadowMap::open(whole));
}

// The bucketing projects the primitives on the build's threads: with
// thousands of them (split among the threads) a build is the same to the
// byte with one thread as with two.
// The raster test lets through, in every variant this processor runs, the
// samples a test written out one sample at a time lets through: ribbons
// (axes of every direction and of no length, samples near their ends and
// edges) and bounds, groups of 1 to 64 samples.
TEST(ScanlineHider, RasterTestVariantsLetThroughTheSameSamples) {
    using dsm::detail::RasterTest;
    const auto oneByOne = [](const double* xs, const double* ys, std::size_t n, const RasterTest& t) {
        std::uint64_t bits = 0;
        for (std::size_t j = 0; j < n; ++j) {
            bool pass;
            if (t.radius2 >= 0.0) {
                const double ex = xs[j] - t.x0, ey = ys[j] - t.y0;
                const double along = std::clamp((ex * t.dx + ey * t.dy) * t.invLength2, 0.0, 1.0);
                const double gx = ex - along * t.dx, gy = ey - along * t.dy;
                pass = !(gx * gx + gy * gy > t.radius2);
            } else {
                pass = xs[j] >= t.boundsX0 && xs[j] <= t.boundsX1 && ys[j] >= t.boundsY0 && ys[j] <= t.boundsY1;
            }
            bits |= std::uint64_t(pass) << j;
        }
        return bits;
    };
    std::vector<dsm::detail::RasterTestFinder> variants{dsm::detail::baselineRasterTest(),
                                                        dsm::detail::rasterTestFinder()};
    if (dsm::detail::RasterTestFinder avx2 = dsm::detail::avx2RasterTest()) variants.push_back(avx2);
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::vector<double> xs(64 + dsm::detail::kRasterTestOverread), ys(xs.size());
    std::size_t passed = 0, tested = 0;
    for (int trial = 0; trial < 4000; ++trial) {
        RasterTest t{};
        t.x0 = 10.0 * unit(rng);
        t.y0 = 10.0 * unit(rng);
        t.dx = trial % 9 == 0 ? 0.0 : 6.0 * unit(rng) - 3.0;
        t.dy = trial % 9 == 0 ? 0.0 : 6.0 * unit(rng) - 3.0;
        const double length2 = t.dx * t.dx + t.dy * t.dy;
        t.invLength2 = length2 > 0.0 ? 1.0 / length2 : 0.0;
        t.radius2 = trial % 4 == 3 ? -1.0 : std::pow(2.0 * unit(rng), 2);
        t.boundsX0 = 10.0 * unit(rng);
        t.boundsY0 = 10.0 * unit(rng);
        t.boundsX1 = t.boundsX0 + 4.0 * unit(rng);
        t.boundsY1 = t.boundsY0 + 4.0 * unit(rng);
        const std::size_t n = 1 + rng() % 64;
        // Around the axis's middle, or the bounds.
        const double cx = t.radius2 >= 0.0 ? t.x0 + 0.5 * t.dx : 0.5 * (t.boundsX0 + t.boundsX1);
        const double cy = t.radius2 >= 0.0 ? t.y0 + 0.5 * t.dy : 0.5 * (t.boundsY0 + t.boundsY1);
        for (std::size_t j = 0; j < xs.size(); ++j) {
            xs[j] = cx + 8.0 * unit(rng) - 4.0;
            ys[j] = cy + 8.0 * unit(rng) - 4.0;
        }
        const std::uint64_t expected = oneByOne(xs.data(), ys.data(), n, t);
        for (std::size_t v = 0; v < variants.size(); ++v)
            ASSERT_EQ(variants[v](xs.data(), ys.data(), n, t), expected) << "variant " << v << ", trial " << trial;
        passed += std::size_t(std::popcount(expected));
        tested += n;
    }
    // Both outcomes are common.
    EXPECT_GT(passed, tested / 20);
    EXPECT_LT(passed, tested - tested / 20);
}

TEST(ScanlineHider, BucketsDoNotDependOnTheThreadCount) {
    const TempDir dir;
    const dsm::Scene scene = dsm::loadScene(DSM_SOURCE_DIR "/examples/hairball.json");
    ASSERT_GT(dsm::RayCaster(scene, dsm::RayCaster::Surfaces::none).surfaces().all().size(), 10000u);
    dsm::BuildOptions options = smallBuild();
    options.samplesPerPixel = 1;
    std::string bytes[2];
    for (unsigned threads : {1u, 2u}) {
        options.threads = threads;
        const std::string path = (dir / ("threads" + std::to_string(threads) + ".dsm")).string();
        dsm::buildMap(scene, options, path);
        std::ifstream in(path, std::ios::binary);
        bytes[threads - 1].assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    ASSERT_GT(bytes[0].size(), 1000u);
    EXPECT_TRUE(bytes[0] == bytes[1]);
}

// Whether the ray caster gives one ray every crossing (depth and object)
// that testing every primitive gives; adds their number to `crossings`.
::testing::AssertionResult castsEveryCrossing(const dsm::RayCaster& caster, const dsm::Vec3& origin,
                                              const dsm::Vec3& direction, double time, std::size_t& crossings) {
    dsm::RaySurfaceHits found, expected;
    caster.surfaceHits(origin, direction, time, 0.0, found);
    for (const dsm::Primitive& p : caster.surfaces().all())
        caster.surfaces().intersect(p, origin, direction, time, 0.0, expected);
    const auto key = [](const dsm::RaySurfaceHit& h) { return std::tie(h.t, h.object); };
    const auto byKey = [&](const dsm::RaySurfaceHit& a, const dsm::RaySurfaceHit& b) { return key(a) < key(b); };
    std::sort(found.begin(), found.end(), byKey);
    std::sort(expected.begin(), expected.end(), byKey);
    if (found.size() != expected.size())
        return ::testing::AssertionFailure() << found.size() << " crossings found, " << expected.size() << " expected";
    for (std::size_t i = 0; i < found.size(); ++i)
        if (key(found[i]) != key(expected[i])) return ::testing::AssertionFailure() << "crossing " << i;
    crossings += found.size();
    return ::testing::AssertionSuccess();
}

// Rays aimed into random primitives' boxes, from inside them, from near
// and from far, at random shutter times: the ray caster must give each the
// crossings that testing every primitive gives. Returns how many it found.
std::size_t expectEveryCrossingFound(const dsm::Scene& scene, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const dsm::RayCaster caster(scene);
    const dsm::ScenePrimitives& surfaces = caster.surfaces();
    const auto& all = surfaces.all();
    if (all.empty()) return 0;
    // Each ray is checked against every primitive: fewer rays through more primitives.
    const std::size_t rays = std::clamp<std::size_t>(10'000'000 / all.size(), 50, 3000);
    std::size_t crossings = 0;
    for (std::size_t r = 0; r < rays; ++r) {
        const double time = unit(rng);
        const dsm::Bounds3 box = surfaces.boundsAt(all[rng() % all.size()], time);
        dsm::Vec3 target, away;
        for (std::size_t a = 0; a < 3; ++a) {
            target[a] = box.lo[a] + unit(rng) * (box.hi[a] - box.lo[a]);
            away[a] = unit(rng) - 0.5;
        }
        const double distance = r % 3 == 0 ? 0.0 : r % 3 == 1 ? 20.0 : 5e4;  // inside, near, far
        const dsm::Vec3 origin{target[0] + distance * away[0], target[1] + distance * away[1],
                               target[2] + distance * away[2]};
        const dsm::Vec3 direction = distance == 0.0 ? away : dsm::Vec3{-away[0], -away[1], -away[2]};
        const ::testing::AssertionResult same = castsEveryCrossing(caster, origin, direction, time, crossings);
        EXPECT_TRUE(same) << "ray " << r;
        if (!same) return crossings;
    }
    EXPECT_GT(crossings, rays / 2);  // the rays do meet the surfaces
    return crossings;
}

// Embree only finds the primitives a ray may cross, with float bounds and a
// float copy of the ray; the exact test then decides. It must reach every
// primitive the exact test crosses, from near and far origins.
TEST(RayCaster, FindsEveryCrossingTheExactTestFindsWhereverTheRayStarts) {
    std::mt19937_64 rng(7);
    for (const auto& entry : std::filesystem::directory_iterator(DSM_SOURCE_DIR "/examples")) {
        if (entry.path().extension() != ".json") continue;
        SCOPED_TRACE(entry.path().filename().string());
        expectEveryCrossingFound(dsm::loadScene(entry.path().string()), rng);
    }
}

// Moving objects have their boxes at both ends of the shutter, and a ray
// meets them where they are at its own time: a hair ball moving by many
// times its strands' width.
TEST(RayCaster, FindsEveryCrossingOfMovingSurfacesAtTheRaysTime) {
    std::mt19937_64 rng(11);
    dsm::Scene scene = dsm::loadScene(DSM_SOURCE_DIR "/examples/hairball.json");
    for (dsm::SceneObject& object : scene.objects) object.motion = {0.6, -0.2, 0.3};
    expectEveryCrossingFound(scene, rng);
}

// Embree passes over a ribbon's crossings near its ray's origin (by a
// multiple of the ribbon's radius), and its rays start just before the
// scene's box: a curl of ribbons nearly as wide as they are long (half-widths
// up to 0.18 on segments 0.2 long), which fill the box, must still give every
// crossing the exact test finds.
TEST(RayCaster, FindsCrossingsOfRibbonsNearlyAsWideAsLong) {
    dsm::Curves curl;
    curl.pointsPerCurve = {40};
    for (int i = 0; i < 40; ++i) {
        const float angle = 0.4f * static_cast<float>(i);
        curl.points.push_back({0.5f * std::cos(angle), 0.5f * std::sin(angle), 0.01f * static_cast<float>(i)});
        curl.widths.push_back(0.2f + 0.16f * static_cast<float>(i % 3) / 2.0f);  // 0.2 to 0.36
    }
    curl.widths.erase(curl.widths.begin());  // the default single width
    dsm::Scene scene;
    scene.objects.push_back({"curl", curl});
    std::mt19937_64 rng(13);
    expectEveryCrossingFound(scene, rng);
}

// A hair segment about a thousand times wider than long (0.35 long, half-
// widths 43 and 445), from a random scene: Embree's hierarchy passed over its
// crossing for some rays from the light, so such segments go to Embree as
// boxes. Rays from the light through the pixels around it must get every
// crossing the exact test finds.
TEST(RayCaster, FindsCrossingsOfSegmentsFarWiderThanLong) {
    const TempDir dir;
    const dsm::Scene scene = dsm::parseScene(R"(
      {"light": {"type": "spot", "position": [1019.4681071586524, -1441.8255250861964,
      4255.523919345952], "look_at": [-384.35022014185915, 122.42165798926541, -863.6594269490745],
      "fov": 4.935454853380962, "resolution": [31, 29]}, "objects": [{"type": "mesh",
      "positions": [[-0.009826384120732445, -0.034018004686928505, -1.2080829061869234],
      [-0.6509212268005595, 1.0416373335707168, 0.875846317630065], [-1.1987966330761308,
      -1.4822198314471928, 1.024531704228047], [-2.125905204012806, -0.955475178574541,
      -0.7970520462838069], [-0.5342149000127687, -0.24695859755628224, 1.1017580295744684],
      [1.5934561272390044, -0.7921010588000843, -2.5844884049093113], [-0.23643131598712408,
      -1.4048321284768746, -0.2756876239205375], [-0.4834285613407574, -0.6942278820506143,
      0.836898526372535], [-0.5372846317858833, -1.00077094202734, -0.16002892051966677],
      [-0.34435664787831843, -1.0111352950314128, -0.7597774177568741], [-1.0355450263566177,
      -0.8942143563879068, -0.838712718034103]], "triangles": [[5, 2, 6], [1, 7, 10], [9, 2, 1]],
      "transform": [{"scale": 2.1515161025988014, "rotate": {"axis": [-0.809133470003061,
      -0.9613331945548635, -0.5554130398674448], "angle": -72.95098931065002}}, {"scale": 1000.0}]},
      {"type": "curves", "points_per_curve": [2], "points": [[-0.11724855150515534,
      0.24982535613374734, -1.2762999081646482], [-0.11733303309136962, 0.24969732554559226,
      -1.276614085619963]], "width": [0.08651303614279257, 0.8894148661694283],
      "transform": [{"scale": 1000.0}]}]}
    )",
                                             dir.path().string(), "wide.json");
    const dsm::RayCaster caster(scene);
    const dsm::detail::LightRayFrame frame = dsm::detail::lightRayFrame(dsm::lightCamera(scene.light), 31, 29);
    std::size_t crossings = 0;
    for (int i = 0; i < 40; ++i)
        for (int j = 0; j < 40; ++j) {
            dsm::Vec3 o, d;
            frame.ray(20 + i / 20.0, 11 + j / 20.0, o, d);
            ASSERT_TRUE(castsEveryCrossing(caster, o, d, 0.0, crossings)) << "ray " << i << ", " << j;
        }
    EXPECT_GT(crossings, 3000u);  // the rays meet the mesh and the segment
}

// Hair is found through Embree's own ribbons, whose float test decides only
// which segments the exact test then sees: rays that pass a segment just
// inside its half-width, anywhere along it up to its ends, from near and
// far, must get the exact test's crossing of that segment.
TEST(RayCaster, FindsHairCrossingsAtTheRibbonsEdges) {
    const dsm::Scene scene = dsm::loadScene(DSM_SOURCE_DIR "/examples/hairball.json");
    const dsm::RayCaster caster(scene);
    const dsm::ScenePrimitives& surfaces = caster.surfaces();
    const auto& all = surfaces.all();
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const auto sub = [](const dsm::Vec3& a, const dsm::Vec3& b) { return dsm::Vec3{a[0] - b[0], a[1] - b[1], a[2] - b[2]}; };
    std::size_t edgeCrossings = 0;
    for (int r = 0; r < 3000; ++r) {
        const dsm::Primitive& p = all[rng() % all.size()];
        ASSERT_EQ(p.kind, dsm::PrimitiveKind::Segment);
        const dsm::ScenePrimitives::Segment& seg = surfaces.segment(p);
        const double along = r % 10 == 0 ? 0.0 : r % 10 == 1 ? 1.0 - 1e-12 : unit(rng);
        const dsm::Vec3 axis = sub(seg.p1, seg.p0);
        const dsm::Vec3 d{unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5};
        dsm::Vec3 side{d[1] * axis[2] - d[2] * axis[1], d[2] * axis[0] - d[0] * axis[2], d[0] * axis[1] - d[1] * axis[0]};
        const double sideLength = std::sqrt(side[0] * side[0] + side[1] * side[1] + side[2] * side[2]);
        const double gap = (seg.r0 + along * (seg.r1 - seg.r0)) * (1.0 - 1e-9);
        const double distance = r % 3 == 0 ? 0.5 : r % 3 == 1 ? 20.0 : 5e4;
        dsm::Vec3 origin;
        for (std::size_t a = 0; a < 3; ++a)
            origin[a] = seg.p0[a] + along * axis[a] + side[a] / sideLength * gap - distance * d[a];
        dsm::RaySurfaceHits exact, found;
        surfaces.intersect(p, origin, d, 0.0, 0.0, exact);
        if (exact.empty()) continue;  // the far origin's rounding put the ray just outside
        ++edgeCrossings;
        caster.surfaceHits(origin, d, 0.0, 0.0, found);
        const bool present = std::any_of(found.begin(), found.end(), [&](const dsm::RaySurfaceHit& h) {
            return h.t == exact[0].t && h.object == exact[0].object;
        });
        ASSERT_TRUE(present) << "ray " << r;
    }
    EXPECT_GT(edgeCrossings, 1500u);
}

}  // namespace
