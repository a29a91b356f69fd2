// Tests for the reference tracer (dsm/reference_tracer.h): each kind of
// geometry against analytic transmittance, motion blur, nearest hits, thread
// safety, and agreement with the sampler's own ray caster on scenes where both
// must give the same answer. Bounds:
//  - surfaces: products of (1 - opacity) in double from float opacities, so
//    1e-12 covers rounding; geometry is single precision in Embree, so no test
//    ray passes within 1e-4 of an edge;
//  - volumes: homogeneous media are integrated exactly by the midpoint rule,
//    up to rounding (1e-9); smooth media within the bound of
//    ReferenceTracerOptions, checked against a much finer march.
#include <gtest/gtest.h>

#include <dsm/error.h>
#include <dsm/reference_tracer.h>
#include <dsm/scene.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <variant>
#include <vector>

#include "ray_caster.h"

namespace {

using dsm::Rgb;
using dsm::Vec3;
using Transmittance = std::array<double, 3>;

constexpr double kRounding = 1e-12;

dsm::SceneObject quad(const Vec3& centre, const Vec3& halfU, const Vec3& halfV, Rgb opacity = {1.0f, 1.0f, 1.0f}) {
    dsm::SceneObject o;
    o.name = "quad";
    o.geometry = dsm::Quad{centre, halfU, halfV};
    o.opacity = opacity;
    return o;
}

dsm::SceneObject sphere(const Vec3& centre, double radius, float opacity = 1.0f) {
    dsm::SceneObject o;
    o.name = "sphere";
    o.geometry = dsm::Sphere{centre, radius};
    o.opacity = {opacity, opacity, opacity};
    return o;
}

// A slab |x|, |y| <= 10, 0 <= z <= thickness of homogeneous density.
dsm::SceneObject slab(double density, double thickness, double scale = 1.0) {
    dsm::Volume v;
    v.boundsMin = {-10.0, -10.0, 0.0};
    v.boundsMax = {10.0, 10.0, thickness};
    v.density = dsm::HomogeneousDensity{density};
    v.scale = scale;
    v.step = 0.05;
    dsm::SceneObject o;
    o.name = "slab";
    o.geometry = v;
    return o;
}

dsm::Scene sceneOf(std::vector<dsm::SceneObject> objects) {
    dsm::Scene s;
    s.objects = std::move(objects);
    return s;
}

double grey(float opacity) { return 1.0 - static_cast<double>(opacity); }

void expectTransmittance(const Transmittance& got, const Transmittance& want, double tolerance,
                         const std::string& where) {
    for (std::size_t k = 0; k < 3; ++k) EXPECT_NEAR(got[k], want[k], tolerance) << where << ", channel " << k;
}

void expectGrey(const Transmittance& got, double want, double tolerance, const std::string& where) {
    expectTransmittance(got, {want, want, want}, tolerance, where);
}

TEST(ReferenceTracer, OpaqueQuadBlocksTheSegmentThroughItOnly) {
    const dsm::ReferenceTracer tracer(sceneOf({quad({0, 0, 0}, {1, 0, 0}, {0, 1, 0})}));
    EXPECT_EQ(tracer.primitiveCount(), 2u);
    expectGrey(tracer.transmittance({0.3, 0.2, -1}, {0.3, 0.2, 1}), 0.0, 0.0, "through");
    expectGrey(tracer.transmittance({-0.7, 0.9, 1}, {0.2, -0.4, -3}), 0.0, 0.0, "oblique, through");
    expectGrey(tracer.transmittance({2.5, 0.0, -1}, {2.5, 0.0, 1}), 1.0, 0.0, "beside");
    expectGrey(tracer.transmittance({0.3, 0.2, -1}, {0.3, 0.2, -0.01}), 1.0, 0.0, "stops short");
    expectGrey(tracer.transmittance({0.3, 0.2, 0.5}, {0.3, 0.2, 3}), 1.0, 0.0, "starts behind");
    expectGrey(tracer.transmittance({0.3, 0.2, 0.5}, {0.3, 0.2, 0.5}), 1.0, 0.0, "empty segment");
}

TEST(ReferenceTracer, RayThroughTheDiagonalCountsTheQuadOnce) {
    // A quad is two triangles; its centre and the corner-to-corner line lie
    // on both, and Embree reports both.
    const float a = 0.4f;
    const dsm::ReferenceTracer tracer(sceneOf({quad({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {a, a, a})}));
    expectGrey(tracer.transmittance({0, 0, -1}, {0, 0, 1}), grey(a), kRounding, "centre");
    expectGrey(tracer.transmittance({0.5, 0.5, -1}, {0.5, 0.5, 1}), grey(a), kRounding, "on the diagonal");
    expectGrey(tracer.transmittance({0.5, -0.2, -1}, {0.5, -0.2, 1}), grey(a), kRounding, "off the diagonal");
}

TEST(ReferenceTracer, StackOfColouredQuadsMultipliesPerChannel) {
    const Rgb a{0.2f, 0.5f, 0.7f}, b{0.1f, 0.3f, 0.9f}, c{0.6f, 0.0f, 0.4f};
    // Listed out of depth order: the product must not care.
    const dsm::ReferenceTracer tracer(sceneOf({quad({0, 0, 2}, {1, 0, 0}, {0, 1, 0}, b),
                                               quad({0, 0, 3}, {1, 0, 0}, {0, 1, 0}, c),
                                               quad({0, 0, 1}, {1, 0, 0}, {0, 1, 0}, a)}));
    Transmittance all{}, firstTwo{};
    for (std::size_t k = 0; k < 3; ++k) {
        all[k] = grey(a[k]) * grey(b[k]) * grey(c[k]);
        firstTwo[k] = grey(a[k]) * grey(b[k]);
    }
    expectTransmittance(tracer.transmittance({0.25, -0.3, 0}, {0.25, -0.3, 4}), all, kRounding, "all three");
    expectTransmittance(tracer.transmittance({0.25, -0.3, 4}, {0.25, -0.3, 0}), all, kRounding, "backwards");
    expectTransmittance(tracer.transmittance({0, 0, 0}, {0, 0, 4}), all, kRounding, "through the centres");
    expectTransmittance(tracer.transmittance({0.25, -0.3, 0}, {0.25, -0.3, 2.5}), firstTwo, kRounding, "first two");
}

TEST(ReferenceTracer, OpaqueChannelsOfDifferentQuadsBlockEverything) {
    const dsm::ReferenceTracer tracer(sceneOf({quad({0, 0, 1}, {1, 0, 0}, {0, 1, 0}, {1.0f, 0.5f, 0.0f}),
                                               quad({0, 0, 2}, {1, 0, 0}, {0, 1, 0}, {0.0f, 1.0f, 1.0f}),
                                               slab(1.0, 5.0)}));
    expectGrey(tracer.transmittance({0.1, 0.1, 0}, {0.1, 0.1, 3}), 0.0, 0.0, "both");
    const Transmittance first = tracer.transmittance({0.1, 0.1, 0}, {0.1, 0.1, 1.5});
    expectTransmittance(first, {0.0, 0.5 * std::exp(-1.5), std::exp(-1.5)}, 1e-9, "first only");
}

TEST(ReferenceTracer, HomogeneousSlabGivesExpMinusKappaL) {
    const double density = 0.7, thickness = 1.3, scale = 1.5;
    const dsm::ReferenceTracer tracer(sceneOf({slab(density, thickness, scale)}));
    EXPECT_EQ(tracer.primitiveCount(), 0u);
    const double kappa = density * scale;
    expectGrey(tracer.transmittance({0, 0, -1}, {0, 0, 5}), std::exp(-kappa * thickness), 1e-9, "straight");
    // Oblique: the path inside is thickness / cos.
    const Vec3 from{-1, 0.5, -1}, to{2, -0.5, 3};
    const double cosine = 4.0 / std::sqrt(9.0 + 1.0 + 16.0);
    expectGrey(tracer.transmittance(from, to), std::exp(-kappa * thickness / cosine), 1e-9, "oblique");
    // Ending inside: only the part of the segment in the slab counts.
    expectGrey(tracer.transmittance({0, 0, -1}, {0, 0, 0.4}), std::exp(-kappa * 0.4), 1e-9, "ends inside");
    expectGrey(tracer.transmittance({0, 0, 0.2}, {0, 0, 0.5}), std::exp(-kappa * 0.3), 1e-9, "inside");
    expectGrey(tracer.transmittance({0, 0, 2}, {0, 0, 5}), 1.0, 0.0, "beyond");
}

TEST(ReferenceTracer, TransformedVolumeStretchesItsPath) {
    dsm::SceneObject s = slab(1.0, 1.0);
    s.objectToWorld = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 2, 0.5, 0, 0, 0, 1};  // z' = 2 z + 0.5
    const dsm::ReferenceTracer tracer(sceneOf({s}));
    expectGrey(tracer.transmittance({0, 0, 0}, {0, 0, 4}), std::exp(-2.0), 1e-9, "z in [0.5, 2.5]");
}

TEST(ReferenceTracer, NoiseCloudMarchIsWithinItsStatedError) {
    dsm::Volume v;
    v.boundsMin = {-1, -1, -1};
    v.boundsMax = {1, 1, 1};
    v.density = dsm::NoiseCloudDensity{2.0, 2.0, 4, 7, 0.5};
    v.step = 0.04;
    dsm::SceneObject o;
    o.geometry = v;
    const dsm::Scene scene = sceneOf({o});
    const dsm::ReferenceTracer coarse(scene);
    dsm::ReferenceTracerOptions fine;
    fine.volumeStepDivisor = 64;
    const dsm::ReferenceTracer reference(scene, fine);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    double worst = 0.0, darkest = 1.0;
    for (int i = 0; i < 200; ++i) {
        const Vec3 from{u(rng), u(rng), -2.0}, to{u(rng), u(rng), 2.0};
        const double a = coarse.transmittance(from, to)[0], b = reference.transmittance(from, to)[0];
        worst = std::max(worst, std::abs(a - b));
        darkest = std::min(darkest, b);
    }
    EXPECT_LT(darkest, 0.5) << "the cloud should attenuate some rays";
    EXPECT_LT(worst, 1e-4);
}

TEST(ReferenceTracer, SphereIsCrossedTwiceOrOnceFromInside) {
    const float a = 0.3f;
    const dsm::ReferenceTracer tracer(sceneOf({sphere({1, 2, 3}, 1.0, a)}));
    EXPECT_EQ(tracer.primitiveCount(), 1u);
    expectGrey(tracer.transmittance({1, 2, 0}, {1, 2, 6}), grey(a) * grey(a), kRounding, "through the centre");
    expectGrey(tracer.transmittance({1.999, 2, 0}, {1.999, 2, 6}), grey(a) * grey(a), kRounding, "near the rim");
    expectGrey(tracer.transmittance({2.001, 2, 0}, {2.001, 2, 6}), 1.0, 0.0, "just outside the rim");
    expectGrey(tracer.transmittance({1, 2, 3}, {1, 2, 6}), grey(a), kRounding, "from the centre");
    expectGrey(tracer.transmittance({1, 2, 2.5}, {1, 2.3, 3.2}), 1.0, 0.0, "inside");
}

TEST(ReferenceTracer, ScaledSphereIsAnEllipsoid) {
    dsm::SceneObject o = sphere({0, 0, 0}, 1.0);
    o.objectToWorld = {2, 0, 0, 5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};  // x' = 2 x + 5
    const dsm::ReferenceTracer tracer(sceneOf({o}));
    expectGrey(tracer.transmittance({6.9, 0, -2}, {6.9, 0, 2}), 0.0, 0.0, "inside the stretched rim");
    expectGrey(tracer.transmittance({7.1, 0, -2}, {7.1, 0, 2}), 1.0, 0.0, "outside");
    expectGrey(tracer.transmittance({5, 1.1, -2}, {5, 1.1, 2}), 1.0, 0.0, "outside across");
}

TEST(ReferenceTracer, HairBlocksWithinHalfItsWidthOfTheAxis) {
    // A straight hair along x through (0, 0, 0) in two segments; width 0.02.
    dsm::Curves c;
    c.pointsPerCurve = {3};
    c.points = {{-1, 0, 0}, {0, 0, 0}, {1, 0, 0}};
    c.widths = {0.02f};
    dsm::SceneObject o;
    o.name = "hair";
    o.geometry = c;
    o.opacity = {0.5f, 0.5f, 0.5f};
    const dsm::ReferenceTracer tracer(sceneOf({o}));
    EXPECT_EQ(tracer.primitiveCount(), 2u);
    expectGrey(tracer.transmittance({0.5, 0.009, -1}, {0.5, 0.009, 1}), 0.5, kRounding, "within, along z");
    expectGrey(tracer.transmittance({0.5, 0.011, -1}, {0.5, 0.011, 1}), 1.0, 0.0, "beside, along z");
    // The ribbon faces every ray: from the side it is just as wide.
    expectGrey(tracer.transmittance({-0.5, -1, 0.009}, {-0.5, 1, 0.009}), 0.5, kRounding, "within, along y");
    expectGrey(tracer.transmittance({-0.5, -1, 0.011}, {-0.5, 1, 0.011}), 1.0, 0.0, "beside, along y");
    // At the joint both segments are hit at the same place: once.
    expectGrey(tracer.transmittance({0, 0.005, -1}, {0, 0.005, 1}), 0.5, kRounding, "at the joint");
    expectGrey(tracer.transmittance({1.5, 0, -1}, {1.5, 0, 1}), 1.0, 0.0, "beyond the end");
}

TEST(ReferenceTracer, TransformedHairWidthScales) {
    dsm::Curves c;
    c.pointsPerCurve = {2};
    c.points = {{-1, 0, 0}, {1, 0, 0}};
    c.widths = {0.02f};
    dsm::SceneObject o;
    o.geometry = c;
    o.objectToWorld = {3, 0, 0, 0, 0, 3, 0, 0, 0, 0, 3, 0, 0, 0, 0, 1};  // uniform scale 3: width 0.06
    const dsm::ReferenceTracer tracer(sceneOf({o}));
    expectGrey(tracer.transmittance({2, 0.029, -1}, {2, 0.029, 1}), 0.0, 0.0, "within");
    expectGrey(tracer.transmittance({2, 0.031, -1}, {2, 0.031, 1}), 1.0, 0.0, "beside");
}

TEST(ReferenceTracer, MotionMovesEveryKindOfObject) {
    // Each object starts over x = 0 and moves 5 units along +x over the
    // shutter: at t = 0.1 it is 0.5 along (still over x = 0), at t = 0.9 4.5.
    const Vec3 motion{5, 0, 0};
    dsm::Curves c;
    c.pointsPerCurve = {2};
    c.points = {{0, -1, 6}, {0, 1, 6}};
    c.widths = {1.6f};
    dsm::SceneObject hair;
    hair.geometry = c;
    dsm::SceneObject volume = slab(1.0, 1.0);
    std::get<dsm::Volume>(volume.geometry).boundsMin = {-1, -10, 8};
    std::get<dsm::Volume>(volume.geometry).boundsMax = {1, 10, 9};
    for (dsm::SceneObject object : {quad({0, 0, 2}, {1, 0, 0}, {0, 1, 0}), sphere({0, 0, 4}, 0.8), hair, volume}) {
        object.motion = motion;
        const bool isVolume = std::holds_alternative<dsm::Volume>(object.geometry);
        const double blocked = isVolume ? std::exp(-1.0) : 0.0;
        const dsm::ReferenceTracer tracer(sceneOf({object}));
        const std::string kind = std::to_string(object.geometry.index());
        expectGrey(tracer.transmittance({0, 0, 0}, {0, 0, 10}, 0.1), blocked, 1e-9, "over 0 at 0.1, " + kind);
        expectGrey(tracer.transmittance({0, 0, 0}, {0, 0, 10}, 0.9), 1.0, 0.0, "over 0 at 0.9, " + kind);
        expectGrey(tracer.transmittance({4.5, 0, 0}, {4.5, 0, 10}, 0.1), 1.0, 0.0, "over 4.5 at 0.1, " + kind);
        expectGrey(tracer.transmittance({4.5, 0, 0}, {4.5, 0, 10}, 0.9), blocked, 1e-9, "over 4.5 at 0.9, " + kind);
    }
}

TEST(ReferenceTracer, ClosestHitDistanceNormalAndObject) {
    const dsm::ReferenceTracer tracer(
        sceneOf({quad({0, 0, 2}, {1, 0, 0}, {0, 1, 0}, {0.0f, 0.0f, 0.0f}), sphere({0, 0, 5}, 1.0), slab(1.0, 1.0)}));
    auto hit = tracer.closestHit({0.5, 0.5, 0}, {0, 0, 3}, 100);
    ASSERT_TRUE(hit.has_value());
    EXPECT_EQ(hit->object, 0u) << "a surface of opacity 0 still receives";
    EXPECT_NEAR(hit->distance, 2.0, 1e-6);
    EXPECT_NEAR(hit->position[2], 2.0, 1e-6);
    EXPECT_NEAR(hit->normal[2], -1.0, 1e-9) << "faces the origin";

    hit = tracer.closestHit({0, 0, 10}, {0, 0, -1}, 100);
    ASSERT_TRUE(hit.has_value());
    EXPECT_EQ(hit->object, 1u);
    EXPECT_NEAR(hit->distance, 4.0, 1e-9);
    EXPECT_NEAR(hit->normal[2], 1.0, 1e-9);

    // Obliquely onto the sphere: the normal is (p - c) / r.
    const Vec3 origin{3, 0.4, 5.3};
    hit = tracer.closestHit(origin, {-1, 0, 0}, 100);
    ASSERT_TRUE(hit.has_value());
    const double x = std::sqrt(1.0 - 0.4 * 0.4 - 0.3 * 0.3);
    EXPECT_NEAR(hit->distance, 3.0 - x, 1e-9);
    EXPECT_NEAR(hit->position[0], x, 1e-9);
    EXPECT_NEAR(hit->normal[0], x, 1e-9);
    EXPECT_NEAR(hit->normal[1], 0.4, 1e-9);
    EXPECT_NEAR(hit->normal[2], 0.3, 1e-9);

    // From inside, the far wall, with the normal turned back to the origin.
    hit = tracer.closestHit({0, 0, 5}, {0, 1, 0}, 100);
    ASSERT_TRUE(hit.has_value());
    EXPECT_NEAR(hit->distance, 1.0, 1e-9);
    EXPECT_NEAR(hit->normal[1], -1.0, 1e-9);

    EXPECT_FALSE(tracer.closestHit({0.5, 0.5, 0}, {0, 0, 1}, 1.9).has_value()) << "tMax before the quad";
    EXPECT_FALSE(tracer.closestHit({3, 3, 0}, {0, 0, 1}, 100).has_value()) << "misses; volumes do not count";
}

TEST(ReferenceTracer, ClosestHitFollowsMotion) {
    dsm::SceneObject s = sphere({0, 0, 5}, 1.0);
    s.motion = {0, 0, 2};
    const dsm::ReferenceTracer tracer(sceneOf({s}));
    EXPECT_NEAR(tracer.closestHit({0, 0, 0}, {0, 0, 1}, 100, 0.0)->distance, 4.0, 1e-9);
    EXPECT_NEAR(tracer.closestHit({0, 0, 0}, {0, 0, 1}, 100, 0.5)->distance, 5.0, 1e-9);
}

TEST(ReferenceTracer, BadQueriesAndGeometryThrow) {
    const dsm::ReferenceTracer tracer(sceneOf({sphere({0, 0, 0}, 1.0)}));
    const double nan = std::nan("");
    EXPECT_THROW(tracer.transmittance({0, 0, 0}, {0, 0, 1}, 1.5), dsm::Error);
    EXPECT_THROW(tracer.transmittance({0, 0, 0}, {0, 0, 1}, -0.1), dsm::Error);
    EXPECT_THROW(tracer.transmittance({nan, 0, 0}, {0, 0, 1}), dsm::Error);
    EXPECT_THROW(tracer.closestHit({0, 0, 0}, {0, 0, 0}, 1), dsm::Error);
    EXPECT_THROW(tracer.closestHit({0, 0, 0}, {0, 0, 1}, -1), dsm::Error);

    dsm::SceneObject mesh;
    mesh.name = "broken";
    mesh.geometry = dsm::TriangleMesh{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 3}}};
    try {
        dsm::ReferenceTracer bad(sceneOf({mesh}));
        FAIL() << "no error for a triangle index beyond the positions";
    } catch (const dsm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("'broken'"), std::string::npos) << e.what();
    }
    dsm::SceneObject flat = sphere({0, 0, 0}, 1.0);
    flat.objectToWorld = {1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    EXPECT_THROW(dsm::ReferenceTracer{sceneOf({flat})}, dsm::Error);
}

// A small hair ball with a sphere and a cloud: every kind the tracer handles.
dsm::Scene mixedScene() {
    dsm::HairBallParameters h;
    h.count = 400;
    h.radius = 0.5;
    h.length = 0.4;
    h.width = 0.01;
    h.segments = 6;
    dsm::SceneObject hair;
    hair.name = "hair";
    hair.geometry = dsm::generateHairBall(h);
    hair.opacity = {0.3f, 0.4f, 0.5f};
    dsm::Volume v;
    v.boundsMin = {-1, -1, -1};
    v.boundsMax = {1, 1, 1};
    v.density = dsm::NoiseCloudDensity{};
    v.step = 0.05;
    dsm::SceneObject cloud;
    cloud.geometry = v;
    return sceneOf({hair, sphere({0, 0, 0}, 0.45, 0.6f), cloud});
}

TEST(ReferenceTracer, ThreadsTracingTheSameRaysGetTheSameBits) {
    const dsm::ReferenceTracer tracer(mixedScene());
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<std::pair<Vec3, Vec3>> segments;
    for (int i = 0; i < 300; ++i) segments.push_back({{u(rng), u(rng), -2.0}, {0.3 * u(rng), 0.3 * u(rng), 2.0}});
    std::vector<Transmittance> expected;
    int shadowed = 0;
    for (const auto& [from, to] : segments) {
        expected.push_back(tracer.transmittance(from, to, 0.5));
        shadowed += expected.back()[0] < 0.99;
    }
    EXPECT_GT(shadowed, 100) << "the rays should cross the scene";
    constexpr int kThreads = 4;
    std::vector<int> mismatches(kThreads, 0);
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([&, t] {
            for (int pass = 0; pass < 2; ++pass)
                for (std::size_t i = 0; i < segments.size(); ++i)
                    if (tracer.transmittance(segments[i].first, segments[i].second, 0.5) != expected[i])
                        ++mismatches[t];
        });
    for (std::thread& t : threads) t.join();
    for (int t = 0; t < kThreads; ++t) EXPECT_EQ(mismatches[t], 0) << "thread " << t;
}

// The sampler's transmittance along a light ray, from its own ray caster:
// surface crossings before `to`, and the trapezoid rule over its volume
// samples (transmittance.h), cut at `to`.
Transmittance casterTransmittance(const dsm::RayCaster& caster, const dsm::Scene& scene, const Vec3& from,
                                  const Vec3& to, double time) {
    const Vec3 delta{to[0] - from[0], to[1] - from[1], to[2] - from[2]};
    const double length = std::sqrt(delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2]);
    const Vec3 d{delta[0] / length, delta[1] / length, delta[2] / length};
    dsm::RaySurfaceHits hits;
    caster.surfaceHits(from, d, time, 0.0, hits);
    Transmittance result{1.0, 1.0, 1.0};
    for (const dsm::RaySurfaceHit& h : hits)
        if (h.t < length)
            for (std::size_t k = 0; k < 3; ++k) result[k] *= grey(scene.objects[h.object].opacity[k]);
    std::vector<dsm::RayVolumeSample> samples;
    caster.volumeSamples(from, d, time, 0.0, samples);
    double depth = 0.0;
    for (std::size_t i = 0; i + 1 < samples.size() && samples[i].t < length; ++i) {
        const double t0 = samples[i].t, k0 = samples[i].extinction;
        double t1 = samples[i + 1].t, k1 = samples[i + 1].extinction;
        if (t1 > length) {
            k1 = k0 + (k1 - k0) * (length - t0) / (t1 - t0);
            t1 = length;
        }
        depth += 0.5 * (t1 - t0) * (k0 + k1);
    }
    for (double& r : result) r *= std::exp(-depth);
    return result;
}

TEST(ReferenceTracer, AgreesWithTheSamplersCasterOnCloudAndPipes) {
    // Light rays from the spot light to the ground. Both march the cloud:
    // the caster with the trapezoid rule at the scene's step h, we with the
    // midpoint rule at h / 8. Each march's error on a ray is estimated
    // against the same march 8 times finer (the caster's at h / 64, ours at
    // h / 64: both exact to a few 1e-7 here), and the two must agree within
    // the sum of their errors.
    dsm::Scene scene = dsm::loadScene(std::string(DSM_SOURCE_DIR) + "/examples/cloud-and-pipes.json");
    const dsm::ReferenceTracer tracer(scene);
    dsm::ReferenceTracerOptions finer;
    finer.volumeStepDivisor = 64;
    const dsm::ReferenceTracer fineTracer(scene, finer);
    const dsm::RayCaster caster(scene);
    for (dsm::SceneObject& o : scene.objects)
        if (auto* v = std::get_if<dsm::Volume>(&o.geometry)) v->step /= 64;
    const dsm::RayCaster fineCaster(scene);
    const Vec3 light = scene.light.position;
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-2.5, 2.5);
    constexpr double kConverged = 1e-6;
    int inCloud = 0, onPipes = 0;
    double ourWorst = 0.0, casterWorst = 0.0;
    for (int i = 0; i < 200; ++i) {
        // Just above the ground: its crossing at the very end would count or
        // not by rounding.
        const Vec3 ground{u(rng), 0.01, u(rng)};
        const Transmittance ours = tracer.transmittance(light, ground);
        const Transmittance oursConverged = fineTracer.transmittance(light, ground);
        const Transmittance theirs = casterTransmittance(caster, scene, light, ground, 0.0);
        const Transmittance theirsConverged = casterTransmittance(fineCaster, scene, light, ground, 0.0);
        inCloud += theirs[0] > 0.0 && theirs[0] < 0.9;
        onPipes += theirs[0] == 0.0;
        for (std::size_t k = 0; k < 3; ++k) {
            const double ourError = std::abs(ours[k] - oursConverged[k]);
            const double casterError = std::abs(theirs[k] - theirsConverged[k]);
            EXPECT_NEAR(oursConverged[k], theirsConverged[k], 2 * kConverged) << "ray " << i << " channel " << k;
            EXPECT_NEAR(ours[k], theirs[k], ourError + casterError + 2 * kConverged) << "ray " << i << " channel " << k;
            ourWorst = std::max(ourWorst, ourError);
            casterWorst = std::max(casterWorst, casterError);
        }
    }
    EXPECT_GT(inCloud, 50);
    EXPECT_GT(onPipes, 10);
    // The point of the finer march: far below the sampler's own error.
    EXPECT_LT(ourWorst, casterWorst / 10);
    RecordProperty("worst_march_error", std::to_string(ourWorst));
    RecordProperty("worst_sampler_march_error", std::to_string(casterWorst));
}

// Distance from point p to the segment a-b.
double distanceToSegment(const Vec3& p, const Vec3& a, const Vec3& b) {
    const Vec3 ab{b[0] - a[0], b[1] - a[1], b[2] - a[2]}, ap{p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    const double s = std::clamp((ab[0] * ap[0] + ab[1] * ap[1] + ab[2] * ap[2]) /
                                    (ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]), 0.0, 1.0);
    const Vec3 gap{ap[0] - s * ab[0], ap[1] - s * ab[1], ap[2] - s * ab[2]};
    return std::sqrt(gap[0] * gap[0] + gap[1] * gap[1] + gap[2] * gap[2]);
}

TEST(ReferenceTracer, AgreesWithTheSamplersCasterOnHairAwayFromJoints) {
    // The two tracers' ribbons differ only within a width of the points of a
    // curve (reference_tracer.h: Embree's half-disc ends at joints and at the
    // ends of a hair, the sampler's overlap and gaps at bends). Everywhere
    // else they must agree to rounding.
    // Long, strongly bent segments, so that most rays cross hair away from
    // its points; no volume, so answers match to rounding.
    dsm::HairBallParameters h;
    h.count = 400;
    h.radius = 0.5;
    h.length = 0.6;
    h.width = 0.01;
    h.segments = 2;
    dsm::SceneObject object;
    object.geometry = dsm::generateHairBall(h);
    object.opacity = {0.3f, 0.4f, 0.5f};
    const dsm::Scene scene = sceneOf({object});
    const dsm::ReferenceTracer tracer(scene);
    const dsm::RayCaster caster(scene);
    const dsm::Curves& hair = std::get<dsm::Curves>(scene.objects[0].geometry);
    const double width = hair.widths[0];
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const int kRays = 1000;
    int differ = 0, throughHairAwayFromPoints = 0;
    for (int i = 0; i < kRays; ++i) {
        const Vec3 from{u(rng), u(rng), -3.0}, to{0.2 * u(rng), 0.2 * u(rng), 3.0};
        const Transmittance ours = tracer.transmittance(from, to);
        const Transmittance theirs = casterTransmittance(caster, scene, from, to, 0.0);
        dsm::RaySurfaceHits hits;
        caster.surfaceHits(from, {to[0] - from[0], to[1] - from[1], to[2] - from[2]}, 0.0, 0.0, hits);
        bool nearAPoint = false;
        for (const auto& p : hair.points)
            nearAPoint = nearAPoint || distanceToSegment({p[0], p[1], p[2]}, from, to) < width;
        throughHairAwayFromPoints += !hits.empty() && !nearAPoint;
        bool same = true;
        for (std::size_t k = 0; k < 3; ++k) same = same && std::abs(ours[k] - theirs[k]) <= 1e-9;
        differ += !same;
        EXPECT_TRUE(same || nearAPoint) << "ray " << i << " disagrees away from the points of the hair: "
                                        << ours[0] << " vs " << theirs[0];
    }
    EXPECT_GT(throughHairAwayFromPoints, kRays / 4) << "too few rays cross hair away from its points";
    RecordProperty("rays_differing_near_points", differ);
}

}  // namespace
