// Extreme inputs through transmittance, sweep and compressor: tolerances 0 and
// >= 1, huge and denormal depths, many hits at one depth, extreme opacities,
// a million vertices, underflowing transmittance, and invalid values.
#include <dsm/dsm.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "oracle.h"

namespace {

using dsm::Compressor;
using dsm::CompressorOptions;
using dsm::SampleRay;
using dsm::SurfaceHit;
using dsm::VisibilityFunction;
using dsm::VolumeSample;
using dsm::test::maxError;
using dsm::test::maxErrorAllChannels;
using ::testing::HasSubstr;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

SurfaceHit hit(float z, float opacity) { return {z, {opacity, opacity, opacity}}; }

// Valid, and nothing non-finite anywhere.
void expectSane(const VisibilityFunction& f) {
    ASSERT_NO_THROW(f.validate());
    for (float z : f.depths()) ASSERT_TRUE(std::isfinite(z));
    for (float v : f.allValues()) ASSERT_TRUE(std::isfinite(v) && v >= 0.0f && v <= 1.0f) << v;
}

void expectSane(const dsm::test::RecordingSink& s) {
    for (const auto& v : s.vertices) {
        ASSERT_TRUE(std::isfinite(v.z));
        for (int c = 0; c < s.channels; ++c) {
            const double x = v.v[static_cast<std::size_t>(c)];
            ASSERT_TRUE(std::isfinite(x) && x >= 0.0 && x <= 1.0) << x;
        }
    }
}

CompressorOptions options(double eps, int channels = 1, int maxLayers = 1) {
    CompressorOptions o;
    o.tolerance = eps;
    o.channels = channels;
    o.keepCounts = true;
    o.maxLayers = maxLayers;
    return o;
}

// sweep -> compressor, the core of buildVisibility, on prepared functions.
VisibilityFunction sweepCompress(std::span<const VisibilityFunction> inputs, double eps, int channels = 1,
                                 std::vector<double> weights = {}) {
    if (weights.empty()) weights.assign(inputs.size(), 1.0);
    Compressor c(options(eps, channels));
    EXPECT_FALSE(dsm::sweep(inputs, weights, channels, c).has_value());
    return c.finish();
}

template <typename F>
std::string errorOf(F&& f) {
    try {
        f();
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "no error";
}

TEST(Extremes, ToleranceZeroIsLosslessEverywhere) {
    std::mt19937_64 rng(61);
    for (int channels : {1, 3}) {
        for (int trial = 0; trial < 10; ++trial) {
            const VisibilityFunction f = dsm::test::randomMonotone(rng, 10 + 30 * trial, channels, true);
            const VisibilityFunction g = dsm::compress(f, 0.0);
            EXPECT_LE(maxErrorAllChannels(f, g), 1e-12);
            EXPECT_EQ(g.totalCount(), f.totalCount());
            expectSane(g);
        }
    }
    // The whole pipeline at eps = 0: only float rounding of the average.
    std::vector<VisibilityFunction> inputs;
    for (int k = 0; k < 16; ++k) inputs.push_back(dsm::test::randomMonotone(rng, 20, 3, true));
    const VisibilityFunction g = sweepCompress(inputs, 0.0, 3);
    const std::vector<double> w(inputs.size(), 1.0);
    EXPECT_LE(dsm::test::maxErrorExact(dsm::test::naiveAverage(inputs, w, 3), g, 3), 0x1p-25 + 1e-9);
    expectSane(g);
}

void expectLargeTolerance(double eps) {
    std::mt19937_64 rng(62);
    for (int channels : {1, 3}) {
        for (int trial = 0; trial < 10; ++trial) {
            const VisibilityFunction f = dsm::test::randomMonotone(rng, 1 + 25 * trial, channels, true);
            const VisibilityFunction g = dsm::compress(f, eps);
            EXPECT_LE(g.size(), 3u);
            EXPECT_LE(maxErrorAllChannels(f, g), eps);
            EXPECT_EQ(g.totalCount(), f.totalCount());
            expectSane(g);
        }
    }
    // Multilayer with such a tolerance: every vertex counts as blocked, the
    // layers end early, but the result stays valid and keeps every count.
    const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(2.0f, 0.5f), hit(3.0f, 0.5f), hit(4.0f, 1.0f)};
    const VolumeSample volume[] = {{0.5f, 0.1f}, {3.5f, 0.3f}};
    const SampleRay rays[] = {{hits, volume}, {hits, {}}};
    const double w[] = {1.0, 2.0};
    const VisibilityFunction b = dsm::buildVisibility(rays, w, options(eps, 1, 4));
    expectSane(b);
    EXPECT_LE(b.layerCount(), 4u);
    EXPECT_EQ(b.totalCount(), 8u + 1u);
}

TEST(Extremes, ToleranceOne) { expectLargeTolerance(1.0); }
TEST(Extremes, ToleranceTwo) { expectLargeTolerance(2.0); }
TEST(Extremes, ToleranceHuge) { expectLargeTolerance(1e30); }

TEST(Extremes, DepthsFrom1e30Down1e30Up) {
    // One function whose depths span 60 orders of magnitude, slopes and steps.
    VisibilityFunction f(1, true);
    float v = 1.0f;
    for (int e = -30; e <= 30; ++e) {
        const float z = std::pow(10.0f, static_cast<float>(e));
        v *= 0.97f;
        f.append(z, v, 1);
        if (e % 3 == 0) {
            v *= 0.9f;
            f.append(z, v, 1);
        }
    }
    expectSane(f);
    for (std::size_t i = 0; i < f.size(); ++i) EXPECT_NEAR(f.evaluate(f.z(i)), dsm::test::valueAt(f, f.z(i)), 1e-12);
    for (double eps : {0.0, 0.001, 0.05}) {
        const VisibilityFunction g = dsm::compress(f, eps);
        EXPECT_LE(maxError(f, g), eps + 1e-12) << "eps " << eps;
        EXPECT_EQ(g.totalCount(), f.totalCount());
        expectSane(g);
    }

    // Rays with hits and volume samples over the same range.
    std::vector<SurfaceHit> hits;
    std::vector<VolumeSample> volume;
    for (int e = -30; e <= 30; e += 2) hits.push_back(hit(std::pow(10.0f, static_cast<float>(e)), 0.05f));
    for (int e = -29; e <= 30; e += 3) volume.push_back({std::pow(10.0f, static_cast<float>(e)), 1e-30f});
    const SampleRay ray{hits, volume};
    const VisibilityFunction t = dsm::transmittance(ray, 1, true);
    expectSane(t);
    EXPECT_EQ(t.totalCount(), hits.size() + volume.size() - 1);
    for (const SurfaceHit& h : hits) {
        EXPECT_NEAR(t.evaluate(h.z), dsm::test::rayTransmittance(ray, h.z, 0), 1e-6) << h.z;
        EXPECT_NEAR(dsm::test::leftLimit(t, h.z), dsm::test::rayTransmittance(ray, h.z, 0, true), 1e-6) << h.z;
    }

    // Sweep of such functions against the oracle.
    std::vector<VisibilityFunction> inputs{f, t, dsm::compress(f, 0.05)};
    const std::vector<double> w{1.0, 2.0, 0.5};
    dsm::test::RecordingSink sink;
    ASSERT_FALSE(dsm::sweep(inputs, w, 1, sink).has_value());
    expectSane(sink);
    const auto exact = dsm::test::naiveAverage(inputs, w, 1);
    ASSERT_FALSE(exact.empty());
    std::size_t i = 0;
    for (const auto& e : exact) {
        ASSERT_LT(i, sink.vertices.size());
        ASSERT_EQ(sink.vertices[i].z, static_cast<float>(e.z));
        EXPECT_NEAR(sink.vertices[i].v[0], e.left[0], 1e-9) << e.z;
        while (i + 1 < sink.vertices.size() && sink.vertices[i + 1].z == sink.vertices[i].z) ++i;
        EXPECT_NEAR(sink.vertices[i].v[0], e.right[0], 1e-9) << e.z;
        ++i;
    }
    const VisibilityFunction g = sweepCompress(inputs, 0.01, 1, w);
    EXPECT_LE(dsm::test::maxErrorExact(exact, g, 1), 0.01 + 1e-9);
    expectSane(g);
}

TEST(Extremes, DenormalDepths) {
    const float d1 = std::numeric_limits<float>::denorm_min();
    const float d2 = 1e-40f, d3 = 2e-40f, d4 = 1e-38f;
    ASSERT_LT(d2, std::numeric_limits<float>::min());
    const SurfaceHit hits[] = {hit(d3, 0.25f), hit(d1, 0.5f), hit(d2, 0.5f), hit(d4, 0.5f)};
    const VolumeSample volume[] = {{d1, 1.0f}, {d3, 1.0f}, {1e-30f, 1.0f}};
    const SampleRay ray{hits, volume};
    const VisibilityFunction t = dsm::transmittance(ray, 1, true);
    expectSane(t);
    EXPECT_EQ(t.totalCount(), 6u);
    for (float z : {d1, d2, d3, d4}) {
        EXPECT_NEAR(t.evaluate(z), dsm::test::rayTransmittance(ray, z, 0), 1e-6) << z;
        EXPECT_NEAR(dsm::test::leftLimit(t, z), dsm::test::rayTransmittance(ray, z, 0, true), 1e-6) << z;
    }
    EXPECT_NEAR(t.evaluate(1.0), 0.5 * 0.5 * 0.75 * 0.5, 1e-6);

    for (double eps : {0.0, 0.01}) {
        const VisibilityFunction g = dsm::compress(t, eps);
        EXPECT_LE(maxError(t, g), eps + 1e-12);
        expectSane(g);
    }
    // A slope between two denormal depths, averaged with the steps.
    VisibilityFunction slope;
    slope.append(d2, 1.0f);
    slope.append(d3, 0.0f);
    const VisibilityFunction inputs[] = {t, slope};
    const double w[] = {1.0, 1.0};
    dsm::test::RecordingSink sink;
    ASSERT_FALSE(dsm::sweep(inputs, w, 1, sink).has_value());
    expectSane(sink);
    const auto exact = dsm::test::naiveAverage(inputs, w, 1);
    const VisibilityFunction g = sweepCompress(inputs, 0.0);
    EXPECT_LE(dsm::test::maxErrorExact(exact, g, 1), 0x1p-25 + 1e-9);
    expectSane(g);
}

TEST(Extremes, HundredThousandHitsAtOneDepth) {
    const std::size_t n = 100000;
    const float opacity = 1e-5f;
    std::vector<SurfaceHit> hits(n, hit(5.0f, opacity));
    const SampleRay ray{hits, {}};
    const double expected = std::pow(1.0 - static_cast<double>(opacity), static_cast<double>(n));
    const VisibilityFunction t = dsm::transmittance(ray, 1, true);
    ASSERT_EQ(t.size(), 2u);
    EXPECT_EQ(t.z(0), 5.0f);
    EXPECT_EQ(t.z(1), 5.0f);
    EXPECT_EQ(t.count(1), n);
    EXPECT_NEAR(t.evaluate(5.0), expected, 1e-6);
    EXPECT_EQ(t.evaluate(4.99), 1.0);

    // Sweep with a second ray stepping at the same depth: one step.
    const SurfaceHit one[] = {hit(5.0f, 0.5f)};
    const VisibilityFunction inputs[] = {t, dsm::transmittance(SampleRay{one, {}}, 1, true)};
    const double w[] = {1.0, 1.0};
    dsm::test::RecordingSink sink;
    ASSERT_FALSE(dsm::sweep(inputs, w, 1, sink).has_value());
    ASSERT_EQ(sink.vertices.size(), 2u);
    EXPECT_EQ(sink.vertices[1].count, n + 1);
    EXPECT_NEAR(sink.vertices[0].v[0], 1.0, 1e-12);
    EXPECT_NEAR(sink.vertices[1].v[0], 0.5 * (expected + 0.5), 1e-6);

    for (double eps : {0.0, 0.05}) {
        const VisibilityFunction g = sweepCompress(inputs, eps);
        ASSERT_GE(g.size(), 1u);
        ASSERT_LE(g.size(), 2u);
        for (float z : g.depths()) EXPECT_EQ(z, 5.0f);
        EXPECT_EQ(g.totalCount(), n + 1);
        EXPECT_NEAR(g.evaluate(5.0), 0.5 * (expected + 0.5), eps + 1e-6);
        expectSane(g);
    }

    const SampleRay rays[] = {ray, {one, {}}};
    const VisibilityFunction b = dsm::buildVisibility(rays, w, options(0.01));
    EXPECT_EQ(b.totalCount(), n + 1);
    EXPECT_NEAR(b.evaluate(5.0), 0.5 * (expected + 0.5), 0.01 + 1e-6);
    EXPECT_EQ(b.evaluate(4.0), 1.0);
    expectSane(b);
}

TEST(Extremes, OpacityZeroOneAndNearlyOne) {
    // Exactly 0: no vertex, no count.
    const SurfaceHit clear[] = {hit(1.0f, 0.0f), hit(2.0f, 0.0f)};
    EXPECT_TRUE(dsm::transmittance(SampleRay{clear, {}}, 1, true).empty());

    // Exactly 1: exactly 0 behind, and stays 0 through further hits.
    const SurfaceHit opaque[] = {hit(1.0f, 0.5f), hit(2.0f, 1.0f), hit(3.0f, 0.5f)};
    const VisibilityFunction o = dsm::transmittance(SampleRay{opaque, {}}, 1, true);
    expectSane(o);
    EXPECT_EQ(o.evaluate(2.0), 0.0);
    EXPECT_EQ(o.evaluate(10.0), 0.0);
    EXPECT_EQ(o.totalCount(), 3u);

    // 1 - 1e-7, many times: the product underflows to exactly 0, never NaN.
    const float nearlyOne = 1.0f - 1e-7f;
    ASSERT_LT(nearlyOne, 1.0f);
    std::vector<SurfaceHit> spread, stacked(1000, hit(3.0f, nearlyOne));
    for (int i = 0; i < 1000; ++i) spread.push_back(hit(1.0f + 0.01f * static_cast<float>(i), nearlyOne));
    for (const auto* hits : {&spread, &stacked}) {
        const VisibilityFunction t = dsm::transmittance(SampleRay{*hits, {}}, 3, true);
        expectSane(t);
        EXPECT_EQ(t.totalCount(), 1000u);
        EXPECT_EQ(t.value(t.size() - 1, 0), 0.0f);
        const float first = hits->front().z;
        EXPECT_EQ(t.evaluate(std::nextafter(first, 0.0f)), 1.0);
        EXPECT_NEAR(t.evaluate(first), hits == &spread ? 1.0 - nearlyOne : 0.0, 1e-9);
        for (double eps : {0.0, 1e-3}) {
            const VisibilityFunction g = dsm::compress(t, eps);
            EXPECT_LE(maxError(t, g), eps + 1e-12);
            expectSane(g);
            EXPECT_LE(g.evaluate(20.0), eps);
        }
        EXPECT_EQ(dsm::compress(t, 0.0).evaluate(20.0), 0.0);
        const VisibilityFunction inputs[] = {t, t};
        const VisibilityFunction s = sweepCompress(inputs, 0.0, 3);
        expectSane(s);
        EXPECT_EQ(s.evaluate(20.0), 0.0);
        EXPECT_EQ(s.totalCount(), 2000u);
    }
}

TEST(Extremes, MillionVerticesThroughTheCompressor) {
    const std::size_t n = 1000000;
    std::mt19937_64 rng(63);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    VisibilityFunction f(1, true);
    f.reserve(n);
    double v = 1.0;
    float z = 0.0f;
    for (std::size_t i = 0; i < n; ++i) {
        if (i % 97 == 0) {
            v -= unit(rng) * 0.3 * 97.0 / n;  // a step
        } else {
            z += 1e-3f;
            v -= unit(rng) * 0.5 / n;  // a slightly jagged slope
        }
        v = std::max(v, 0.0);
        f.append(z, std::min(static_cast<float>(v), f.empty() ? 1.0f : f.value(f.size() - 1)), 1);
    }
    ASSERT_EQ(f.size(), n);
    const std::vector<dsm::test::ExactVertex> exact = dsm::test::exactVertices(f);
    for (double eps : {dsm::autoTolerance(256), 1e-4}) {
        Compressor c(options(eps));
        for (std::size_t i = 0; i < n; ++i) ASSERT_TRUE(c.push(f.z(i), f.values(i), f.count(i)));
        const VisibilityFunction g = c.finish();
        EXPECT_LE(dsm::test::maxErrorExact(exact, g, 1), eps + 1e-12) << "eps " << eps;
        EXPECT_EQ(g.totalCount(), n);
        EXPECT_LT(g.size(), n / 10);
        expectSane(g);
    }
}

TEST(Extremes, TransmittanceUnderflowReachesExactlyZero) {
    const float big = std::numeric_limits<float>::max();
    const VolumeSample dense[] = {{1.0f, 1e30f}, {2.0f, 1e30f}, {3.0f, 0.0f}};
    const VolumeSample densest[] = {{0.0f, big}, {1e30f, big}, {big, big}};
    const SurfaceHit hits[] = {hit(1.5f, 0.5f), hit(2.5f, 1.0f), hit(4.0f, 0.5f)};
    for (const auto volume : {std::span<const VolumeSample>(dense), std::span<const VolumeSample>(densest)}) {
        for (int channels : {1, 3}) {
            const SampleRay ray{hits, volume};
            const VisibilityFunction t = dsm::transmittance(ray, channels, true);
            expectSane(t);
            for (int c = 0; c < channels; ++c) EXPECT_EQ(t.value(t.size() - 1, c), 0.0f);
            EXPECT_EQ(t.evaluate(1e38), 0.0);
            const VisibilityFunction inputs[] = {t, t, t};
            for (double eps : {0.0, 0.1}) {
                const VisibilityFunction g = sweepCompress(inputs, eps, channels, {1.0, 1.0 / 3.0, 0.7});
                expectSane(g);
                EXPECT_LE(g.evaluate(1e38), eps) << "eps " << eps;
            }
            // Every input ends at exactly 0: so does their average.
            for (const std::vector<double>& w : {std::vector<double>{1.0, 1.0, 1.0}, {1.0, 1.0 / 3.0, 0.7}}) {
                const VisibilityFunction g = sweepCompress(inputs, 0.0, channels, w);
                for (int c = 0; c < g.channels(); ++c) EXPECT_EQ(g.evaluate(1e38, c), 0.0);
            }
            const SampleRay rays[] = {ray, ray};
            const double w[] = {1.0, 1.0};
            const VisibilityFunction b = dsm::buildVisibility(rays, w, options(0.01, channels, 3));
            expectSane(b);
            EXPECT_EQ(b.evaluate(1e38), 0.0);
        }
    }
}

TEST(Extremes, InvalidValuesAreErrorsNamingValueAndIndex) {
    struct BadHit {
        SurfaceHit hit;
        const char* text;
    };
    const BadHit badHits[] = {
        {hit(kNaN, 0.5f), "depth nan"},
        {hit(kInf, 0.5f), "depth inf"},
        {hit(-kInf, 0.5f), "depth -inf"},
        {hit(-1.0f, 0.5f), "depth -1"},
        {hit(1.0f, std::nextafter(1.0f, 2.0f)), "opacity 1.00000012"},
        {hit(1.0f, -1e-7f), "opacity -1.00000001e-07"},
        {hit(1.0f, kNaN), "opacity nan"},
        {hit(1.0f, kInf), "opacity inf"},
    };
    for (const BadHit& bad : badHits) {
        const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(2.0f, 0.5f), bad.hit};
        const std::string e = errorOf([&] { dsm::transmittance(SampleRay{hits, {}}, 1, true); });
        EXPECT_THAT(e, HasSubstr("surface hit 2"));
        EXPECT_THAT(e, HasSubstr(bad.text));
        // Through buildVisibility the ray index is named too.
        const SampleRay rays[] = {{{}, {}}, {hits, {}}};
        const double w[] = {1.0, 1.0};
        const std::string b = errorOf([&] { dsm::buildVisibility(rays, w, options(0.01)); });
        EXPECT_THAT(b, HasSubstr("ray 1"));
        EXPECT_THAT(b, HasSubstr(bad.text));
    }
    const std::pair<VolumeSample, const char*> badSamples[] = {
        {{kNaN, 1.0f}, "depth nan"},          {{kInf, 1.0f}, "depth inf"},
        {{-kInf, 1.0f}, "depth -inf"},        {{-0.5f, 1.0f}, "depth -0.5"},
        {{1.0f, kNaN}, "extinction nan"},     {{1.0f, kInf}, "extinction inf"},
        {{1.0f, -kInf}, "extinction -inf"},   {{1.0f, -2.0f}, "extinction -2"},
    };
    for (const auto& [sample, text] : badSamples) {
        const VolumeSample volume[] = {{0.0f, 1.0f}, sample};
        const std::string e = errorOf([&] { dsm::transmittance(SampleRay{{}, volume}, 1, true); });
        EXPECT_THAT(e, HasSubstr("volume sample 1"));
        EXPECT_THAT(e, HasSubstr(text));
    }
    // The compressor's own checks.
    const std::pair<std::pair<float, double>, const char*> badVertices[] = {
        {{kNaN, 0.5}, "depth nan"},
        {{kInf, 0.5}, "depth inf"},
        {{-kInf, 0.5}, "depth -inf"},
        {{-1.0f, 0.5}, "depth -1"},
        {{3.0f, std::numeric_limits<double>::quiet_NaN()}, "visibility nan"},
        {{3.0f, std::numeric_limits<double>::infinity()}, "visibility inf"},
        {{3.0f, -std::numeric_limits<double>::infinity()}, "visibility -inf"},
        {{3.0f, 1.5}, "visibility 1.5"},
    };
    for (const auto& [vertex, text] : badVertices) {
        Compressor c(options(0.01));
        const double ok = 0.75;
        c.push(1.0f, &ok, 0);
        const std::string e = errorOf([&, z = vertex.first, v = vertex.second] { c.push(z, &v, 0); });
        EXPECT_THAT(e, HasSubstr("input vertex 1"));
        EXPECT_THAT(e, HasSubstr(text));
    }
    // And stored functions.
    VisibilityFunction f;
    f.append(1.0f, 0.5f);
    f.append(2.0f, -kInf);
    EXPECT_THAT(errorOf([&] { f.validate(); }), HasSubstr("vertex 1 channel 0: visibility -inf"));
}

}  // namespace
