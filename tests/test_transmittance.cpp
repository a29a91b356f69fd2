// transmittance(): surface and volume transmittance of one sample ray (LV §3.2).
#include <dsm/dsm.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "oracle.h"

namespace {

using dsm::SampleRay;
using dsm::SurfaceHit;
using dsm::VisibilityFunction;
using dsm::VolumeSample;
using dsm::test::leftLimit;
using dsm::test::valueAt;
using ::testing::HasSubstr;

// Values are stored as float: relative error 2^-24.
constexpr double kFloat = 2e-7;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

SurfaceHit hit(float z, float opacity) { return {z, {opacity, opacity, opacity}}; }
SurfaceHit hitRgb(float z, float r, float g, float b) { return {z, {r, g, b}}; }

VisibilityFunction tau(std::span<const SurfaceHit> hits, std::span<const VolumeSample> volume = {}, int channels = 1,
                       bool counts = true, float zStart = -kInf) {
    return dsm::transmittance(SampleRay{hits, volume}, channels, counts, zStart);
}

std::size_t verticesAt(const VisibilityFunction& f, float z) {
    std::size_t n = 0;
    for (float d : f.depths()) n += d == z;
    return n;
}

std::string errorOf(std::span<const SurfaceHit> hits, std::span<const VolumeSample> volume = {}, int channels = 1) {
    try {
        tau(hits, volume, channels);
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "no error";
}

// Every vertex and midpoint of the result against the direct evaluation.
void expectMatchesReference(const SampleRay& ray, const VisibilityFunction& f, int channels) {
    std::vector<double> probes;
    for (const SurfaceHit& h : ray.hits) probes.push_back(h.z);
    for (const VolumeSample& s : ray.volume) probes.push_back(s.z);
    for (float z : f.depths()) probes.push_back(z);
    std::sort(probes.begin(), probes.end());
    const std::size_t n = probes.size();
    for (std::size_t i = 0; i + 1 < n; ++i) probes.push_back(0.5 * (probes[i] + probes[i + 1]));
    if (n > 0) probes.push_back(probes[n - 1] + 1.0);
    for (double z : probes) {
        for (int c = 0; c < channels; ++c) {
            ASSERT_NEAR(valueAt(f, z, c), dsm::test::rayTransmittance(ray, z, c), kFloat) << "z = " << z;
            ASSERT_NEAR(leftLimit(f, z, c), dsm::test::rayTransmittance(ray, z, c, true), kFloat) << "z = " << z;
        }
    }
}

TEST(Transmittance, EmptyRayIsOneEverywhere) {
    const VisibilityFunction f = tau({});
    EXPECT_TRUE(f.empty());
    EXPECT_EQ(f.evaluate(3.0), 1.0);
}

TEST(Transmittance, SingleHitIsVerticalStep) {
    const SurfaceHit hits[] = {hit(2.0f, 0.25f)};
    const VisibilityFunction f = tau(hits);
    ASSERT_EQ(f.size(), 2u);
    EXPECT_EQ(f.z(0), 2.0f);
    EXPECT_EQ(f.z(1), 2.0f);
    EXPECT_EQ(f.value(0), 1.0f);
    EXPECT_EQ(f.value(1), 0.75f);
    EXPECT_EQ(leftLimit(f, 2.0), 1.0);
    EXPECT_EQ(f.evaluate(2.0), 0.75);
    EXPECT_EQ(f.evaluate(1.9), 1.0);
    EXPECT_EQ(f.evaluate(100.0), 0.75);
}

TEST(Transmittance, HitsCompositeAsProductsOfTransparency) {
    // Given out of order; transmittance() sorts.
    const SurfaceHit hits[] = {hit(2.0f, 0.2f), hit(3.0f, 0.1f), hit(1.0f, 0.5f)};
    const VisibilityFunction f = tau(hits);
    EXPECT_NO_THROW(f.validate());
    EXPECT_EQ(f.evaluate(0.5), 1.0);
    EXPECT_NEAR(f.evaluate(1.0), 0.5, kFloat);
    EXPECT_NEAR(f.evaluate(2.0), 0.4, kFloat);
    EXPECT_NEAR(f.evaluate(3.0), 0.36, kFloat);
    EXPECT_NEAR(f.evaluate(7.0), 0.36, kFloat);
}

TEST(Transmittance, EveryHitIsVerticalStepWithFlatStretchesBetween) {
    const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(2.0f, 0.5f), hit(4.0f, 0.5f)};
    const VisibilityFunction f = tau(hits);
    for (float z : {1.0f, 2.0f, 4.0f}) EXPECT_EQ(verticesAt(f, z), 2u) << "z = " << z;
    // Piecewise constant between hits, not interpolated.
    EXPECT_NEAR(f.evaluate(1.5), 0.5, kFloat);
    EXPECT_NEAR(f.evaluate(3.0), 0.25, kFloat);
    EXPECT_NEAR(f.evaluate(3.99), 0.25, kFloat);
    EXPECT_NEAR(leftLimit(f, 2.0), 0.5, kFloat);
    EXPECT_NEAR(leftLimit(f, 4.0), 0.25, kFloat);
    EXPECT_NEAR(f.evaluate(4.0), 0.125, kFloat);
}

TEST(Transmittance, SeveralHitsAtOneDepthMakeOneStep) {
    const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(1.0f, 0.5f), hit(1.0f, 0.5f), hit(3.0f, 0.5f)};
    const VisibilityFunction f = tau(hits);
    EXPECT_EQ(verticesAt(f, 1.0f), 2u);
    EXPECT_NEAR(f.evaluate(1.0), 0.125, kFloat);
    EXPECT_NEAR(f.evaluate(2.0), 0.125, kFloat);
    EXPECT_NEAR(f.evaluate(3.0), 0.0625, kFloat);
    // The three hits are counted on the vertex after the step.
    std::size_t last = 0;
    while (last + 1 < f.size() && f.z(last + 1) == 1.0f) ++last;
    EXPECT_EQ(f.count(last), 3u);
    EXPECT_EQ(f.count(0), 0u);
    EXPECT_EQ(f.totalCount(), 4u);
}

TEST(Transmittance, ZeroOpacityHitsAreDropped) {
    const SurfaceHit hits[] = {hit(1.0f, 0.0f), hit(2.0f, 0.5f), hit(3.0f, 0.0f)};
    const VisibilityFunction f = tau(hits);
    EXPECT_EQ(verticesAt(f, 1.0f), 0u);
    EXPECT_EQ(verticesAt(f, 3.0f), 0u);
    EXPECT_EQ(f.totalCount(), 1u);
    EXPECT_NEAR(f.evaluate(5.0), 0.5, kFloat);

    // RGB: dropped only when every channel is 0.
    const SurfaceHit rgb[] = {hitRgb(1.0f, 0.0f, 0.0f, 0.0f), hitRgb(2.0f, 0.0f, 0.5f, 0.0f)};
    const VisibilityFunction g = tau(rgb, {}, 3);
    EXPECT_EQ(verticesAt(g, 1.0f), 0u);
    EXPECT_EQ(verticesAt(g, 2.0f), 2u);
    EXPECT_EQ(g.totalCount(), 1u);

    // Monochrome rays read opacity[0] only.
    const SurfaceHit monoHit[] = {hitRgb(2.0f, 0.0f, 1.0f, 1.0f)};
    EXPECT_TRUE(tau(monoHit).empty());
}

TEST(Transmittance, RgbOpacityPerChannel) {
    const SurfaceHit hits[] = {hitRgb(1.0f, 0.1f, 0.5f, 0.9f), hitRgb(2.0f, 0.5f, 0.5f, 0.5f)};
    const VisibilityFunction f = tau(hits, {}, 3);
    ASSERT_EQ(f.channels(), 3);
    const double after1[3] = {0.9, 0.5, 0.1};
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(f.evaluate(1.5, c), after1[c], kFloat);
        EXPECT_NEAR(f.evaluate(2.0, c), 0.5 * after1[c], kFloat);
    }
    EXPECT_FALSE(f.isMonochrome());
}

TEST(Transmittance, HomogeneousVolumeIsExponential) {
    const float kappa = 0.3f;
    std::vector<VolumeSample> volume;
    for (float z : {1.0f, 1.5f, 2.0f, 4.0f, 4.25f, 7.0f, 11.0f}) volume.push_back({z, kappa});
    const VisibilityFunction f = tau({}, volume);
    ASSERT_EQ(f.size(), volume.size());
    for (const VolumeSample& s : volume) {
        EXPECT_NEAR(f.evaluate(s.z), std::exp(-static_cast<double>(kappa) * (s.z - 1.0)), kFloat) << "z = " << s.z;
    }
    // Linear between samples, constant beyond the last.
    EXPECT_NEAR(f.evaluate(5.625), 0.5 * (f.evaluate(4.25) + f.evaluate(7.0)), kFloat);
    EXPECT_NEAR(f.evaluate(50.0), std::exp(-0.3 * 10.0), kFloat);
    EXPECT_EQ(f.evaluate(0.5), 1.0);
}

TEST(Transmittance, VolumeUsesTrapezoidRule) {
    // kappa linear per segment, so the trapezoid rule is exact:
    // T = exp(-dz (k_i + k_{i+1}) / 2). Given out of order.
    const VolumeSample volume[] = {{3.0f, 1.0f}, {0.0f, 0.0f}, {1.0f, 2.0f}};
    const VisibilityFunction f = tau({}, volume);
    EXPECT_NEAR(f.evaluate(0.0), 1.0, kFloat);
    EXPECT_NEAR(f.evaluate(1.0), std::exp(-1.0), kFloat);
    EXPECT_NEAR(f.evaluate(3.0), std::exp(-1.0 - 3.0), kFloat);
    EXPECT_NEAR(f.evaluate(2.0), 0.5 * (std::exp(-1.0) + std::exp(-4.0)), kFloat);
}

TEST(Transmittance, SurfaceTimesVolumeAtMergedVertices) {
    const VolumeSample volume[] = {{0.0f, 1.0f}, {2.0f, 1.0f}};
    const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(3.0f, 0.5f)};
    const VisibilityFunction f = tau(hits, volume);
    const double tv1 = 0.5 * (1.0 + std::exp(-2.0));  // volume tau is linear between its samples
    EXPECT_NEAR(leftLimit(f, 1.0), tv1, kFloat);
    EXPECT_NEAR(f.evaluate(1.0), 0.5 * tv1, kFloat);
    EXPECT_NEAR(f.evaluate(2.0), 0.5 * std::exp(-2.0), kFloat);
    EXPECT_NEAR(f.evaluate(2.5), 0.5 * std::exp(-2.0), kFloat);
    EXPECT_NEAR(leftLimit(f, 3.0), 0.5 * std::exp(-2.0), kFloat);
    EXPECT_NEAR(f.evaluate(3.0), 0.25 * std::exp(-2.0), kFloat);
    EXPECT_EQ(verticesAt(f, 1.0f), 2u);
    EXPECT_EQ(verticesAt(f, 3.0f), 2u);
    // A hit exactly at a volume sample.
    const SurfaceHit atSample[] = {hit(2.0f, 0.5f)};
    const VisibilityFunction g = tau(atSample, volume);
    EXPECT_NEAR(leftLimit(g, 2.0), std::exp(-2.0), kFloat);
    EXPECT_NEAR(g.evaluate(2.0), 0.5 * std::exp(-2.0), kFloat);
}

TEST(Transmittance, RandomRaysMatchDirectEvaluation) {
    std::mt19937_64 rng(21);
    std::uniform_real_distribution<float> depth(0.0f, 10.0f), unit(0.0f, 1.0f);
    for (int channels : {1, 3}) {
        for (int trial = 0; trial < 40; ++trial) {
            std::vector<SurfaceHit> hits(rng() % 12);
            for (SurfaceHit& h : hits) {
                h.z = trial % 2 ? std::round(depth(rng)) : depth(rng);  // shared depths on odd trials
                for (float& o : h.opacity) o = unit(rng) < 0.2f ? 0.0f : unit(rng);
            }
            std::vector<VolumeSample> volume(rng() % 3 == 0 ? 0 : rng() % 10);
            for (VolumeSample& s : volume) s = {depth(rng), 0.5f * unit(rng)};
            const SampleRay ray{hits, volume};
            const VisibilityFunction f = dsm::transmittance(ray, channels, true);
            ASSERT_NO_THROW(f.validate());
            expectMatchesReference(ray, f, channels);
            if (HasFailure()) return;
        }
    }
}

TEST(Transmittance, CountsOnePerHitAndPerVolumeStep) {
    const VolumeSample volume[] = {{1.0f, 0.1f}, {2.0f, 0.2f}, {3.0f, 0.1f}, {5.0f, 0.0f}};
    const SurfaceHit hits[] = {hit(0.5f, 0.2f), hit(2.0f, 0.3f), hit(2.5f, 0.4f), hit(2.5f, 0.1f), hit(9.0f, 0.0f),
                               hit(9.0f, 1.0f)};
    const VisibilityFunction f = tau(hits, volume);
    ASSERT_TRUE(f.hasCounts());
    EXPECT_EQ(f.totalCount(), 5u + 3u);
    for (std::size_t i = 0; i < f.size(); ++i) {
        const float z = f.z(i);
        const bool lastAtDepth = i + 1 == f.size() || f.z(i + 1) != z;
        if (z == 1.0f) {
            EXPECT_EQ(f.count(i), 0u);  // volume start: no step ends here
        } else if (z == 3.0f || z == 5.0f) {
            EXPECT_EQ(f.count(i), 1u);  // a volume step ends here
        } else if (z == 2.5f) {
            EXPECT_EQ(f.count(i), lastAtDepth ? 2u : 0u);  // two hits, after the step
        } else if (z == 0.5f || z == 9.0f) {
            EXPECT_EQ(f.count(i), lastAtDepth ? 1u : 0u);
        }
    }
    // At z = 2 both a volume step and a hit: 2 in total at that depth.
    std::uint64_t at2 = 0;
    for (std::size_t i = 0; i < f.size(); ++i)
        if (f.z(i) == 2.0f) at2 += f.count(i);
    EXPECT_EQ(at2, 2u);

    const VisibilityFunction g = tau(hits, volume, 1, false);
    EXPECT_FALSE(g.hasCounts());
    EXPECT_EQ(g.totalCount(), 0u);
    EXPECT_EQ(g.size(), f.size());
}

TEST(Transmittance, ZStartDropsHitsAtOrBeforeIt) {
    const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(2.0f, 0.5f), hit(3.0f, 0.25f)};
    const VisibilityFunction f = tau(hits, {}, 1, true, 2.0f);
    EXPECT_EQ(f.totalCount(), 1u);
    EXPECT_EQ(f.evaluate(2.5), 1.0);
    EXPECT_NEAR(f.evaluate(3.0), 0.75, kFloat);
    for (float z : f.depths()) EXPECT_GT(z, 2.0f);
    EXPECT_TRUE(tau(hits, {}, 1, true, 3.0f).empty());
}

TEST(Transmittance, ZStartCutsStraddlingVolumeSegment) {
    const VolumeSample volume[] = {{0.0f, 1.0f}, {4.0f, 3.0f}, {6.0f, 3.0f}};
    const SurfaceHit hits[] = {hit(0.5f, 0.9f), hit(5.0f, 0.5f)};
    const VisibilityFunction f = tau(hits, volume, 1, true, 1.0f);
    // kappa at the cut: 1 + (3 - 1) / 4 = 1.5.
    const double t4 = std::exp(-3.0 * (1.5 + 3.0) / 2.0);
    const double t6 = t4 * std::exp(-2.0 * 3.0);
    EXPECT_EQ(f.evaluate(0.75), 1.0);
    EXPECT_NEAR(f.evaluate(1.0), 1.0, kFloat);
    EXPECT_NEAR(f.evaluate(4.0), t4, kFloat);
    EXPECT_NEAR(f.evaluate(6.0), 0.5 * t6, kFloat);
    EXPECT_NEAR(f.evaluate(2.5), 0.5 * (1.0 + t4), kFloat);
    for (float z : f.depths()) EXPECT_GE(z, 1.0f);
    // Two volume steps end beyond the cut, and one hit.
    EXPECT_EQ(f.totalCount(), 3u);
}

TEST(Transmittance, ZStartAtSampleKeepsLaterSegments) {
    const VolumeSample volume[] = {{0.0f, 1.0f}, {1.0f, 1.0f}, {2.0f, 1.0f}};
    const VisibilityFunction f = tau({}, volume, 1, true, 1.0f);
    EXPECT_NEAR(f.evaluate(1.0), 1.0, kFloat);
    EXPECT_NEAR(f.evaluate(2.0), std::exp(-1.0), kFloat);
    EXPECT_EQ(f.totalCount(), 1u);
}

TEST(Transmittance, ErrorsNameHitIndexAndValue) {
    {
        const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(kNaN, 0.5f)};
        const std::string e = errorOf(hits);
        EXPECT_THAT(e, HasSubstr("surface hit 1"));
        EXPECT_THAT(e, HasSubstr("nan"));
    }
    {
        const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(2.0f, 0.5f), hit(kInf, 0.5f)};
        const std::string e = errorOf(hits);
        EXPECT_THAT(e, HasSubstr("surface hit 2"));
        EXPECT_THAT(e, HasSubstr("inf"));
    }
    {
        const SurfaceHit hits[] = {hit(-2.5f, 0.5f)};
        const std::string e = errorOf(hits);
        EXPECT_THAT(e, HasSubstr("surface hit 0"));
        EXPECT_THAT(e, HasSubstr("-2.5"));
    }
    {
        const SurfaceHit hits[] = {hit(1.0f, 0.5f), hit(2.0f, 1.5f)};
        const std::string e = errorOf(hits);
        EXPECT_THAT(e, HasSubstr("surface hit 1 channel 0"));
        EXPECT_THAT(e, HasSubstr("1.5"));
    }
    {
        const SurfaceHit hits[] = {hit(1.0f, -0.25f)};
        EXPECT_THAT(errorOf(hits), HasSubstr("surface hit 0 channel 0: opacity -0.25"));
    }
    {
        const SurfaceHit hits[] = {hit(1.0f, kNaN)};
        EXPECT_THAT(errorOf(hits), HasSubstr("surface hit 0 channel 0: opacity nan"));
    }
    {
        const SurfaceHit hits[] = {hitRgb(1.0f, 0.5f, 0.5f, 0.5f), hitRgb(1.0f, 0.5f, 0.5f, 2.0f)};
        EXPECT_THAT(errorOf(hits, {}, 3), HasSubstr("surface hit 1 channel 2: opacity 2"));
    }
}

TEST(Transmittance, ErrorsNameVolumeSampleIndexAndValue) {
    {
        const VolumeSample volume[] = {{0.0f, 1.0f}, {1.0f, -1.0f}};
        const std::string e = errorOf({}, volume);
        EXPECT_THAT(e, HasSubstr("volume sample 1"));
        EXPECT_THAT(e, HasSubstr("extinction -1"));
    }
    {
        const VolumeSample volume[] = {{0.0f, 1.0f}, {1.0f, 1.0f}, {2.0f, kNaN}};
        EXPECT_THAT(errorOf({}, volume), HasSubstr("volume sample 2: extinction nan"));
    }
    {
        const VolumeSample volume[] = {{0.0f, kInf}};
        EXPECT_THAT(errorOf({}, volume), HasSubstr("volume sample 0: extinction inf"));
    }
    {
        const VolumeSample volume[] = {{0.0f, 1.0f}, {kNaN, 1.0f}};
        EXPECT_THAT(errorOf({}, volume), HasSubstr("volume sample 1: depth nan"));
    }
    {
        const VolumeSample volume[] = {{-3.0f, 1.0f}};
        EXPECT_THAT(errorOf({}, volume), HasSubstr("volume sample 0: depth -3"));
    }
    EXPECT_THROW(tau({}, {}, 2), dsm::Error);
}

}  // namespace

TEST(Transmittance, ReusedBuilderMatchesFreshBuilds) {
    // One builder and one output, reused over rays of every kind (channels,
    // counts, starts, unsorted and tied depths, errors in between), give what
    // transmittance() gives each ray alone.
    std::mt19937_64 rng(22);
    std::uniform_real_distribution<float> depth(0.0f, 10.0f), unit(0.0f, 1.0f);
    dsm::TransmittanceBuilder builder;
    VisibilityFunction out;
    for (int trial = 0; trial < 120; ++trial) {
        const int channels = trial % 3 == 0 ? 3 : 1;
        const bool counts = trial % 4 != 1;
        std::vector<SurfaceHit> hits(rng() % 40);
        for (SurfaceHit& h : hits) {
            h.z = trial % 2 ? std::round(depth(rng)) : depth(rng);
            for (float& o : h.opacity) o = unit(rng) < 0.2f ? 0.0f : unit(rng);
        }
        std::vector<VolumeSample> volume(rng() % 3 == 0 ? 0 : rng() % 10);
        for (VolumeSample& s : volume) s = {trial % 5 == 0 ? std::round(depth(rng)) : depth(rng), 0.5f * unit(rng)};
        const float zStart = trial % 3 == 2 ? depth(rng) : -kInf;
        const SampleRay ray{hits, volume};
        builder.build(ray, channels, counts, zStart, out);
        EXPECT_EQ(out, dsm::transmittance(ray, channels, counts, zStart)) << "trial " << trial;
        if (trial % 10 == 0) {
            const SurfaceHit bad[] = {hit(1.0f, 0.5f), hit(kNaN, 0.5f)};
            EXPECT_THROW(builder.build(SampleRay{bad, {}}, channels, counts, -kInf, out), dsm::Error);
        }
        if (HasFailure()) return;
    }
}

namespace {

// The prepared inputs agree field by field and bit for bit.
void expectSamePrepared(const dsm::SweepInput& got, const dsm::SweepInput& want, const std::string& where) {
    ASSERT_EQ(got.channels(), want.channels()) << where;
    ASSERT_EQ(got.size(), want.size()) << where;
    EXPECT_EQ(got.vertexCount(), want.vertexCount()) << where;
    EXPECT_EQ(got.slopes(), want.slopes()) << where;
    for (std::size_t i = 0; i < want.size(); ++i) {
        EXPECT_EQ(std::bit_cast<std::uint32_t>(got.step(i).z), std::bit_cast<std::uint32_t>(want.step(i).z))
            << where << " depth " << i;
        EXPECT_EQ(got.step(i).count, want.step(i).count) << where << " depth " << i;
        EXPECT_EQ(got.step(i).flags, want.step(i).flags) << where << " depth " << i;
        for (int k = 0; k < 2 * want.channels(); ++k)
            EXPECT_EQ(std::bit_cast<std::uint64_t>(got.changes(i)[k]), std::bit_cast<std::uint64_t>(want.changes(i)[k]))
                << where << " depth " << i << " number " << k;
    }
}

}  // namespace

TEST(Transmittance, PreparedForTheSweepDirectlyAsIfBuiltThenAssigned) {
    // Rays of steps alone are prepared without building the function: the
    // result must be what assign() makes of the function, bit for bit, for
    // every kind of ray (one builder and one input reused, so that storage
    // inside and outside the object and growth are all exercised).
    std::mt19937_64 rng(23);
    std::uniform_real_distribution<float> depth(0.0f, 10.0f), unit(0.0f, 1.0f);
    dsm::TransmittanceBuilder builder;
    dsm::SweepInput prepared, reference;
    int opaque = 0, tied = 0;
    for (int trial = 0; trial < 400; ++trial) {
        const int channels = trial % 3 == 0 ? 3 : 1;
        const bool counts = trial % 4 != 1;
        std::vector<SurfaceHit> hits(trial % 7 == 0 ? rng() % 40 : rng() % 5);
        for (SurfaceHit& h : hits) {
            h.z = trial % 2 ? std::round(depth(rng)) : depth(rng);
            for (float& o : h.opacity) o = unit(rng) < 0.2f ? 0.0f : (unit(rng) < 0.1f ? 1.0f : unit(rng));
            if (unit(rng) < 0.1f) h.opacity = {1.0f, 1.0f, 1.0f};
            opaque += h.opacity[0] == 1.0f;
        }
        std::vector<VolumeSample> volume(trial % 5 == 0 ? rng() % 6 : 0);
        for (VolumeSample& s : volume) s = {depth(rng), 0.5f * unit(rng)};
        const float zStart = trial % 3 == 2 ? depth(rng) : -kInf;
        const SampleRay ray{hits, volume};
        builder.build(ray, channels, counts, zStart, prepared);
        reference.assign(dsm::transmittance(ray, channels, counts, zStart));
        tied += reference.vertexCount() > 2 * reference.size() || reference.size() < hits.size();
        expectSamePrepared(prepared, reference, "trial " + std::to_string(trial));
        if (trial % 10 == 0) {
            const SurfaceHit bad[] = {hit(1.0f, 0.5f), hit(kNaN, 0.5f)};
            EXPECT_THROW(builder.build(SampleRay{bad, {}}, channels, counts, -kInf, prepared), dsm::Error);
        }
        if (HasFailure()) return;
    }
    EXPECT_GT(opaque, 50);  // rays that reach 0, where the flags change
    EXPECT_GT(tied, 50);    // hits sharing a depth, or dropped
}
