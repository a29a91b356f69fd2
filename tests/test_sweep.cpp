// sweep(): the O(n log n) weighted average of visibility functions (LV §5.1),
// checked against the O(n^2) oracle naiveAverage().
#include <dsm/dsm.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "oracle.h"

namespace {

using dsm::VisibilityFunction;
using dsm::test::RecordingSink;
using ::testing::HasSubstr;

constexpr double kSweepTolerance = 1e-9;

RecordingSink runSweep(std::span<const VisibilityFunction> inputs, std::span<const double> weights, int channels) {
    RecordingSink sink;
    sink.channels = channels;
    const std::optional<float> refused = dsm::sweep(inputs, weights, channels, sink);
    EXPECT_FALSE(refused.has_value());
    return sink;
}

std::uint64_t inputCount(std::span<const VisibilityFunction> inputs) {
    std::uint64_t n = 0;
    for (const VisibilityFunction& f : inputs) n += f.totalCount();
    return n;
}

// Output structure and values against the oracle: one vertex per distinct
// input depth with V(z-), a second one with V(z) when there is a step, the
// count of the depth on the last vertex, values in [0, 1] and non-increasing.
void expectMatchesOracle(std::span<const VisibilityFunction> inputs, std::span<const double> weights, int channels,
                         const RecordingSink& out) {
    const std::vector<dsm::test::ExactVertex> exact = dsm::test::naiveAverage(inputs, weights, channels);
    std::map<float, std::uint64_t> countAt;
    for (const VisibilityFunction& f : inputs)
        for (std::size_t i = 0; i < f.size(); ++i) countAt[f.z(i)] += f.count(i);

    std::size_t i = 0;
    double previous[dsm::kMaxChannels] = {1.0, 1.0, 1.0};
    for (const dsm::test::ExactVertex& e : exact) {
        ASSERT_LT(i, out.vertices.size()) << "output ends before depth " << e.z;
        ASSERT_EQ(out.vertices[i].z, static_cast<float>(e.z)) << "vertex " << i;
        std::size_t last = i;
        while (last + 1 < out.vertices.size() && out.vertices[last + 1].z == out.vertices[i].z) ++last;
        ASSERT_LE(last - i, 1u) << "more than two vertices at depth " << e.z;
        bool step = false;
        for (int c = 0; c < channels; ++c) {
            const auto cc = static_cast<std::size_t>(c);
            ASSERT_NEAR(out.vertices[i].v[cc], e.left[c], kSweepTolerance) << "left limit at z = " << e.z;
            ASSERT_NEAR(out.vertices[last].v[cc], e.right[c], kSweepTolerance) << "value at z = " << e.z;
            if (std::abs(e.left[c] - e.right[c]) > kSweepTolerance) step = true;
            for (std::size_t k = i; k <= last; ++k) {
                const double v = out.vertices[k].v[cc];
                ASSERT_GE(v, 0.0);
                ASSERT_LE(v, previous[c]) << "increase at z = " << e.z;
                previous[c] = v;
            }
        }
        if (step) {
            ASSERT_EQ(last, i + 1) << "step at z = " << e.z << " needs two vertices";
        }
        if (last > i) {
            EXPECT_EQ(out.vertices[i].count, 0u);
        }
        EXPECT_EQ(out.vertices[last].count, countAt[static_cast<float>(e.z)]) << "count at z = " << e.z;
        i = last + 1;
    }
    EXPECT_EQ(i, out.vertices.size()) << "output has vertices beyond the inputs";
    std::uint64_t total = 0;
    for (const auto& v : out.vertices) total += v.count;
    EXPECT_EQ(total, inputCount(inputs));
}

struct Mix {
    const char* name;
    std::size_t functions;
    int channels;
    float depthGrid;   // > 0: many shared depths
    bool zeroWeights;  // some weights exactly 0
    bool uniformWeights;
};

void PrintTo(const Mix& mix, std::ostream* os) { *os << mix.name; }

class SweepRandom : public ::testing::TestWithParam<Mix> {};

TEST_P(SweepRandom, MatchesNaiveAverage) {
    const Mix mix = GetParam();
    std::mt19937_64 rng(1000 + mix.functions * 7 + static_cast<std::size_t>(mix.channels));
    for (int trial = 0; trial < 3; ++trial) {
        std::vector<VisibilityFunction> inputs;
        std::vector<double> weights;
        std::uniform_int_distribution<std::size_t> length(0, 24);
        std::uniform_real_distribution<double> weight(0.01, 3.0);
        dsm::test::RandomShape shape;
        shape.depthGrid = mix.depthGrid;
        for (std::size_t k = 0; k < mix.functions; ++k) {
            inputs.push_back(dsm::test::randomMonotone(rng, length(rng), mix.channels, true, shape));
            double w = mix.uniformWeights ? 1.0 : weight(rng);
            if (mix.zeroWeights && k % 3 == 1) w = 0.0;
            weights.push_back(w);
        }
        if (mix.zeroWeights) weights[0] = 0.5;  // at least one positive weight
        const RecordingSink out = runSweep(inputs, weights, mix.channels);
        expectMatchesOracle(inputs, weights, mix.channels, out);
        if (HasFailure()) return;
    }
}

INSTANTIATE_TEST_SUITE_P(
    Mixes, SweepRandom,
    ::testing::Values(Mix{"n1_mono", 1, 1, 0.0f, false, true}, Mix{"n1_rgb", 1, 3, 0.0f, false, false},
                      Mix{"n2_mono", 2, 1, 0.0f, false, false}, Mix{"n2_rgb_shared", 2, 3, 0.25f, false, true},
                      Mix{"n16_mono_shared", 16, 1, 0.25f, false, false},
                      Mix{"n16_rgb_zero_weights", 16, 3, 0.0f, true, false},
                      Mix{"n64_mono_zero_weights", 64, 1, 0.5f, true, false},
                      Mix{"n64_rgb", 64, 3, 0.0f, false, false}, Mix{"n256_mono", 256, 1, 0.0f, false, true},
                      Mix{"n256_rgb_shared", 256, 3, 0.125f, true, false}),
    [](const ::testing::TestParamInfo<Mix>& info) { return std::string(info.param.name); });

// Transmittances of surface hits alone are flat between their steps: the
// sweep then leaves out the slope bookkeeping. Such inputs, alone and with
// one sloped input among them (which brings the bookkeeping back), must both
// match the oracle, in mono and RGB.
TEST(Sweep, InputsOfStepsAloneAndWithOneSlopedInputMatchTheOracle) {
    std::mt19937_64 rng(77);
    std::uniform_real_distribution<float> depth(0.0f, 8.0f), unit(0.0f, 1.0f);
    std::uniform_real_distribution<double> weight(0.01, 3.0);
    for (int channels : {1, 3}) {
        for (int trial = 0; trial < 20; ++trial) {
            std::vector<VisibilityFunction> inputs;
            std::vector<double> weights;
            for (int k = 0; k < 40; ++k) {
                std::vector<dsm::SurfaceHit> hits(rng() % 5);
                for (dsm::SurfaceHit& h : hits) {
                    h.z = trial % 2 ? std::round(4.0f * depth(rng)) / 4.0f : depth(rng);
                    for (float& o : h.opacity) o = unit(rng) < 0.1f ? 1.0f : unit(rng);
                }
                inputs.push_back(dsm::transmittance(dsm::SampleRay{hits, {}}, channels, true));
                weights.push_back(weight(rng));
                dsm::SweepInput prepared;
                prepared.assign(inputs.back());
                ASSERT_FALSE(prepared.slopes());
            }
            expectMatchesOracle(inputs, weights, channels, runSweep(inputs, weights, channels));
            VisibilityFunction sloped(channels, true);
            const float top[3] = {1.0f, 1.0f, 1.0f}, middle[3] = {0.6f, 0.5f, 0.7f}, bottom[3] = {0.2f, 0.1f, 0.3f};
            sloped.append(depth(rng) * 0.25f, top, 1);
            sloped.append(4.0f + depth(rng) * 0.25f, middle, 1);
            sloped.append(6.5f + depth(rng) * 0.25f, bottom, 1);
            inputs.push_back(sloped);
            weights.push_back(weight(rng));
            dsm::SweepInput prepared;
            prepared.assign(inputs.back());
            ASSERT_TRUE(prepared.slopes());
            expectMatchesOracle(inputs, weights, channels, runSweep(inputs, weights, channels));
            if (HasFailure()) return;
        }
    }
}

// Inputs of steps alone are summed by sorting all their steps at once; any
// input that slopes sends the sweep through a heap of the inputs instead.
// Both must add the same terms in the same order (by depth, ties in input
// order), so a weight-0 sloped input beyond every other depth, which adds
// nothing but its own depths, must leave every vertex before it bit for bit.
TEST(Sweep, InputsOfStepsAloneSumInTheHeapsOrderBitForBit) {
    std::mt19937_64 rng(2026);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f), exponent(-6.0f, 6.0f);
    std::uniform_real_distribution<double> weight(0.01, 3.0);
    for (int channels : {1, 3}) {
        for (int trial = 0; trial < 90; ++trial) {
            // From a handful of events (sorted by insertion) to hundreds
            // (radix), depths tied on a grid, spread over 2^-6 .. 2^6, all one
            // depth, or a few ulps apart (no radix pass, one, or two and
            // insertion); bunches of close depths, which differ below the 12 bits
            // that the radix passes sort (insertion finishes); or a bunch of
            // a few ulps with one far away, which would make insertion
            // quadratic (an exact radix sort finishes); some weights 0.
            const std::size_t functions = 1 + rng() % (trial % 3 == 0 ? 6 : 120);
            std::vector<VisibilityFunction> inputs;
            std::vector<double> weights;
            for (std::size_t k = 0; k < functions; ++k) {
                std::vector<dsm::SurfaceHit> hits(rng() % 6);
                for (dsm::SurfaceHit& h : hits) {
                    switch (trial % 6) {
                        case 0: h.z = std::round(8.0f * unit(rng)) / 4.0f; break;
                        case 1: h.z = std::exp2(exponent(rng)); break;
                        case 2: h.z = 3.0f; break;  // one depth: nothing to sort
                        case 4:  // bunches of a few ulps, spread over 2^20 ulps
                            h.z = std::bit_cast<float>(std::bit_cast<std::uint32_t>(3.0f) +
                                                       static_cast<std::uint32_t>(rng() % 64) * 16384u +
                                                       static_cast<std::uint32_t>(rng() % 3));
                            break;
                        case 5:  // a bunch of 200 ulps, and now and then a depth far behind
                            h.z = rng() % 50 == 0 ? 900.0f
                                                  : std::bit_cast<float>(std::bit_cast<std::uint32_t>(3.0f) +
                                                                         static_cast<std::uint32_t>(rng() % 200));
                            break;
                        default:  // within 200 ulps: the keys differ in their low byte alone
                            h.z = std::bit_cast<float>(std::bit_cast<std::uint32_t>(3.0f) +
                                                       static_cast<std::uint32_t>(rng() % 200));
                    }
                    for (float& o : h.opacity) o = unit(rng) < 0.1f ? 1.0f : unit(rng);
                }
                inputs.push_back(dsm::transmittance(dsm::SampleRay{hits, {}}, channels, true));
                weights.push_back(rng() % 8 == 0 ? 0.0 : weight(rng));
            }
            weights.front() = weight(rng);  // the weights may not all be 0
            const RecordingSink flat = runSweep(inputs, weights, channels);

            VisibilityFunction sloped(channels, true);
            const float top[3] = {1.0f, 1.0f, 1.0f}, bottom[3] = {0.2f, 0.1f, 0.3f};
            sloped.append(1000.0f, top, 1);
            sloped.append(2000.0f, bottom, 1);
            inputs.push_back(sloped);
            weights.push_back(0.0);
            const RecordingSink heap = runSweep(inputs, weights, channels);

            ASSERT_EQ(heap.vertices.size(), flat.vertices.size() + 2);
            for (std::size_t i = 0; i < flat.vertices.size(); ++i) {
                ASSERT_EQ(std::bit_cast<std::uint32_t>(flat.vertices[i].z),
                          std::bit_cast<std::uint32_t>(heap.vertices[i].z))
                    << "vertex " << i;
                ASSERT_EQ(flat.vertices[i].count, heap.vertices[i].count) << "vertex " << i;
                for (std::size_t c = 0; c < static_cast<std::size_t>(channels); ++c)
                    ASSERT_EQ(std::bit_cast<std::uint64_t>(flat.vertices[i].v[c]),
                              std::bit_cast<std::uint64_t>(heap.vertices[i].v[c]))
                        << "vertex " << i << " channel " << c << " at z = " << flat.vertices[i].z;
            }
        }
    }
}

TEST(Sweep, SingleInputIsReproduced) {
    VisibilityFunction f(1, true);
    f.append(1.0f, 1.0f, 0);
    f.append(1.0f, 0.5f, 2);
    f.append(3.0f, 0.25f, 1);
    f.append(5.0f, 0.25f, 1);
    f.append(5.0f, 0.0f, 4);
    const double w[] = {2.5};
    const RecordingSink out = runSweep({&f, 1}, w, 1);
    ASSERT_EQ(out.vertices.size(), 5u);
    const double expected[] = {1.0, 0.5, 0.25, 0.25, 0.0};
    const std::uint32_t counts[] = {0, 2, 1, 0, 5};
    for (std::size_t i = 0; i < 5; ++i) {
        EXPECT_EQ(out.vertices[i].z, f.z(i));
        EXPECT_NEAR(out.vertices[i].v[0], expected[i], 1e-12);
        EXPECT_EQ(out.vertices[i].count, counts[i]) << "vertex " << i;
    }
}

TEST(Sweep, WeightedAverageOfStepAndSlope) {
    VisibilityFunction step, slope;
    step.append(2.0f, 1.0f);
    step.append(2.0f, 0.0f);
    slope.append(0.0f, 1.0f);
    slope.append(4.0f, 0.0f);
    const VisibilityFunction inputs[] = {step, slope};
    const double w[] = {1.0, 3.0};
    const RecordingSink out = runSweep(inputs, w, 1);
    // Depths 0, 2 (left limit and step), 4.
    ASSERT_EQ(out.vertices.size(), 4u);
    EXPECT_NEAR(out.vertices[0].v[0], 1.0, 1e-12);
    EXPECT_EQ(out.vertices[1].z, 2.0f);
    EXPECT_NEAR(out.vertices[1].v[0], 0.25 + 0.75 * 0.5, 1e-12);
    EXPECT_EQ(out.vertices[2].z, 2.0f);
    EXPECT_NEAR(out.vertices[2].v[0], 0.75 * 0.5, 1e-12);
    EXPECT_NEAR(out.vertices[3].v[0], 0.0, 1e-12);
}

TEST(Sweep, OutputIsDeterministic) {
    std::mt19937_64 rng(31);
    std::vector<VisibilityFunction> inputs;
    std::vector<double> weights;
    dsm::test::RandomShape shape;
    shape.depthGrid = 0.25f;
    for (int k = 0; k < 100; ++k) {
        inputs.push_back(dsm::test::randomMonotone(rng, 20, 3, true, shape));
        weights.push_back(0.1 + static_cast<double>(k % 7));
    }
    const RecordingSink a = runSweep(inputs, weights, 3);
    const RecordingSink b = runSweep(inputs, weights, 3);
    ASSERT_EQ(a.vertices.size(), b.vertices.size());
    for (std::size_t i = 0; i < a.vertices.size(); ++i) {
        EXPECT_EQ(a.vertices[i].z, b.vertices[i].z);
        EXPECT_EQ(a.vertices[i].v, b.vertices[i].v);
        EXPECT_EQ(a.vertices[i].count, b.vertices[i].count);
    }
}

TEST(Sweep, NoInputsGiveNoVertices) {
    RecordingSink sink;
    EXPECT_FALSE(dsm::sweep({}, {}, 1, sink).has_value());
    EXPECT_TRUE(sink.vertices.empty());
    // Empty functions average to V = 1: no vertices either.
    const VisibilityFunction empty[2] = {VisibilityFunction(), VisibilityFunction()};
    const double w[] = {1.0, 1.0};
    EXPECT_FALSE(dsm::sweep(empty, w, 1, sink).has_value());
    EXPECT_TRUE(sink.vertices.empty());
}

TEST(Sweep, StopsWhereTheSinkRefuses) {
    std::mt19937_64 rng(32);
    std::vector<VisibilityFunction> inputs;
    for (int k = 0; k < 8; ++k) inputs.push_back(dsm::test::randomMonotone(rng, 30, 1, false));
    const std::vector<double> weights(inputs.size(), 1.0);
    RecordingSink full;
    ASSERT_FALSE(dsm::sweep(inputs, weights, 1, full).has_value());
    ASSERT_GT(full.vertices.size(), 10u);
    const float limit = full.vertices[full.vertices.size() / 2].z;
    RecordingSink part;
    part.refuseBeyond = limit;
    const std::optional<float> refused = dsm::sweep(inputs, weights, 1, part);
    ASSERT_TRUE(refused.has_value());
    EXPECT_GT(*refused, limit);
    // The first refused depth is the next depth of the full output.
    const auto next = std::find_if(full.vertices.begin(), full.vertices.end(),
                                   [&](const RecordingSink::Vertex& v) { return v.z > limit; });
    ASSERT_NE(next, full.vertices.end());
    EXPECT_EQ(*refused, next->z);
    ASSERT_EQ(part.vertices.size(), static_cast<std::size_t>(next - full.vertices.begin()));
    for (std::size_t i = 0; i < part.vertices.size(); ++i) EXPECT_EQ(part.vertices[i].v, full.vertices[i].v);
}

std::string sweepError(std::span<const VisibilityFunction> inputs, std::span<const double> weights, int channels) {
    RecordingSink sink;
    sink.channels = channels;
    try {
        dsm::sweep(inputs, weights, channels, sink);
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "no error";
}

VisibilityFunction simple(int channels = 1) {
    VisibilityFunction f(channels);
    const float v[3] = {0.5f, 0.5f, 0.5f};
    f.append(1.0f, v);
    return f;
}

TEST(Sweep, RejectsMismatchedChannels) {
    const VisibilityFunction inputs[] = {simple(1), simple(3), simple(1)};
    const double w[] = {1.0, 1.0, 1.0};
    EXPECT_THAT(sweepError(inputs, w, 1), HasSubstr("input 1 has 3 channels"));
    EXPECT_THAT(sweepError(inputs, w, 3), HasSubstr("input 0 has 1 channels"));
    EXPECT_THAT(sweepError(inputs, w, 2), HasSubstr("channel count 2"));
}

TEST(Sweep, RejectsBadWeights) {
    const VisibilityFunction inputs[] = {simple(), simple(), simple()};
    {
        const double w[] = {1.0, 1.0, -0.5};
        EXPECT_THAT(sweepError(inputs, w, 1), HasSubstr("weight -0.5 of input 2"));
    }
    {
        const double w[] = {std::numeric_limits<double>::quiet_NaN(), 1.0, 1.0};
        EXPECT_THAT(sweepError(inputs, w, 1), HasSubstr("weight nan of input 0"));
    }
    {
        const double w[] = {1.0, std::numeric_limits<double>::infinity(), 1.0};
        EXPECT_THAT(sweepError(inputs, w, 1), HasSubstr("of input 1"));
    }
    {
        const double w[] = {0.0, 0.0, 0.0};
        EXPECT_THAT(sweepError(inputs, w, 1), HasSubstr("weights sum to 0"));
    }
    {
        const double w[] = {1.0, 1.0};
        EXPECT_THAT(sweepError(inputs, w, 1), HasSubstr("3 inputs but 2 weights"));
    }
}

// The checks run in one pass without a branch an input; the error still
// names the first input at fault, its weight before itself, as checking
// them one after the other would: on functions and on prepared inputs.
TEST(Sweep, TheFirstFaultIsNamed) {
    const VisibilityFunction inputs[] = {simple(1), simple(1), simple(3), simple(1)};
    const double laterBadWeight[] = {1.0, 1.0, 1.0, -2.0};
    const double earlierBadWeight[] = {1.0, std::numeric_limits<double>::infinity(), 1.0, 1.0};
    EXPECT_THAT(sweepError(inputs, laterBadWeight, 1), HasSubstr("input 2 has 3 channels"));
    EXPECT_THAT(sweepError(inputs, earlierBadWeight, 1), HasSubstr("weight inf of input 1"));
    std::vector<dsm::SweepInput> prepared(std::size(inputs));
    std::vector<const dsm::SweepInput*> pointers;
    for (std::size_t k = 0; k < prepared.size(); ++k) {
        prepared[k].assign(inputs[k]);
        pointers.push_back(&prepared[k]);
    }
    dsm::Sweeper sweeper;
    dsm::SweptVertices out(1);
    for (const auto& [weights, expected] :
         {std::pair{laterBadWeight, "input 2 has 3 channels"}, std::pair{earlierBadWeight, "weight inf of input 1"}}) {
        try {
            sweeper.sweep(std::span<const dsm::SweepInput* const>(pointers), std::span<const double>(weights, 4), 1,
                          out);
            ADD_FAILURE() << "no error";
        } catch (const dsm::Error& e) {
            EXPECT_THAT(e.what(), HasSubstr(expected));
        }
    }
}

TEST(Sweep, RejectsLayeredInputs) {
    VisibilityFunction layered = simple();
    layered.beginLayer();
    layered.append(2.0f, 0.5f);
    const VisibilityFunction inputs[] = {simple(), layered};
    const double w[] = {1.0, 1.0};
    EXPECT_THAT(sweepError(inputs, w, 1), HasSubstr("input 1 has 2 layers"));
}

TEST(Sweep, ZeroWeightInputsKeepTheirDepthsAndCounts) {
    VisibilityFunction a(1, true), b(1, true);
    a.append(1.0f, 0.5f, 1);
    b.append(2.0f, 0.0f, 3);
    const VisibilityFunction inputs[] = {a, b};
    const double w[] = {1.0, 0.0};
    const RecordingSink out = runSweep(inputs, w, 1);
    expectMatchesOracle(inputs, w, 1, out);
    // The average ignores b entirely.
    ASSERT_FALSE(out.vertices.empty());
    EXPECT_NEAR(out.vertices.back().v[0], 0.5, 1e-12);
}

TEST(Sweep, ResultFeedsTheCompressorWithinTolerance) {
    // sweep -> compressor with double values: bound max(eps, 2^-25) against
    // the exact average.
    std::mt19937_64 rng(33);
    for (int channels : {1, 3}) {
        std::vector<VisibilityFunction> inputs;
        std::vector<double> weights;
        for (int k = 0; k < 32; ++k) {
            inputs.push_back(dsm::test::randomMonotone(rng, 12, channels, true));
            weights.push_back(0.5 + static_cast<double>(k % 5));
        }
        for (double eps : {0.0, dsm::autoTolerance(32), 0.1}) {
            dsm::CompressorOptions options;
            options.tolerance = eps;
            options.channels = channels;
            options.keepCounts = true;
            dsm::Compressor compressor(options);
            ASSERT_FALSE(dsm::sweep(inputs, weights, channels, compressor).has_value());
            const VisibilityFunction out = compressor.finish();
            const auto exact = dsm::test::naiveAverage(inputs, weights, channels);
            EXPECT_LE(dsm::test::maxErrorExact(exact, out, channels), std::max(eps, 0x1p-25) + kSweepTolerance)
                << "eps " << eps << " channels " << channels;
            EXPECT_EQ(out.totalCount(), inputCount(inputs));
            EXPECT_NO_THROW(out.validate());
        }
    }
}

}  // namespace

TEST(Sweep, ReusedSweeperMatchesFreshSweeps) {
    // One sweeper over pixels of changing size and channels, over functions,
    // views of them and inputs prepared ahead (reused from pixel to pixel),
    // gives what sweep() gives each pixel alone (the same doubles, not just
    // close ones).
    std::mt19937_64 rng(41);
    dsm::Sweeper sweeper;
    std::vector<dsm::SweepInput> prepared;
    dsm::test::RandomShape shape;
    for (int trial = 0; trial < 30; ++trial) {
        const int channels = trial % 2 ? 3 : 1;
        shape.depthGrid = trial % 3 == 0 ? 0.25f : 0.0f;
        std::vector<VisibilityFunction> inputs;
        std::vector<double> weights;
        const std::size_t n = 1 + rng() % 150;
        for (std::size_t k = 0; k < n; ++k) {
            inputs.push_back(dsm::test::randomMonotone(rng, rng() % 20, channels, trial % 4 != 0, shape));
            weights.push_back(k % 5 == 3 ? 0.0 : 0.1 + static_cast<double>(rng() % 7));
        }
        weights[0] = 1.0;
        const RecordingSink fresh = runSweep(inputs, weights, channels);
        RecordingSink fromFunctions, fromViews, fromPrepared;
        fromFunctions.channels = fromViews.channels = fromPrepared.channels = channels;
        EXPECT_FALSE(sweeper.sweep(std::span<const VisibilityFunction>(inputs), weights, channels, fromFunctions));
        std::vector<dsm::VisibilityView> views(inputs.begin(), inputs.end());
        EXPECT_FALSE(sweeper.sweep(std::span<const dsm::VisibilityView>(views), weights, channels, fromViews));
        if (prepared.size() < n) prepared.resize(n);
        std::vector<const dsm::SweepInput*> preparedInputs;
        for (std::size_t k = 0; k < n; ++k) {
            prepared[k].assign(inputs[k]);
            EXPECT_EQ(prepared[k].vertexCount(), inputs[k].size());
            preparedInputs.push_back(&prepared[k]);
        }
        EXPECT_FALSE(sweeper.sweep(std::span<const dsm::SweepInput* const>(preparedInputs), weights, channels,
                                   fromPrepared));
        for (const RecordingSink* out : {&fromFunctions, &fromViews, &fromPrepared}) {
            ASSERT_EQ(out->vertices.size(), fresh.vertices.size()) << "trial " << trial;
            for (std::size_t i = 0; i < fresh.vertices.size(); ++i) {
                EXPECT_EQ(out->vertices[i].z, fresh.vertices[i].z);
                EXPECT_EQ(out->vertices[i].v, fresh.vertices[i].v);
                EXPECT_EQ(out->vertices[i].count, fresh.vertices[i].count);
            }
        }
        if (HasFailure()) return;
    }
}

// A SweptVertices holds what a sink is given, bit for bit, whether the
// inputs are steps alone (written into its arrays directly, with room made
// ahead) or some slope; after clear() or, without it, after the vertices
// already held, which stay as they were.
TEST(Sweep, SweptVerticesHoldWhatASinkIsGiven) {
    std::mt19937_64 rng(1204);
    std::uniform_real_distribution<float> depth(0.0f, 8.0f), unit(0.0f, 1.0f);
    dsm::Sweeper sweeper;
    dsm::SweptVertices held[2] = {dsm::SweptVertices(1), dsm::SweptVertices(3)};
    std::vector<dsm::test::RecordingSink::Vertex> expected[2];
    for (int trial = 0; trial < 60; ++trial) {
        const int channels = trial % 2 ? 3 : 1;
        dsm::SweptVertices& out = held[trial % 2];
        std::vector<dsm::test::RecordingSink::Vertex>& kept = expected[trial % 2];
        std::vector<VisibilityFunction> inputs;
        std::vector<double> weights;
        const std::size_t n = 1 + rng() % (trial % 5 == 0 ? 400 : 60);
        for (std::size_t k = 0; k < n; ++k) {
            std::vector<dsm::SurfaceHit> hits(rng() % 6);
            for (dsm::SurfaceHit& h : hits) {
                h.z = trial % 3 == 0 ? std::round(4.0f * depth(rng)) / 4.0f : depth(rng);
                for (float& o : h.opacity) o = unit(rng) < 0.1f ? 1.0f : unit(rng);
            }
            inputs.push_back(dsm::transmittance(dsm::SampleRay{hits, {}}, channels, true));
            weights.push_back(k % 7 == 3 ? 0.0 : 0.1 + static_cast<double>(rng() % 5));
        }
        weights[0] = 1.0;
        if (trial % 4 == 1) {  // one input that slopes: the heap's path
            VisibilityFunction sloped(channels, true);
            const float top[3] = {1.0f, 1.0f, 1.0f}, bottom[3] = {0.3f, 0.2f, 0.4f};
            sloped.append(depth(rng), top, 1);
            sloped.append(8.0f + depth(rng), bottom, 1);
            inputs.push_back(sloped);
            weights.push_back(1.5);
        }
        std::vector<dsm::SweepInput> prepared(inputs.size());
        std::vector<const dsm::SweepInput*> pointers;
        for (std::size_t k = 0; k < inputs.size(); ++k) {
            prepared[k].assign(inputs[k]);
            pointers.push_back(&prepared[k]);
        }
        const RecordingSink sink = runSweep(inputs, weights, channels);
        if (trial % 3 != 2) {
            out.clear();
            kept.clear();
        }
        EXPECT_FALSE(sweeper.sweep(std::span<const dsm::SweepInput* const>(pointers), weights, channels, out));
        kept.insert(kept.end(), sink.vertices.begin(), sink.vertices.end());
        ASSERT_EQ(out.size(), kept.size()) << "trial " << trial;
        for (std::size_t i = 0; i < kept.size(); ++i) {
            ASSERT_EQ(std::bit_cast<std::uint32_t>(out.depths()[i]), std::bit_cast<std::uint32_t>(kept[i].z))
                << "trial " << trial << " vertex " << i;
            ASSERT_EQ(out.counts()[i], kept[i].count) << "trial " << trial << " vertex " << i;
            for (std::size_t c = 0; c < static_cast<std::size_t>(channels); ++c)
                ASSERT_EQ(std::bit_cast<std::uint64_t>(out.values()[i * static_cast<std::size_t>(channels) + c]),
                          std::bit_cast<std::uint64_t>(kept[i].v[c]))
                    << "trial " << trial << " vertex " << i << " channel " << c;
        }
    }
}

// Small inputs keep their depths inside the SweepInput, larger ones on the
// heap: inputs moved after assign() (a vector that grows, a move-assignment
// over an input of the other kind) still sweep as the functions do.
TEST(Sweep, PreparedInputsSurviveMoves) {
    std::mt19937_64 rng(43);
    for (const int channels : {1, 3}) {
        std::vector<VisibilityFunction> inputs;
        std::vector<double> weights;
        for (std::size_t k = 0; k < 40; ++k) {
            // 0 to 9 vertices: both sides of SweepInput::kInlineDepths.
            inputs.push_back(dsm::test::randomMonotone(rng, k % 10, channels, true));
            weights.push_back(0.5 + static_cast<double>(k % 3));
        }
        const RecordingSink fresh = runSweep(inputs, weights, channels);
        std::vector<dsm::SweepInput> prepared(1);
        for (std::size_t k = 0; k < inputs.size(); ++k) {
            if (k > 0) prepared.emplace_back();  // grows, moving those assigned so far
            prepared[k].assign(inputs[k]);
        }
        // Each swapped with its mirror by move-assignments, then swapped back.
        const std::size_t n = prepared.size();
        for (int pass = 0; pass < 2; ++pass)
            for (std::size_t k = 0; k < n / 2; ++k) {
                dsm::SweepInput held = std::move(prepared[k]);
                prepared[k] = std::move(prepared[n - 1 - k]);
                prepared[n - 1 - k] = std::move(held);
            }
        std::vector<dsm::SweepInput> moved;
        for (std::size_t k = n; k-- > 0;) moved.push_back(std::move(prepared[k]));
        std::reverse(moved.begin(), moved.end());
        std::vector<const dsm::SweepInput*> pointers;
        for (const dsm::SweepInput& p : moved) pointers.push_back(&p);
        RecordingSink out;
        out.channels = channels;
        dsm::Sweeper sweeper;
        EXPECT_FALSE(sweeper.sweep(std::span<const dsm::SweepInput* const>(pointers), weights, channels, out));
        ASSERT_EQ(out.vertices.size(), fresh.vertices.size());
        for (std::size_t i = 0; i < fresh.vertices.size(); ++i) {
            EXPECT_EQ(out.vertices[i].z, fresh.vertices[i].z);
            EXPECT_EQ(out.vertices[i].v, fresh.vertices[i].v);
            EXPECT_EQ(out.vertices[i].count, fresh.vertices[i].count);
        }
    }
}

TEST(Sweep, PreparedInputsAreChecked) {
    VisibilityFunction layered = simple();
    layered.beginLayer();
    layered.append(2.0f, 0.5f);
    dsm::SweepInput input;
    try {
        input.assign(layered);
        ADD_FAILURE() << "no error";
    } catch (const dsm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("2 layers"));
    }
    VisibilityFunction undefinedDepth(1);
    undefinedDepth.append(std::numeric_limits<float>::quiet_NaN(), 0.5f);
    try {
        input.assign(undefinedDepth);
        ADD_FAILURE() << "no error";
    } catch (const dsm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("depth NaN at vertex 0"));
    }
    // Channels must match the sweep's, as for functions.
    dsm::SweepInput mono, rgb;
    mono.assign(simple(1));
    rgb.assign(simple(3));
    const dsm::SweepInput* inputs[] = {&mono, &rgb};
    const double w[] = {1.0, 1.0};
    RecordingSink sink;
    sink.channels = 1;
    dsm::Sweeper sweeper;
    try {
        sweeper.sweep(std::span<const dsm::SweepInput* const>(inputs), w, 1, sink);
        ADD_FAILURE() << "no error";
    } catch (const dsm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("input 1 has 3 channels"));
    }
}
