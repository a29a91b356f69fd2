// buildVisibility(): rays of one pixel -> transmittance -> sweep -> compressor,
// with MTSM layers (LV §3.2-3.3, §5.1; Xie et al. §5.1).
#include <dsm/dsm.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <random>
#include <string>
#include <vector>

#include "oracle.h"

// Heap allocations of the whole program, counted for the PixelBuilder tests
// that check what a pixel allocates.
namespace {
std::atomic<std::uint64_t> allocationCount{0};
}  // namespace

void* operator new(std::size_t size) {
    ++allocationCount;
    if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
    throw std::bad_alloc();
}
// std::stable_sort's buffer comes from this one: replaced too, so that every
// block the replaced delete frees came from malloc (AddressSanitizer checks).
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
    ++allocationCount;
    return std::malloc(size == 0 ? 1 : size);
}
// Not inlined: GCC would take free() of what `new` returned for a mismatch.
__attribute__((noinline)) void operator delete(void* p) noexcept { std::free(p); }
__attribute__((noinline)) void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace {

using dsm::CompressorOptions;
using dsm::SampleRay;
using dsm::SurfaceHit;
using dsm::VisibilityFunction;
using dsm::VolumeSample;
using ::testing::HasSubstr;

SurfaceHit hit(float z, float opacity) { return {z, {opacity, opacity, opacity}}; }

CompressorOptions options(double eps, int channels = 1, int maxLayers = 1, bool counts = true) {
    CompressorOptions o;
    o.tolerance = eps;
    o.channels = channels;
    o.keepCounts = counts;
    o.maxLayers = maxLayers;
    return o;
}

// Storage for random rays (SampleRay only views its hits and samples).
struct Pixel {
    std::vector<std::vector<SurfaceHit>> hits;
    std::vector<std::vector<VolumeSample>> volumes;
    std::vector<SampleRay> rays;
    std::vector<double> weights;
    std::uint64_t expectedCount = 0;  // non-zero-opacity hits plus volume steps
};

Pixel randomPixel(std::mt19937_64& rng, std::size_t n, int channels, bool sharedDepths) {
    std::uniform_real_distribution<float> depth(0.0f, 10.0f), unit(0.0f, 1.0f);
    Pixel p;
    p.hits.resize(n);
    p.volumes.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
        p.hits[k].resize(rng() % 8);
        for (SurfaceHit& h : p.hits[k]) {
            h.z = sharedDepths ? std::round(depth(rng)) : depth(rng);
            bool any = false;
            for (int c = 0; c < 3; ++c) {
                float& o = h.opacity[static_cast<std::size_t>(c)];
                o = unit(rng) < 0.15f ? 0.0f : unit(rng);
                if (c < channels && o != 0.0f) any = true;
            }
            if (channels == 1) h.opacity = {h.opacity[0], h.opacity[0], h.opacity[0]};
            p.expectedCount += any;
        }
        if (k % 3 == 0) {
            const float start = depth(rng);
            const std::size_t samples = 2 + rng() % 6;
            for (std::size_t i = 0; i < samples; ++i)
                p.volumes[k].push_back({start + 0.5f * static_cast<float>(i), 0.4f * unit(rng)});
            p.expectedCount += samples - 1;
        }
        p.weights.push_back(k % 5 == 0 ? 1.0 : 0.25 + unit(rng));
    }
    for (std::size_t k = 0; k < n; ++k) p.rays.push_back({p.hits[k], p.volumes[k]});
    return p;
}

// The exact filtered average of the rays' transmittances, at every depth
// where any ray has a hit or sample (left limit and value): V is linear
// between those depths.
std::vector<dsm::test::ExactVertex> exactAverage(const Pixel& p, int channels) {
    std::vector<double> depths;
    for (const SampleRay& r : p.rays) {
        for (const SurfaceHit& h : r.hits) depths.push_back(h.z);
        for (const VolumeSample& s : r.volume) depths.push_back(s.z);
    }
    std::sort(depths.begin(), depths.end());
    depths.erase(std::unique(depths.begin(), depths.end()), depths.end());
    double total = 0.0;
    for (double w : p.weights) total += w;
    std::vector<dsm::test::ExactVertex> out;
    for (double z : depths) {
        dsm::test::ExactVertex v{z, {}, {}};
        for (int c = 0; c < channels; ++c) {
            for (std::size_t k = 0; k < p.rays.size(); ++k) {
                v.left[c] += p.weights[k] * dsm::test::rayTransmittance(p.rays[k], z, c, true) / total;
                v.right[c] += p.weights[k] * dsm::test::rayTransmittance(p.rays[k], z, c) / total;
            }
        }
        out.push_back(v);
    }
    return out;
}

TEST(BuildVisibility, PixelMatchesExactAverageWithinTolerance) {
    std::mt19937_64 rng(71);
    for (int channels : {1, 3}) {
        for (std::size_t n : {1u, 4u, 16u, 64u}) {
            const Pixel p = randomPixel(rng, n, channels, n == 16);
            const double eps = dsm::autoTolerance(static_cast<double>(n));
            const VisibilityFunction f = dsm::buildVisibility(p.rays, p.weights, options(eps, channels));
            ASSERT_NO_THROW(f.validate());
            EXPECT_LE(dsm::test::maxErrorExact(exactAverage(p, channels), f, channels), eps + 1e-6)
                << "n " << n << " channels " << channels;
            EXPECT_EQ(f.totalCount(), p.expectedCount) << "n " << n;
            EXPECT_EQ(f.layerCount(), 1u);
        }
    }
}

TEST(BuildVisibility, SmallToleranceTracksTheAverageClosely) {
    std::mt19937_64 rng(72);
    const Pixel p = randomPixel(rng, 32, 3, false);
    for (double eps : {0.0, 1e-4}) {
        const VisibilityFunction f = dsm::buildVisibility(p.rays, p.weights, options(eps, 3));
        EXPECT_LE(dsm::test::maxErrorExact(exactAverage(p, 3), f, 3), std::max(eps, 0x1p-25) + 1e-6) << eps;
    }
}

TEST(BuildVisibility, CountsWithoutKeepCountsAreAbsent) {
    std::mt19937_64 rng(73);
    const Pixel p = randomPixel(rng, 8, 1, false);
    const VisibilityFunction f = dsm::buildVisibility(p.rays, p.weights, options(0.05, 1, 1, false));
    EXPECT_FALSE(f.hasCounts());
    EXPECT_EQ(f.totalCount(), 0u);
}

TEST(BuildVisibility, ZeroWeightRaysStillCount) {
    const SurfaceHit a[] = {hit(1.0f, 0.5f)};
    const SurfaceHit b[] = {hit(2.0f, 0.5f), hit(3.0f, 0.0f), hit(4.0f, 1.0f)};
    const SampleRay rays[] = {{a, {}}, {b, {}}};
    const double w[] = {1.0, 0.0};
    const VisibilityFunction f = dsm::buildVisibility(rays, w, options(0.0));
    EXPECT_EQ(f.totalCount(), 3u);
    EXPECT_NEAR(f.evaluate(10.0), 0.5, 1e-7);  // ray 1 does not shade
}

TEST(BuildVisibility, TwoOpaquePlanesMakeTwoLayers) {
    // Every ray hits an opaque plane at 1 and another at 2.
    const SurfaceHit planes[] = {hit(1.0f, 1.0f), hit(2.0f, 1.0f)};
    const std::vector<SampleRay> rays(7, SampleRay{planes, {}});
    const std::vector<double> w{1.0, 2.0, 3.0, 1.0, 1.0, 0.5, 1.0 / 3.0};
    for (double eps : {0.0, 0.05}) {
        const VisibilityFunction f = dsm::buildVisibility(rays, w, options(eps, 1, 2));
        ASSERT_NO_THROW(f.validate());
        ASSERT_EQ(f.layerCount(), 2u) << "eps " << eps;
        // Layer 0 ends at the first full occlusion.
        EXPECT_EQ(f.z(f.layerEnd(0) - 1), 1.0f);
        EXPECT_EQ(f.evaluate(0.5), 1.0);
        EXPECT_EQ(f.evaluate(1.0), 0.0);
        EXPECT_EQ(f.evaluate(1.5), 0.0);
        // Layer 1 holds what is behind: the plane at 2, starting at V = 1.
        EXPECT_NEAR(f.evaluateLayer(1, 1.5), 1.0, eps);
        EXPECT_NEAR(f.evaluateLayer(1, 2.0), 0.0, eps);
        for (float z : f.depths()) EXPECT_TRUE(z == 1.0f || z == 2.0f) << z;
        std::uint64_t layer0 = 0, layer1 = 0;
        for (std::size_t i = f.layerBegin(0); i < f.layerEnd(0); ++i) layer0 += f.count(i);
        for (std::size_t i = f.layerBegin(1); i < f.layerEnd(1); ++i) layer1 += f.count(i);
        EXPECT_EQ(layer0, 7u);
        EXPECT_EQ(layer1, 7u);
    }
    // With one layer there is no second.
    const VisibilityFunction single = dsm::buildVisibility(rays, w, options(0.05, 1, 1));
    EXPECT_EQ(single.layerCount(), 1u);
    EXPECT_EQ(single.totalCount(), 14u);
}

TEST(BuildVisibility, LastLayerRunsToTheEnd) {
    // Three opaque planes, two layers: layer 1 holds planes 2 and 3.
    const SurfaceHit planes[] = {hit(1.0f, 1.0f), hit(2.0f, 1.0f), hit(3.0f, 1.0f)};
    const SampleRay rays[] = {{planes, {}}, {planes, {}}, {planes, {}}};
    const double w[] = {1.0, 1.0, 1.0};
    const VisibilityFunction f = dsm::buildVisibility(rays, w, options(0.01, 1, 2));
    ASSERT_EQ(f.layerCount(), 2u);
    EXPECT_EQ(f.totalCount(), 9u);
    std::uint64_t layer1 = 0;
    for (std::size_t i = f.layerBegin(1); i < f.layerEnd(1); ++i) layer1 += f.count(i);
    EXPECT_EQ(layer1, 6u);
    EXPECT_EQ(f.z(f.layerEnd(1) - 1), 3.0f);
    EXPECT_NEAR(f.evaluateLayer(1, 2.5), 0.0, 0.01);
}

TEST(BuildVisibility, LayersBehindPartialAndVolumetricOccluders) {
    // Half the rays are stopped at 1; the rest at 2 (layer 0 ends at 2). A
    // fog behind both then fills layer 1, compared with its exact
    // transmittance restarted at 2 (the kappa at 2 interpolated).
    const SurfaceHit near[] = {hit(1.0f, 1.0f), hit(2.0f, 1.0f)};
    const SurfaceHit far[] = {hit(2.0f, 1.0f)};
    const VolumeSample fog[] = {{1.5f, 0.0f}, {2.5f, 0.5f}, {4.0f, 0.5f}, {6.0f, 1.0f}};
    const SampleRay rays[] = {{near, fog}, {far, fog}, {near, fog}, {far, fog}};
    const double w[] = {1.0, 1.0, 1.0, 1.0};
    const double eps = 0.01;
    const VisibilityFunction f = dsm::buildVisibility(rays, w, options(eps, 1, 3));
    ASSERT_NO_THROW(f.validate());
    ASSERT_EQ(f.layerCount(), 2u);
    EXPECT_EQ(f.z(f.layerEnd(0) - 1), 2.0f);
    // Layer 0: V(1) = 0.5 times the fog's transmittance at 1 (no fog yet).
    EXPECT_NEAR(f.evaluate(1.0), 0.5, eps);
    EXPECT_NEAR(f.evaluate(1.5), 0.5, eps);
    EXPECT_EQ(f.evaluate(2.0), 0.0);
    // Layer 1: the fog from 2 on, kappa(2) = 0.25.
    const VolumeSample restarted[] = {{2.0f, 0.25f}, {2.5f, 0.5f}, {4.0f, 0.5f}, {6.0f, 1.0f}};
    const SampleRay behind{{}, restarted};
    for (double z : {2.0, 2.25, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0})
        EXPECT_NEAR(f.evaluateLayer(1, z), dsm::test::rayTransmittance(behind, z, 0), eps + 1e-6) << z;
    // Counts: 6 hits, 4 x 3 volume steps.
    EXPECT_EQ(f.totalCount(), 6u + 12u);
}

TEST(BuildVisibility, NothingBehindTheLayerEndButAVolumeSample) {
    // Layer 0 ends at the hit (V = 0.25 <= eps); behind it only a lone volume
    // sample: layer 1 is V = 1 and must still be a valid layer.
    const SurfaceHit h[] = {hit(0.0f, 0.75f)};
    const VolumeSample lone[] = {{0.25f, 0.0f}};
    const SampleRay rays[] = {{h, lone}};
    const double w[] = {1.0};
    const VisibilityFunction f = dsm::buildVisibility(rays, w, options(0.25, 1, 2));
    EXPECT_NO_THROW(f.validate());
    EXPECT_LE(f.layerCount(), 2u);
    EXPECT_EQ(f.totalCount(), 1u);
    EXPECT_LE(f.evaluate(1.0), 0.25);
}

TEST(BuildVisibility, RgbPixel) {
    const SurfaceHit red[] = {{1.0f, {0.0f, 0.8f, 0.8f}}};   // lets red through
    const SurfaceHit grey[] = {{2.0f, {0.5f, 0.5f, 0.5f}}};
    const SampleRay rays[] = {{red, {}}, {grey, {}}};
    const double w[] = {1.0, 1.0};
    const VisibilityFunction f = dsm::buildVisibility(rays, w, options(0.01, 3));
    ASSERT_EQ(f.channels(), 3);
    EXPECT_NEAR(f.evaluate(1.5, 0), 1.0, 0.01);
    EXPECT_NEAR(f.evaluate(1.5, 1), 0.6, 0.01);
    EXPECT_NEAR(f.evaluate(3.0, 0), 0.75, 0.01);
    EXPECT_NEAR(f.evaluate(3.0, 2), 0.35, 0.01);
    // All-grey rays give a monochrome function.
    const SampleRay greyRays[] = {{grey, {}}, {grey, {}}};
    EXPECT_EQ(dsm::buildVisibility(greyRays, w, options(0.01, 3)).channels(), 1);
}

TEST(BuildVisibility, NoHitsGiveAnEmptyFunction) {
    const SampleRay rays[] = {{{}, {}}, {{}, {}}};
    const double w[] = {1.0, 1.0};
    const VisibilityFunction f = dsm::buildVisibility(rays, w, options(0.01));
    EXPECT_TRUE(f.empty());
    EXPECT_EQ(f.evaluate(5.0), 1.0);
}

std::string buildError(std::span<const SampleRay> rays, std::span<const double> weights, int channels = 1) {
    try {
        dsm::buildVisibility(rays, weights, options(0.01, channels));
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "no error";
}

TEST(BuildVisibility, ErrorsNameTheRay) {
    const SurfaceHit good[] = {hit(1.0f, 0.5f)};
    const SurfaceHit nanDepth[] = {hit(1.0f, 0.5f), hit(std::numeric_limits<float>::quiet_NaN(), 0.5f)};
    const SurfaceHit badOpacity[] = {hit(1.0f, 1.25f)};
    const VolumeSample badVolume[] = {{0.0f, 0.5f}, {1.0f, -3.0f}};
    const double w[] = {1.0, 1.0, 1.0};
    {
        const SampleRay rays[] = {{good, {}}, {good, {}}, {nanDepth, {}}};
        const std::string e = buildError(rays, w);
        EXPECT_THAT(e, HasSubstr("ray 2"));
        EXPECT_THAT(e, HasSubstr("surface hit 1"));
        EXPECT_THAT(e, HasSubstr("nan"));
    }
    {
        const SampleRay rays[] = {{badOpacity, {}}, {good, {}}, {good, {}}};
        const std::string e = buildError(rays, w);
        EXPECT_THAT(e, HasSubstr("ray 0"));
        EXPECT_THAT(e, HasSubstr("opacity 1.25"));
    }
    {
        const SampleRay rays[] = {{good, {}}, {good, badVolume}, {good, {}}};
        const std::string e = buildError(rays, w);
        EXPECT_THAT(e, HasSubstr("ray 1"));
        EXPECT_THAT(e, HasSubstr("volume sample 1"));
        EXPECT_THAT(e, HasSubstr("-3"));
    }
    {
        const SampleRay rays[] = {{good, {}}, {good, {}}, {good, {}}};
        const double bad[] = {1.0, -1.0, 1.0};
        EXPECT_THAT(buildError(rays, bad), HasSubstr("input 1"));
        const double two[] = {1.0, 1.0};
        EXPECT_NE(buildError(rays, two), "no error");
    }
}

std::vector<VisibilityFunction> transmittancesOf(std::span<const SampleRay> rays, const CompressorOptions& o) {
    std::vector<VisibilityFunction> out;
    for (const SampleRay& r : rays) out.push_back(dsm::transmittance(r, o.channels, o.keepCounts));
    return out;
}

TEST(PixelBuilder, ReusedBuilderMatchesBuildVisibility) {
    // One builder per set of options, over random pixels of every size, from
    // the rays or from their transmittances built (and prepared for the
    // sweep) beforehand, gives exactly
    // what buildVisibility() gives each pixel alone, layers included.
    std::mt19937_64 rng(77);
    const SurfaceHit planes[] = {hit(1.0f, 1.0f), hit(2.0f, 0.5f), hit(3.0f, 1.0f)};
    for (int channels : {1, 3})
        for (int layers : {1, 3}) {
            const CompressorOptions o = options(0.02, channels, layers, layers > 1);
            dsm::PixelBuilder builder(o);
            for (int trial = 0; trial < 12; ++trial) {
                Pixel p = randomPixel(rng, 1 + rng() % 120, channels, trial % 2 == 0);
                if (trial % 3 == 0) {  // opaque planes in front: layers end and restart
                    for (std::size_t k = 0; k < p.rays.size(); k += 2) p.rays[k] = {planes, p.volumes[k]};
                }
                const VisibilityFunction expected = dsm::buildVisibility(p.rays, p.weights, o);
                EXPECT_EQ(builder.build(p.rays, p.weights), expected) << "trial " << trial;
                const std::vector<VisibilityFunction> taus = transmittancesOf(p.rays, o);
                const std::vector<dsm::VisibilityView> views(taus.begin(), taus.end());
                EXPECT_EQ(builder.build(views, p.rays, p.weights), expected) << "trial " << trial;
                std::vector<dsm::SweepInput> prepared(taus.size());
                std::vector<const dsm::SweepInput*> inputs;
                for (std::size_t k = 0; k < taus.size(); ++k) {
                    prepared[k].assign(taus[k]);
                    inputs.push_back(&prepared[k]);
                }
                EXPECT_EQ(builder.build(inputs, p.rays, p.weights), expected) << "trial " << trial;
                if (HasFailure()) return;
            }
        }
}

TEST(PixelBuilder, AnErrorLeavesTheBuilderUsable) {
    // The second layer's rays are rebuilt from the rays: a bad ray stops the
    // pixel there, after the compressor has taken the first layer. The next
    // pixel must not inherit it.
    const CompressorOptions o = options(0.01, 1, 2);
    const SurfaceHit good[] = {hit(1.0f, 1.0f), hit(2.0f, 0.5f)};
    const SurfaceHit bad[] = {hit(1.0f, 1.0f), hit(std::numeric_limits<float>::quiet_NaN(), 0.5f)};
    const SampleRay goodRays[] = {{good, {}}, {good, {}}};
    const SampleRay badRays[] = {{good, {}}, {bad, {}}};
    const double w[] = {1.0, 1.0};
    const std::vector<VisibilityFunction> taus = transmittancesOf(goodRays, o);
    const std::vector<dsm::VisibilityView> views(taus.begin(), taus.end());
    dsm::PixelBuilder builder(o);
    try {
        builder.build(views, badRays, w);
        ADD_FAILURE() << "no error";
    } catch (const dsm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("ray 1"));
        EXPECT_THAT(e.what(), HasSubstr("surface hit 1"));
    }
    const VisibilityFunction expected = dsm::buildVisibility(goodRays, w, o);
    EXPECT_EQ(expected.layerCount(), 2u);
    EXPECT_EQ(builder.build(views, goodRays, w), expected);
    EXPECT_THROW(builder.build(views, std::span<const SampleRay>(goodRays, 1), w), dsm::Error);
}

TEST(PixelBuilder, AllocatesOnlyItsResultOnceWarm) {
    // After a first pixel, a pixel allocates only what its result holds:
    // as much with 400 rays as with 4 (same result), where buildVisibility()
    // allocates for every ray. The second layer (rebuilt transmittances) is
    // included: an opaque hit ends the first.
    const SurfaceHit hits[] = {hit(1.0f, 0.3f), hit(2.0f, 1.0f), hit(3.0f, 0.25f)};
    const VolumeSample volume[] = {{0.5f, 0.2f}, {1.5f, 0.4f}, {2.5f, 0.1f}};
    const std::vector<SampleRay> many(400, SampleRay{hits, volume}), few(4, SampleRay{hits, volume});
    const std::vector<double> manyWeights(400, 1.0), fewWeights(4, 1.0);
    const CompressorOptions o = options(0.01, 1, 2);
    dsm::PixelBuilder builder(o);
    const VisibilityFunction warm = builder.build(many, manyWeights);
    ASSERT_EQ(warm.layerCount(), 2u);
    auto allocations = [](auto&& build) {
        const std::uint64_t before = allocationCount;
        const VisibilityFunction f = build();
        return allocationCount - before;
    };
    const std::uint64_t fewRays = allocations([&] { return builder.build(few, fewWeights); });
    const std::uint64_t manyRays = allocations([&] { return builder.build(many, manyWeights); });
    EXPECT_EQ(manyRays, fewRays);
    EXPECT_LT(manyRays, 20u);
    EXPECT_GT(allocations([&] { return dsm::buildVisibility(many, manyWeights, o); }), 400u);
}

TEST(PixelBuilder, BuildingIntoFunctionsHandedBackAllocatesNothingOnceWarm) {
    // The sampler's way: the rays' transmittances prepared for the sweep once,
    // each pixel built into a function that held an earlier pixel, whose
    // storage the builder keeps for the next. The results are build()'s, and
    // once the functions have grown nothing is allocated, the second layer
    // included. A function handed in with other channels, counts or layers is
    // replaced whole.
    const SurfaceHit hits[] = {hit(1.0f, 0.3f), hit(2.0f, 1.0f), hit(3.0f, 0.25f)};
    const VolumeSample volume[] = {{0.5f, 0.2f}, {1.5f, 0.4f}, {2.5f, 0.1f}};
    const std::vector<SampleRay> rays(100, SampleRay{hits, volume});
    std::vector<double> weights(rays.size());
    for (std::size_t k = 0; k < weights.size(); ++k) weights[k] = 1.0 + 0.01 * static_cast<double>(k);
    const CompressorOptions o = options(0.01, 1, 2);
    std::vector<dsm::SweepInput> prepared(rays.size());
    std::vector<const dsm::SweepInput*> inputs;
    for (std::size_t k = 0; k < rays.size(); ++k) {
        prepared[k].assign(dsm::transmittance(rays[k], o.channels, o.keepCounts));
        inputs.push_back(&prepared[k]);
    }
    dsm::PixelBuilder builder(o);
    const VisibilityFunction expected = builder.build(inputs, rays, weights);
    ASSERT_EQ(expected.layerCount(), 2u);

    std::vector<VisibilityFunction> pixels(3, VisibilityFunction(3, false));
    const float grey[3] = {0.5f, 0.5f, 0.5f};
    for (VisibilityFunction& f : pixels) {
        f.append(0.25f, grey);
        f.beginLayer();
        f.append(9.0f, grey);
    }
    for (int round = 0; round < 2; ++round)
        for (VisibilityFunction& f : pixels) {
            builder.build(inputs, rays, weights, f);
            ASSERT_EQ(f, expected) << "round " << round;
        }
    const std::uint64_t before = allocationCount;
    for (VisibilityFunction& f : pixels) builder.build(inputs, rays, weights, f);
    EXPECT_EQ(allocationCount - before, 0u);
    for (const VisibilityFunction& f : pixels) EXPECT_EQ(f, expected);
    EXPECT_THROW(builder.build(inputs, std::span<const SampleRay>(rays.data(), 1), weights, pixels[0]), dsm::Error);
}

}  // namespace
