// VisibilityFunction and VisibilityCursor: evaluation, layers, validation,
// monochrome conversion (LV §3.1, §3.4; Xie et al. §5.1).
#include <dsm/dsm.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "oracle.h"

namespace {

using dsm::VisibilityCursor;
using dsm::VisibilityFunction;
using ::testing::HasSubstr;

constexpr double kTight = 1e-12;

VisibilityFunction mono(std::initializer_list<std::pair<float, float>> vertices) {
    VisibilityFunction f;
    for (const auto& [z, v] : vertices) f.append(z, v);
    return f;
}

// A step at 1 (to 0.5), flat to 2, a step to 0.2 at 2, a slope to 0 at 4.
VisibilityFunction stepsAndSlope() {
    return mono({{1.0f, 1.0f}, {1.0f, 0.5f}, {2.0f, 0.5f}, {2.0f, 0.2f}, {4.0f, 0.0f}});
}

std::string errorOf(const VisibilityFunction& f) {
    try {
        f.validate();
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "no error";
}

// Depths to query: every vertex depth, its float neighbours, midpoints, and
// points before and after the function.
std::vector<double> queryDepths(const VisibilityFunction& f, std::mt19937_64& rng, std::size_t randomCount) {
    std::vector<double> q;
    for (float z : f.depths()) {
        q.push_back(z);
        q.push_back(std::nextafter(z, -1.0f));
        q.push_back(std::nextafter(z, std::numeric_limits<float>::infinity()));
    }
    for (std::size_t i = 0; i + 1 < f.size(); ++i) q.push_back(0.5 * (f.z(i) + f.z(i + 1)));
    const double hi = f.empty() ? 1.0 : static_cast<double>(f.z(f.size() - 1)) + 1.0;
    std::uniform_real_distribution<double> d(-0.5, hi);
    for (std::size_t i = 0; i < randomCount; ++i) q.push_back(d(rng));
    q.push_back(-1.0);
    q.push_back(hi * 10.0);
    return q;
}

TEST(VisibilityFunction, EmptyFunctionIsOneEverywhere) {
    const VisibilityFunction f(3);
    for (double z : {0.0, 1.0, 1e30}) {
        for (int c = 0; c < 3; ++c) EXPECT_EQ(f.evaluate(z, c), 1.0);
    }
    VisibilityCursor cursor(f);
    EXPECT_EQ(cursor.evaluate(5.0), 1.0);
    EXPECT_EQ(f.layerCount(), 1u);
    EXPECT_TRUE(f.empty());
}

TEST(VisibilityFunction, ResetEmptiesAndSetsChannelsAndCounts) {
    VisibilityFunction f(3, true);
    const float v[3] = {0.5f, 0.25f, 0.125f};
    f.append(1.0f, v, 4);
    f.beginLayer();
    f.append(2.0f, v, 1);
    f.reset(1, false);
    EXPECT_EQ(f, VisibilityFunction(1, false));
    f.append(3.0f, 0.5f, 7);
    EXPECT_EQ(f.count(0), 0u);
    EXPECT_EQ(f.layerCount(), 1u);
    f.reset(3, true);
    EXPECT_EQ(f, VisibilityFunction(3, true));
    EXPECT_THROW(f.reset(2, true), dsm::Error);
}

TEST(VisibilityFunction, OneBeforeFirstVertex) {
    const VisibilityFunction f = mono({{2.0f, 0.8f}, {3.0f, 0.4f}});
    EXPECT_EQ(f.evaluate(0.0), 1.0);
    EXPECT_EQ(f.evaluate(1.999), 1.0);
    EXPECT_EQ(f.evaluate(std::nextafter(2.0, 0.0)), 1.0);
    // At the first vertex the function has stepped to its value.
    EXPECT_NEAR(f.evaluate(2.0), 0.8, 1e-7);
}

TEST(VisibilityFunction, LastValueAfterLastVertex) {
    const VisibilityFunction f = mono({{2.0f, 0.8f}, {3.0f, 0.4f}});
    EXPECT_NEAR(f.evaluate(3.0), 0.4, 1e-7);
    EXPECT_NEAR(f.evaluate(3.5), 0.4, 1e-7);
    EXPECT_NEAR(f.evaluate(1e30), 0.4, 1e-7);
}

TEST(VisibilityFunction, LinearBetweenVertices) {
    const VisibilityFunction f = mono({{2.0f, 1.0f}, {4.0f, 0.5f}});
    EXPECT_NEAR(f.evaluate(3.0), 0.75, kTight);
    EXPECT_NEAR(f.evaluate(2.5), 0.875, kTight);
    EXPECT_NEAR(f.evaluate(3.5), 0.625, kTight);
}

TEST(VisibilityFunction, RightContinuousAtSteps) {
    const VisibilityFunction f = stepsAndSlope();
    EXPECT_EQ(f.evaluate(0.5), 1.0);
    EXPECT_NEAR(f.evaluate(1.0), 0.5, kTight);  // value after the step
    EXPECT_NEAR(f.evaluate(1.5), 0.5, kTight);  // flat between the steps
    EXPECT_NEAR(f.evaluate(std::nextafter(2.0, 0.0)), 0.5, kTight);
    EXPECT_NEAR(f.evaluate(2.0), 0.2, 1e-7);
    EXPECT_NEAR(f.evaluate(3.0), 0.1, 1e-7);
    EXPECT_EQ(f.evaluate(4.0), 0.0);
    EXPECT_EQ(f.evaluate(100.0), 0.0);
}

TEST(VisibilityFunction, SeveralVerticesAtOneDepthTakeTheLast) {
    const VisibilityFunction f = mono({{1.0f, 1.0f}, {1.0f, 0.7f}, {1.0f, 0.3f}, {2.0f, 0.1f}});
    EXPECT_NEAR(f.evaluate(1.0), 0.3, 1e-7);
    EXPECT_NEAR(f.evaluate(1.5), 0.2, 1e-7);
    EXPECT_EQ(f.evaluate(0.99), 1.0);
}

TEST(VisibilityFunction, EvaluateMatchesOracleOnRandomFunctions) {
    std::mt19937_64 rng(11);
    for (int channels : {1, 3}) {
        for (int trial = 0; trial < 20; ++trial) {
            const VisibilityFunction f = dsm::test::randomMonotone(rng, 1 + trial * 7, channels, false);
            for (double z : queryDepths(f, rng, 50)) {
                double all[dsm::kMaxChannels];
                f.evaluate(z, all);
                for (int c = 0; c < channels; ++c) {
                    const double expected = dsm::test::valueAt(f, z, c);
                    ASSERT_NEAR(f.evaluate(z, c), expected, kTight) << "z = " << z << " channel " << c;
                    ASSERT_NEAR(all[c], expected, kTight) << "z = " << z << " channel " << c;
                }
            }
        }
    }
}

TEST(VisibilityCursor, ForwardQueriesMatchEvaluate) {
    std::mt19937_64 rng(12);
    const VisibilityFunction f = dsm::test::randomMonotone(rng, 300, 3, false);
    std::vector<double> q = queryDepths(f, rng, 500);
    std::sort(q.begin(), q.end());
    VisibilityCursor cursor(f);
    for (double z : q) {
        double all[dsm::kMaxChannels];
        cursor.evaluate(z, all);
        for (int c = 0; c < 3; ++c) {
            ASSERT_NEAR(all[c], f.evaluate(z, c), kTight) << "z = " << z;
            ASSERT_NEAR(all[c], dsm::test::valueAt(f, z, c), kTight) << "z = " << z;
        }
    }
}

TEST(VisibilityCursor, BackwardQueriesMatchEvaluate) {
    std::mt19937_64 rng(13);
    const VisibilityFunction f = dsm::test::randomMonotone(rng, 300, 1, false);
    std::vector<double> q = queryDepths(f, rng, 500);
    std::sort(q.rbegin(), q.rend());
    VisibilityCursor cursor(f);
    for (double z : q) ASSERT_NEAR(cursor.evaluate(z), dsm::test::valueAt(f, z), kTight) << "z = " << z;
}

TEST(VisibilityCursor, RandomQueriesMatchEvaluate) {
    std::mt19937_64 rng(14);
    for (int trial = 0; trial < 10; ++trial) {
        const VisibilityFunction f = dsm::test::randomMonotone(rng, 5 + 40 * trial, 3, false);
        std::vector<double> q = queryDepths(f, rng, 300);
        std::shuffle(q.begin(), q.end(), rng);
        VisibilityCursor cursor(f);
        for (double z : q) {
            const int c = static_cast<int>(rng() % 3);
            ASSERT_NEAR(cursor.evaluate(z, c), f.evaluate(z, c), kTight) << "z = " << z;
        }
    }
}

TEST(VisibilityCursor, CoherentForwardQueriesTakeConstantStepsOnAverage) {
    VisibilityFunction f;
    const std::size_t n = 2000;
    for (std::size_t i = 0; i < n; ++i) f.append(static_cast<float>(i), 1.0f - static_cast<float>(i) / n);
    VisibilityCursor cursor(f);
    const std::size_t queries = 20000;
    for (std::size_t i = 0; i < queries; ++i) {
        const double z = static_cast<double>(i) * static_cast<double>(n) / queries;
        ASSERT_NEAR(cursor.evaluate(z), f.evaluate(z), kTight);
    }
    // A forward run steps over each vertex about once: O(1) per query.
    EXPECT_LE(cursor.stepsTaken(), n + 2);
    EXPECT_GT(cursor.stepsTaken(), 0u);

    // Nearby lookups after a jump stay cheap too.
    VisibilityCursor back(f);
    back.evaluate(1500.0);
    const std::uint64_t afterJump = back.stepsTaken();
    for (int i = 0; i < 100; ++i) back.evaluate(1500.0 - 0.5 * i);
    EXPECT_LE(back.stepsTaken() - afterJump, 60u);
}

TEST(VisibilityFunction, LayeredEvaluateIsZeroFromEndOfLayerZero) {
    VisibilityFunction f;
    f.append(1.0f, 0.6f);
    f.append(2.0f, 0.01f);
    f.beginLayer();
    f.append(3.0f, 0.5f);
    f.append(4.0f, 0.2f);
    ASSERT_NO_THROW(f.validate());
    ASSERT_EQ(f.layerCount(), 2u);
    EXPECT_EQ(f.layerBegin(0), 0u);
    EXPECT_EQ(f.layerEnd(0), 2u);
    EXPECT_EQ(f.layerBegin(1), 2u);
    EXPECT_EQ(f.layerEnd(1), 4u);

    EXPECT_EQ(f.evaluate(0.5), 1.0);
    EXPECT_NEAR(f.evaluate(1.5), 0.305, 1e-7);
    EXPECT_EQ(f.evaluate(2.0), 0.0);
    EXPECT_EQ(f.evaluate(2.5), 0.0);
    EXPECT_EQ(f.evaluate(3.5), 0.0);
    EXPECT_EQ(f.evaluate(1e9), 0.0);

    VisibilityCursor cursor(f);
    for (double z : {0.5, 1.5, 1.99, 2.0, 3.5, 10.0, 1.2})
        EXPECT_NEAR(cursor.evaluate(z), f.evaluate(z), kTight) << "z = " << z;
    EXPECT_EQ(cursor.evaluate(2.0), 0.0);

    EXPECT_NEAR(f.evaluateLayer(0, 1.5), 0.305, 1e-7);
    EXPECT_NEAR(f.evaluateLayer(0, 10.0), 0.01, 1e-7);
    EXPECT_EQ(f.evaluateLayer(1, 2.5), 1.0);
    EXPECT_NEAR(f.evaluateLayer(1, 3.0), 0.5, 1e-7);
    EXPECT_NEAR(f.evaluateLayer(1, 3.5), 0.35, 1e-7);
    EXPECT_NEAR(f.evaluateLayer(1, 10.0), 0.2, 1e-7);
}

TEST(VisibilityFunction, SingleLayerKeepsLastValueBeyondEnd) {
    const VisibilityFunction f = mono({{1.0f, 0.6f}, {2.0f, 0.01f}});
    EXPECT_NEAR(f.evaluate(2.0), 0.01, 1e-7);
    EXPECT_NEAR(f.evaluate(50.0), 0.01, 1e-7);
    EXPECT_NEAR(f.evaluateLayer(0, 50.0), 0.01, 1e-7);
}

TEST(VisibilityFunction, EvaluateLayerMatchesOracle) {
    std::mt19937_64 rng(15);
    VisibilityFunction f(3);
    // Three layers of random functions at increasing depths.
    float base = 0.0f;
    for (int layer = 0; layer < 3; ++layer) {
        if (layer > 0) f.beginLayer();
        const VisibilityFunction part = dsm::test::randomMonotone(rng, 20, 3, false);
        for (std::size_t i = 0; i < part.size(); ++i) f.append(base + part.z(i), part.values(i));
        base += part.z(part.size() - 1) + 1.0f;
    }
    ASSERT_NO_THROW(f.validate());
    for (std::size_t layer = 0; layer < 3; ++layer) {
        for (double z : queryDepths(f, rng, 100)) {
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(f.evaluateLayer(layer, z, c), dsm::test::valueAt(f, z, c, layer), kTight)
                    << "layer " << layer << " z " << z;
        }
    }
}

TEST(VisibilityFunction, ValidateAcceptsValidFunctions) {
    std::mt19937_64 rng(16);
    for (int i = 0; i < 20; ++i) EXPECT_NO_THROW(dsm::test::randomMonotone(rng, 50, 3, true).validate());
    EXPECT_NO_THROW(VisibilityFunction().validate());
    EXPECT_NO_THROW(stepsAndSlope().validate());
}

TEST(VisibilityFunction, ValidateRejectsNonFiniteDepth) {
    VisibilityFunction f = mono({{1.0f, 0.9f}, {2.0f, 0.8f}});
    f.append(std::numeric_limits<float>::quiet_NaN(), 0.5f);
    EXPECT_THAT(errorOf(f), HasSubstr("vertex 2: depth nan"));
    VisibilityFunction g = mono({{1.0f, 0.9f}});
    g.append(std::numeric_limits<float>::infinity(), 0.5f);
    EXPECT_THAT(errorOf(g), HasSubstr("vertex 1: depth inf"));
}

TEST(VisibilityFunction, ValidateRejectsNegativeDepth) {
    const VisibilityFunction f = mono({{-0.5f, 0.9f}, {2.0f, 0.8f}});
    EXPECT_THAT(errorOf(f), HasSubstr("vertex 0: depth -0.5"));
}

TEST(VisibilityFunction, ValidateRejectsDecreasingDepth) {
    const VisibilityFunction f = mono({{1.0f, 0.9f}, {3.0f, 0.8f}, {2.0f, 0.7f}});
    EXPECT_THAT(errorOf(f), HasSubstr("vertex 2: depth 2"));
}

TEST(VisibilityFunction, ValidateRejectsValueOutsideUnitInterval) {
    EXPECT_THAT(errorOf(mono({{1.0f, 1.5f}})), HasSubstr("vertex 0 channel 0: visibility 1.5"));
    EXPECT_THAT(errorOf(mono({{1.0f, 0.5f}, {2.0f, -0.25f}})), HasSubstr("vertex 1 channel 0: visibility -0.25"));
    EXPECT_THAT(errorOf(mono({{1.0f, 0.5f}, {2.0f, std::numeric_limits<float>::quiet_NaN()}})),
                HasSubstr("vertex 1 channel 0: visibility nan"));
}

TEST(VisibilityFunction, ValidateRejectsIncreasingValue) {
    EXPECT_THAT(errorOf(mono({{1.0f, 0.5f}, {2.0f, 0.375f}, {3.0f, 0.4375f}})),
                HasSubstr("vertex 2 channel 0: visibility 0.4375"));
    VisibilityFunction rgb(3);
    const float a[3] = {0.9f, 0.8f, 0.7f}, b[3] = {0.9f, 0.8f, 0.75f};
    rgb.append(1.0f, a);
    rgb.append(2.0f, a);
    rgb.append(3.0f, a);
    rgb.append(4.0f, b);
    EXPECT_THAT(errorOf(rgb), HasSubstr("vertex 3 channel 2: visibility 0.75"));
}

TEST(VisibilityFunction, ValidateRejectsBadLayerStarts) {
    VisibilityFunction emptyLayer = mono({{1.0f, 0.5f}});
    emptyLayer.beginLayer();
    emptyLayer.beginLayer();
    emptyLayer.append(2.0f, 0.5f);
    EXPECT_THAT(errorOf(emptyLayer), HasSubstr("layer 2 starts at vertex 1"));

    VisibilityFunction trailing = mono({{1.0f, 0.5f}, {2.0f, 0.1f}});
    trailing.beginLayer();
    EXPECT_THAT(errorOf(trailing), HasSubstr("layer 1 starts at vertex 2"));

    VisibilityFunction leading;
    leading.beginLayer();
    leading.append(1.0f, 0.5f);
    EXPECT_THAT(errorOf(leading), HasSubstr("layer 1 starts at vertex 0"));
}

TEST(VisibilityFunction, ValidateAllowsValueToRiseAtLayerStartOnly) {
    VisibilityFunction f = mono({{1.0f, 0.5f}, {2.0f, 0.0f}});
    f.beginLayer();
    f.append(3.0f, 0.9f);
    f.append(4.0f, 0.3f);
    EXPECT_NO_THROW(f.validate());
    f.append(5.0f, 0.4f);
    EXPECT_THAT(errorOf(f), HasSubstr("vertex 4 channel 0"));
}

TEST(VisibilityFunction, CountsAndTotals) {
    VisibilityFunction f(1, true);
    f.append(1.0f, 0.5f, 3);
    f.append(2.0f, 0.4f, 4);
    f.addToLastCount(5);
    EXPECT_EQ(f.count(0), 3u);
    EXPECT_EQ(f.count(1), 9u);
    EXPECT_EQ(f.totalCount(), 12u);
    VisibilityFunction g(1, false);
    g.append(1.0f, 0.5f, 3);
    EXPECT_EQ(g.count(0), 0u);
    EXPECT_EQ(g.totalCount(), 0u);
}

TEST(VisibilityFunction, RejectsBadChannelCount) {
    EXPECT_THROW(VisibilityFunction(2), dsm::Error);
    EXPECT_THROW(VisibilityFunction(0), dsm::Error);
    EXPECT_THROW(VisibilityFunction(4), dsm::Error);
}

TEST(VisibilityFunction, MonochromeDetection) {
    EXPECT_TRUE(stepsAndSlope().isMonochrome());
    EXPECT_TRUE(VisibilityFunction(3).isMonochrome());
    VisibilityFunction grey(3);
    const float g1[3] = {0.7f, 0.7f, 0.7f}, g2[3] = {0.2f, 0.2f, 0.2f};
    grey.append(1.0f, g1);
    grey.append(2.0f, g2);
    EXPECT_TRUE(grey.isMonochrome());
    const float c[3] = {0.2f, 0.2f, std::nextafter(0.2f, 0.0f)};
    grey.append(3.0f, c);
    EXPECT_FALSE(grey.isMonochrome());
}

TEST(VisibilityFunction, ToMonochromeKeepsDepthsChannelZeroCountsAndLayers) {
    VisibilityFunction f(3, true);
    const float a[3] = {0.8f, 0.8f, 0.8f}, b[3] = {0.3f, 0.3f, 0.3f}, c[3] = {0.6f, 0.6f, 0.6f};
    f.append(1.0f, a, 2);
    f.append(2.0f, b, 5);
    f.beginLayer();
    f.append(3.0f, c, 7);
    const VisibilityFunction m = f.toMonochrome();
    EXPECT_EQ(m.channels(), 1);
    ASSERT_TRUE(m.hasCounts());
    ASSERT_EQ(m.size(), 3u);
    ASSERT_EQ(m.layerCount(), 2u);
    EXPECT_EQ(m.layerBegin(1), 2u);
    for (std::size_t i = 0; i < 3; ++i) {
        EXPECT_EQ(m.z(i), f.z(i));
        EXPECT_EQ(m.value(i), f.value(i, 0));
        EXPECT_EQ(m.count(i), f.count(i));
    }
    EXPECT_NO_THROW(m.validate());
    for (double z : {0.5, 1.0, 1.5, 2.5, 3.0, 4.0}) EXPECT_EQ(m.evaluate(z), f.evaluate(z, 2));
}

TEST(VisibilityFunction, CollectingSinkStoresVerticesRounded) {
    VisibilityFunction out(3, true);
    dsm::CollectingSink sink(out);
    const double v[3] = {0.1, 0.2, 0.3};
    EXPECT_TRUE(sink.push(1.5f, v, 4));
    ASSERT_EQ(out.size(), 1u);
    EXPECT_EQ(out.z(0), 1.5f);
    EXPECT_EQ(out.value(0, 0), 0.1f);
    EXPECT_EQ(out.value(0, 2), 0.3f);
    EXPECT_EQ(out.count(0), 4u);
}

}  // namespace
