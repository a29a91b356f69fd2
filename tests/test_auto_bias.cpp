// The automatic receiver bias (dsm/auto_bias.h): its formula, and that the
// default lookups and soft shadows keep lit ground lit at every scale of a
// scene while still seeing an occluder just above the ground.
#include <gtest/gtest.h>

#include <dsm/area_light.h>
#include <dsm/auto_bias.h>
#include <dsm/lookup.h>
#include <dsm/reader.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>
#include <dsm/soft_shadow.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "temp_dir.h"

namespace {

using dsm::Vec3;
using dsm::test::TempDir;

dsm::MapInfo perspectiveMap(std::uint32_t size, double filterWidth) {
    dsm::MapInfo info;
    info.width = info.height = size;
    info.filterWidth = filterWidth;
    info.camera.screenWindow = {-0.5, 0.5, -0.25, 0.25};  // x is the larger pixel: 1 / size at unit depth
    return info;
}

TEST(AutomaticBias, ScalesWithDepthAndResolution) {
    const dsm::MapInfo info = perspectiveMap(256, 2.0);
    const double centre = 128.0;
    // Without a normal: z 2^-14 + z / 256 (1 + 2 / 2) * 1.
    for (double z : {1e-3, 1.0, 1e4})
        EXPECT_DOUBLE_EQ(dsm::automaticBias(info, centre, centre, z), z / 16384.0 + z / 256.0 * 2.0) << "depth " << z;
    const dsm::MapInfo coarse = perspectiveMap(128, 2.0);
    EXPECT_DOUBLE_EQ(dsm::automaticBias(coarse, 64.0, 64.0, 1.0), 1.0 / 16384.0 + 1.0 / 128.0 * 2.0);
    dsm::MapInfo orthographic = perspectiveMap(256, 1.0);
    orthographic.camera.projection = dsm::Projection::Orthographic;
    EXPECT_DOUBLE_EQ(dsm::automaticBias(orthographic, centre, centre, 100.0), 100.0 / 16384.0 + 1.5 / 256.0);
}

TEST(AutomaticBias, SlopeFollowsTheNormalAgainstTheLightsRay) {
    const dsm::MapInfo info = perspectiveMap(256, 2.0);
    const double z = 10.0, floor = z / 16384.0, pixel = z / 256.0 * 2.0;
    // At the raster centre the ray is +z. A surface facing the light keeps
    // the slope-1 bias; steeper ones get more, up to the cap.
    EXPECT_DOUBLE_EQ(dsm::automaticBias(info, 128.0, 128.0, z, Vec3{0.0, 0.0, -3.0}), floor + pixel);
    EXPECT_DOUBLE_EQ(dsm::automaticBias(info, 128.0, 128.0, z, Vec3{0.5, 0.0, 1.0}), floor + pixel);
    EXPECT_NEAR(dsm::automaticBias(info, 128.0, 128.0, z, Vec3{1.0, 0.0, 1.0}), floor + pixel, 1e-12);
    EXPECT_NEAR(dsm::automaticBias(info, 128.0, 128.0, z, Vec3{std::sqrt(3.0), 0.0, -1.0}),
                floor + pixel * std::sqrt(3.0), 1e-12);
    EXPECT_DOUBLE_EQ(dsm::automaticBias(info, 128.0, 128.0, z, Vec3{1.0, 0.0, 0.0}),
                     floor + pixel * dsm::kAutomaticBiasMaxSlope);
    // Off the centre the ray tilts: raster x = 256 is screen x = 0.5, so a
    // normal (1, 0, -0.5) is perpendicular to it (the surface is edge-on).
    EXPECT_DOUBLE_EQ(dsm::automaticBias(info, 256.0, 128.0, z, Vec3{1.0, 0.0, -0.5}),
                     floor + pixel * dsm::kAutomaticBiasMaxSlope);
    // There a normal along x is at atan(2) from the ray (at the centre it is edge-on).
    EXPECT_NEAR(dsm::automaticBias(info, 256.0, 128.0, z, Vec3{1.0, 0.0, 0.0}), floor + 2.0 * pixel, 1e-12);
    // A zero or non-finite normal counts as none.
    EXPECT_DOUBLE_EQ(dsm::automaticBias(info, 128.0, 128.0, z, Vec3{0.0, 0.0, 0.0}), floor + pixel);
    EXPECT_DOUBLE_EQ(dsm::automaticBias(info, 128.0, 128.0, z, Vec3{NAN, 0.0, 1.0}), floor + pixel);
}

TEST(AutomaticBias, WorldNormalsStayPerpendicularToTheSurfaceInLightSpace) {
    // A camera that rotates, scales unevenly and mirrors.
    dsm::LightCamera camera;
    camera.worldToLight = {0.0, 2.0, 0.0, 1.0, -1.0, 0.0, 0.0, 2.0, 0.0, 0.0, -0.5, 3.0, 0.0, 0.0, 0.0, 1.0};
    const Vec3 normal{1.0, 2.0, 3.0};
    const Vec3 tangents[2] = {{2.0, -1.0, 0.0}, {3.0, 0.0, -1.0}};  // both perpendicular to the normal
    const Vec3 n = dsm::lightSpaceNormal(camera, normal);
    const Vec3 origin = camera.worldToLightSpace({0.0, 0.0, 0.0});
    for (const Vec3& t : tangents) {
        const Vec3 end = camera.worldToLightSpace(t);
        const double dot = n[0] * (end[0] - origin[0]) + n[1] * (end[1] - origin[1]) + n[2] * (end[2] - origin[2]);
        EXPECT_NEAR(dot, 0.0, 1e-12);
    }
    // The same side of the surface: a point along the world normal stays on the positive side.
    const Vec3 out = camera.worldToLightSpace(normal);
    EXPECT_GT(n[0] * (out[0] - origin[0]) + n[1] * (out[1] - origin[1]) + n[2] * (out[2] - origin[2]), 0.0);
}

// A spot light above a ground plane with a small opaque square just above
// it, everything scaled by `scale`: the ground around the square is lit, the
// ground under it is shadowed.
struct Scaled {
    std::shared_ptr<dsm::DeepShadowMap> map;
    double scale;
};

Scaled buildScaled(const TempDir& dir, double scale) {
    char json[1024];
    std::snprintf(json, sizeof json,
                  R"({"light": {"type": "spot", "position": [0, %.17g, 0], "direction": [0, -1, 0], "up": [0, 0, 1],
                                "fov": 60, "resolution": 128, "area_radius": %.17g},
                      "objects": [{"type": "plane", "center": [0, 0, 0], "normal": [0.2, 1, 0], "size": %.17g},
                                  {"type": "quad", "center": [0, %.17g, 0], "u": [%.17g, 0, 0], "v": [0, 0, %.17g]}]})",
                  10.0 * scale, 0.5 * scale, 40.0 * scale, 0.5 * scale, 1.0 * scale, 1.0 * scale);
    const std::string name = "scaled" + std::to_string(static_cast<int>(std::log10(scale)) + 10);
    const dsm::Scene scene = dsm::parseScene(json, dir.path().string(), name);
    dsm::BuildOptions options;
    options.samplesPerPixel = 16;
    options.tolerance = 0.01;
    options.mtsmLayers = 2;
    options.threads = 2;
    const std::string path = (dir / (name + ".dsm")).string();
    dsm::buildMap(scene, options, path);
    return {dsm::DeepShadowMap::open(path), scale};
}

// The ground's height at x (its normal is (0.2, 1, 0)).
double groundY(double x) { return -0.2 * x; }

// The scene at three scales, built once for the suite.
class AutomaticBiasScenes : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        dir_ = new TempDir();
        for (double scale : {1e-3, 1.0, 1e4}) scenes_.push_back(buildScaled(*dir_, scale));
    }
    static void TearDownTestSuite() {
        scenes_.clear();
        delete dir_;
    }
    static TempDir* dir_;
    static std::vector<Scaled> scenes_;
};
TempDir* AutomaticBiasScenes::dir_ = nullptr;
std::vector<Scaled> AutomaticBiasScenes::scenes_;

TEST_F(AutomaticBiasScenes, DefaultLookupsKeepLitGroundLitAtEveryScale) {
    for (const Scaled& s : scenes_) {
        const double scale = s.scale;
        dsm::LookupContext lookup(s.map);
        dsm::LookupOptions automatic;
        dsm::LookupOptions none;
        none.bias = 0.0;
        double unbiased = 0.0;
        int lit = 0;
        for (double x = -4.0; x <= 4.0; x += 0.25)
            for (double z : {-4.0, -2.5, 2.5, 4.0}) {
                const Vec3 p{x * scale, groundY(x) * scale, z * scale};
                EXPECT_GT(lookup.world(p, automatic).v[0], 0.99) << "scale " << scale << " at " << x << "," << z;
                unbiased += lookup.world(p, none).v[0];
                ++lit;
            }
        // Without a bias the ground shadows itself (the test can fail).
        EXPECT_LT(unbiased / lit, 0.9) << "scale " << scale;
        // The square 0.4 to 0.6 above the ground still shadows it.
        for (double x : {-0.4, 0.0, 0.4}) {
            const Vec3 p{x * scale, groundY(x) * scale, 0.1 * scale};
            EXPECT_LT(lookup.world(p, automatic).v[0], 0.01) << "scale " << scale << " at " << x;
            dsm::LookupOptions withNormal;
            withNormal.normal = Vec3{0.2, 1.0, 0.0};
            EXPECT_LT(lookup.world(p, withNormal).v[0], 0.01) << "scale " << scale << " at " << x;
        }
    }
}

TEST_F(AutomaticBiasScenes, DefaultSoftShadowsKeepLitGroundLitAtEveryScale) {
    for (const Scaled& s : scenes_) {
        const double scale = s.scale;
        const auto tracer = std::make_shared<dsm::SoftShadowTracer>(
            s.map, dsm::AreaLight::disk(s.map->info().camera, 0.5 * scale));
        dsm::SoftShadowContext context(tracer);
        dsm::SoftShadowOptions automatic;
        automatic.samples = 16;
        dsm::SoftShadowOptions none = automatic;
        none.bias = 0.0;
        double unbiased = 0.0;
        int count = 0;
        for (double x = -4.0; x <= 4.0; x += 1.0)
            for (double z : {-4.0, 3.0}) {
                const Vec3 p{x * scale, groundY(x) * scale, z * scale};
                EXPECT_GT(context.visibility(p, automatic).v[0], 0.99) << "scale " << scale << " at " << x << "," << z;
                dsm::SoftShadowOptions withNormal = automatic;
                withNormal.normal = Vec3{0.2, 1.0, 0.0};
                EXPECT_GT(context.visibility(p, withNormal).v[0], 0.99) << "scale " << scale << " at " << x;
                unbiased += context.visibility(p, none).v[0];
                ++count;
            }
        EXPECT_LT(unbiased / count, 0.9) << "scale " << scale;
        // Under the square's centre the light (radius 0.5, 9.7 above) is
        // hidden by the square (half-size 1, 0.5 above).
        const Vec3 under{0.0, 0.0, 0.0};
        EXPECT_LT(context.visibility(under, automatic).v[0], 0.05) << "scale " << scale;
    }
}

}  // namespace
