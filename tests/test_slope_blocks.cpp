// The compressor's blocks of slopes (slope_blocks.h, internal): whole blocks
// of eight vertices leave exactly the window, count and number of vertices
// that taking the vertices one by one with vertexSlopes() gives up to the
// last whole block before the segment ends, bit for bit, on the baseline
// instruction set and on AVX2 (where the processor has it), with one band
// for the run and with a band for each vertex, for one channel and for RGB.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "slope_blocks.h"

namespace {

using namespace dsm::detail;

struct Walk {
    std::size_t taken;
    double lo, hi;
    std::uint64_t count;
};

// Vertex by vertex: the window after each vertex, and where it stops being
// feasible; then cut back to the last whole block of eight.
template <typename T>
Walk walkInBlocks(const std::vector<float>& z, const std::vector<T>& v, const std::vector<double>* bands,
                  const std::vector<std::uint32_t>& counts, const SlopeFrame& frame, double lo, double hi) {
    std::vector<Walk> after{{0, lo, hi, 0}};
    for (std::size_t i = 0; i < z.size(); ++i) {
        const VertexSlopes s = vertexSlopes(z[i], v[i], bands ? withBand(frame, (*bands)[i]) : frame);
        const double nextHi = std::min(hi, s.top), nextLo = std::max(lo, s.bottom);
        if (!feasibleWindow(nextLo, nextHi, frame.originV, s.dz)) break;
        hi = nextHi;
        lo = nextLo;
        after.push_back({i + 1, lo, hi, after.back().count + counts[i]});
    }
    return after[(after.size() - 1) / 8 * 8];
}

template <typename T>
void checkVariant(std::size_t (*blocks)(const float*, const T*, const double*, const std::uint32_t*, std::size_t,
                                        const SlopeFrame&, double&, double&, std::uint64_t&),
                  const char* name) {
    std::mt19937_64 rng(29);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    int ended = 0, whole = 0;
    for (int trial = 0; trial < 3000; ++trial) {
        const std::size_t n = rng() % 90;
        const float originZ = static_cast<float>(0.5 + 4.0 * unit(rng));
        const double originV = trial % 5 == 0 ? 1.0 : unit(rng);
        const double band = trial % 7 == 0 ? 1e-9 : 0.2 * unit(rng) + 1e-6;
        const SlopeFrame frame = slopeFrame(originZ, originV, band);
        // A falling input, in steps (equal depths) and ramps, sometimes
        // flat for long stretches so that segments run past many blocks.
        std::vector<float> z(n);
        std::vector<T> v(n);
        std::vector<std::uint32_t> counts(n);
        std::vector<double> bands(n);  // each vertex's own (grey RGB input)
        // From the open segment's first vertex (at originZ + 1e-3) on: depths never fall,
        // and each differs from the origin's (the blocks' preconditions).
        double depth = originZ + 1e-3 * (1.0 + unit(rng)), value = originV;
        const double fall = trial % 3 == 0 ? 0.002 : 0.05;
        for (std::size_t i = 0; i < n; ++i) {
            if (rng() % 3 != 0) depth += 0.05 * unit(rng);
            value = std::max(0.0, value - fall * unit(rng));
            z[i] = static_cast<float>(depth);
            v[i] = static_cast<T>(value);
            counts[i] = static_cast<std::uint32_t>(rng() % 5 == 0 ? 0xffffffffu : rng() % 1000);
            bands[i] = band * (0.5 + 0.5 * unit(rng));
        }
        // The open segment's window, as after its first vertex.
        const VertexSlopes first = vertexSlopes(static_cast<float>(originZ + 1e-3), originV, frame);
        const double lo0 = first.bottom, hi0 = first.top;
        for (bool withCounts : {false, true})
            for (bool ownBands : {false, true}) {
                const Walk expected = walkInBlocks(z, v, ownBands ? &bands : nullptr, counts, frame, lo0, hi0);
                double lo = lo0, hi = hi0;
                std::uint64_t count = 5;
                const std::size_t taken = blocks(z.data(), v.data(), ownBands ? bands.data() : nullptr,
                                                 withCounts ? counts.data() : nullptr, n, frame, lo, hi, count);
                ASSERT_EQ(taken, expected.taken) << name << " trial " << trial;
                ASSERT_EQ(lo, expected.lo) << name << " trial " << trial;
                ASSERT_EQ(hi, expected.hi) << name << " trial " << trial;
                ASSERT_EQ(count, 5 + (withCounts ? expected.count : 0)) << name << " trial " << trial;
                if (withCounts && !ownBands) (taken + 8 <= n ? ended : whole) += 1;
            }
    }
    // Both outcomes were seen many times: segments that end within the run,
    // and runs taken to their last whole block.
    EXPECT_GT(ended, 300) << name;
    EXPECT_GT(whole, 300) << name;
}

TEST(SlopeBlocks, BaselineBlocksTakeWhatVertexByVertexWould) {
    const SlopeBlockVariants baseline = baselineSlopeBlocks();
    checkVariant(baseline.floats, "baseline, float values");
    checkVariant(baseline.doubles, "baseline, double values");
}

TEST(SlopeBlocks, Avx2BlocksTakeWhatVertexByVertexWould) {
    const SlopeBlockVariants avx2 = avx2SlopeBlocks();
    if (!avx2.floats) GTEST_SKIP() << "built without the AVX2 variant, or the processor lacks AVX2";
    checkVariant(avx2.floats, "AVX2, float values");
    checkVariant(avx2.doubles, "AVX2, double values");
}

// RGB vertex by vertex, as the compressor's RGB walk takes them: one 1 / dz
// a vertex, each channel's window narrowed by its bounds, and the vertex
// taken while every channel's window stays feasible; then cut back to the
// last whole block of eight.
struct RgbWalk {
    std::size_t taken;
    double lo[3], hi[3];
    std::uint64_t count;
};

template <typename T>
RgbWalk rgbWalkInBlocks(const std::vector<float>& z, const std::vector<T>& v,
                        const std::vector<std::uint32_t>& counts, const SlopeFrame* frames, RgbWalk w) {
    std::vector<RgbWalk> after{w};
    for (std::size_t i = 0; i < z.size(); ++i) {
        const double dz = static_cast<double>(z[i]) - static_cast<double>(frames[0].originZ);
        const double inverse = depthInverse(z[i], frames[0].originZ, dz);
        RgbWalk next = w;
        bool feasible = true;
        for (int c = 0; c < 3; ++c) {
            const VertexSlopes s = slopesScaledBy(inverse, dz, v[3 * i + static_cast<std::size_t>(c)], frames[c]);
            next.hi[c] = std::min(w.hi[c], s.top);
            next.lo[c] = std::max(w.lo[c], s.bottom);
            feasible &= feasibleWindow(next.lo[c], next.hi[c], frames[c].originV, dz);
        }
        if (!feasible) break;
        next.taken = i + 1;
        next.count = w.count + counts[i];
        w = next;
        after.push_back(w);
    }
    return after[(after.size() - 1) / 8 * 8];
}

template <typename T>
void checkRgbVariant(std::size_t (*blocks)(const float*, const T*, const std::uint32_t*, std::size_t,
                                           const SlopeFrame*, double*, double*, std::uint64_t&),
                     const char* name) {
    std::mt19937_64 rng(31);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    int ended = 0, whole = 0;
    for (int trial = 0; trial < 3000; ++trial) {
        const std::size_t n = rng() % 90;
        const float originZ = static_cast<float>(0.5 + 4.0 * unit(rng));
        const double band = trial % 7 == 0 ? 1e-9 : 0.2 * unit(rng) + 1e-6;
        SlopeFrame frames[3];
        double value[3];
        for (int c = 0; c < 3; ++c) {
            value[c] = trial % 5 == 0 ? 1.0 : unit(rng);
            frames[c] = slopeFrame(originZ, value[c], band);
        }
        // Each channel falls in its own steps and ramps (a coloured input),
        // sometimes slowly enough for segments to run past many blocks.
        std::vector<float> z(n);
        std::vector<T> v(3 * n);
        std::vector<std::uint32_t> counts(n);
        // From the open segment's first vertex (at originZ + 1e-3) on: depths never fall,
        // and each differs from the origin's (the blocks' preconditions).
        double depth = originZ + 1e-3 * (1.0 + unit(rng));
        const double fall = trial % 3 == 0 ? 0.002 : 0.05;
        for (std::size_t i = 0; i < n; ++i) {
            if (rng() % 3 != 0) depth += 0.05 * unit(rng);
            z[i] = static_cast<float>(depth);
            for (std::size_t c = 0; c < 3; ++c) {
                value[c] = std::max(0.0, value[c] - fall * (c + 1) * 0.5 * unit(rng));
                v[3 * i + c] = static_cast<T>(value[c]);
            }
            counts[i] = static_cast<std::uint32_t>(rng() % 5 == 0 ? 0xffffffffu : rng() % 1000);
        }
        // The open segment's windows, as after its first vertex.
        RgbWalk start{0, {}, {}, 0};
        for (int c = 0; c < 3; ++c) {
            const VertexSlopes first = vertexSlopes(static_cast<float>(originZ + 1e-3), frames[c].originV, frames[c]);
            start.lo[c] = first.bottom;
            start.hi[c] = first.top;
        }
        for (bool withCounts : {false, true}) {
            const RgbWalk expected = rgbWalkInBlocks(z, v, counts, frames, start);
            double lo[3], hi[3];
            std::copy(start.lo, start.lo + 3, lo);
            std::copy(start.hi, start.hi + 3, hi);
            std::uint64_t count = 5;
            const std::size_t taken =
                blocks(z.data(), v.data(), withCounts ? counts.data() : nullptr, n, frames, lo, hi, count);
            ASSERT_EQ(taken, expected.taken) << name << " trial " << trial;
            for (int c = 0; c < 3; ++c) {
                ASSERT_EQ(lo[c], expected.lo[c]) << name << " trial " << trial << " channel " << c;
                ASSERT_EQ(hi[c], expected.hi[c]) << name << " trial " << trial << " channel " << c;
            }
            ASSERT_EQ(count, 5 + (withCounts ? expected.count : 0)) << name << " trial " << trial;
            if (withCounts) (taken + 8 <= n ? ended : whole) += 1;
        }
    }
    EXPECT_GT(ended, 300) << name;
    EXPECT_GT(whole, 300) << name;
}

TEST(SlopeBlocks, BaselineRgbBlocksTakeWhatVertexByVertexWould) {
    const SlopeBlockVariants baseline = baselineSlopeBlocks();
    checkRgbVariant(baseline.rgbFloats, "baseline RGB, float values");
    checkRgbVariant(baseline.rgbDoubles, "baseline RGB, double values");
}

TEST(SlopeBlocks, Avx2RgbBlocksTakeWhatVertexByVertexWould) {
    const SlopeBlockVariants avx2 = avx2SlopeBlocks();
    if (!avx2.rgbFloats) GTEST_SKIP() << "built without the AVX2 variant, or the processor lacks AVX2";
    checkRgbVariant(avx2.rgbFloats, "AVX2 RGB, float values");
    checkRgbVariant(avx2.rgbDoubles, "AVX2 RGB, double values");
}

// The compressor's centred walk, vertex by vertex (takeCentredVertex()):
// the run state after each vertex while the windows stay feasible.
template <int C, typename T>
std::vector<CentredRunOf<C>> centredWalk(const std::vector<float>& z, const std::vector<T>& v,
                                         const std::vector<double>* bands, const std::vector<std::uint32_t>* counts,
                                         const CentredFrameOf<C>& frame, CentredRunOf<C> r) {
    std::vector<CentredRunOf<C>> after{r};
    for (std::size_t i = 0; i < z.size(); ++i) {
        const CentredFrameOf<C> own =
            bands ? CentredFrameOf<C>{{withBand(frame.slopes[0], (*bands)[i])}, frame.margin} : frame;
        if (!takeCentredVertex(z[i], v.data() + i * C, counts ? (*counts)[i] : 0u, i, own, r)) break;
        after.push_back(r);
    }
    return after;
}

// Equal bit for bit (a zero's sign included).
void expectSameBits(double a, double b, const std::string& what) {
    EXPECT_EQ(std::bit_cast<std::uint64_t>(a), std::bit_cast<std::uint64_t>(b)) << what << ": " << a << " " << b;
}

// Every field of two run states equal bit for bit.
template <int C>
void expectSameRun(const CentredRunOf<C>& got, const CentredRunOf<C>& expected, const std::string& what) {
    for (int c = 0; c < C; ++c) {
        const std::string channel = what + (C > 1 ? " channel " + std::to_string(c) : std::string());
        expectSameBits(got.lo[c], expected.lo[c], channel + " lo");
        expectSameBits(got.hi[c], expected.hi[c], channel + " hi");
        expectSameBits(got.twiceIntegral[c], expected.twiceIntegral[c], channel + " integral");
        expectSameBits(got.previousV[c], expected.previousV[c], channel + " previous value");
        expectSameBits(got.longestEndV[c], expected.longestEndV[c], channel + " longest stretch's end value");
        expectSameBits(got.balancedLo[c], expected.balancedLo[c], channel + " balanced lo");
        expectSameBits(got.balancedHi[c], expected.balancedHi[c], channel + " balanced hi");
        expectSameBits(got.balancedIntegral[c], expected.balancedIntegral[c], channel + " balanced integral");
        expectSameBits(got.balancedLongestEndV[c], expected.balancedLongestEndV[c],
                       channel + " balanced longest end value");
    }
    expectSameBits(got.previousZ, expected.previousZ, what + " previous depth");
    EXPECT_EQ(got.count, expected.count) << what;
    EXPECT_EQ(got.balancedAt, expected.balancedAt) << what;
    expectSameBits(got.longest, expected.longest, what + " longest stretch");
    expectSameBits(got.longestEndDz, expected.longestEndDz, what + " longest stretch's end depth");
    expectSameBits(got.balancedLongest, expected.balancedLongest, what + " balanced longest stretch");
    expectSameBits(got.balancedLongestEndDz, expected.balancedLongestEndDz, what + " balanced longest end depth");
    EXPECT_EQ(got.balancedCount, expected.balancedCount) << what;
}

// Whether a segment that a walk took `walked` vertices of a run of n into
// ends within a whole block of the run.
bool endsInABlock(std::size_t walked, std::size_t n) { return walked < n && walked / 8 * 8 + 8 <= n; }

// How many vertices the blocks take of such a run: whole blocks, and the
// vertices of the block where the segment ends before the one that ends it;
// a run's last few are left.
std::size_t takenInBlocks(std::size_t walked, std::size_t n) {
    return endsInABlock(walked, n) ? walked : walked / 8 * 8;
}

// How often a check met each case worth covering: segments that end within
// the run (part way through a block among them), runs taken to their last
// whole block, and balanced vertices found in blocks. Each must come many
// times.
struct CentredCoverage {
    int ended = 0, endedPartWay = 0, whole = 0, balancedInBlocks = 0;

    template <int C>
    void note(std::size_t walked, std::size_t n, const CentredRunOf<C>& expected, const CentredRunOf<C>& start) {
        const bool endsInBlock = endsInABlock(walked, n);
        (endsInBlock ? ended : whole) += 1;
        if (endsInBlock && walked % 8 != 0) ++endedPartWay;
        if (expected.balancedAt != start.balancedAt) ++balancedInBlocks;
    }

    void expectEachManyTimes(const char* name) const {
        EXPECT_GT(ended, 300) << name;
        EXPECT_GT(endedPartWay, 300) << name;
        EXPECT_GT(whole, 300) << name;
        EXPECT_GT(balancedInBlocks, 300) << name;
    }
};

template <typename T>
void checkCentredVariant(std::size_t (*blocks)(const float*, const T*, const double*, const std::uint32_t*,
                                               std::size_t, const CentredFrame&, CentredRun&),
                         const char* name) {
    std::mt19937_64 rng(41);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    CentredCoverage coverage;
    for (int trial = 0; trial < 3000; ++trial) {
        const std::size_t n = rng() % 120;
        const float originZ = static_cast<float>(0.5 + 4.0 * unit(rng));
        const double originV = trial % 5 == 0 ? 1.0 : unit(rng);
        const double band = trial % 7 == 0 ? 1e-9 : 0.2 * unit(rng) + 1e-6;
        const CentredFrame frame{{slopeFrame(originZ, originV, band)}, 0.1 * band};
        // A falling input in steps and ramps, flat for long stretches at
        // times (plateaus, where segments balance, and whose ends they keep).
        std::vector<float> z(n);
        std::vector<T> v(n);
        std::vector<std::uint32_t> counts(n);
        std::vector<double> bands(n);  // each vertex's own (grey RGB input)
        // From the open segment's first vertex (at originZ + 1e-3) on: depths never fall,
        // and each differs from the origin's (the blocks' preconditions).
        double depth = originZ + 1e-3 * (1.0 + unit(rng)), value = originV;
        const double fall = trial % 3 == 0 ? 0.002 : 0.05;
        for (std::size_t i = 0; i < n; ++i) {
            if (rng() % 3 != 0) depth += 0.05 * unit(rng);
            if (trial % 2 == 0 && rng() % 23 == 0) depth += 0.5 + unit(rng);  // a plateau
            if (rng() % 4 != 0) value = std::max(0.0, value - fall * unit(rng));
            z[i] = static_cast<float>(depth);
            v[i] = static_cast<T>(value);
            counts[i] = static_cast<std::uint32_t>(rng() % 5 == 0 ? 0xffffffffu : rng() % 1000);
            bands[i] = band * (0.5 + 0.5 * unit(rng));
        }
        // An open segment, as after its first vertex, with something already
        // summed and balanced.
        const float firstZ = static_cast<float>(originZ + 1e-3);
        const VertexSlopes first = vertexSlopes(firstZ, originV, frame.slopes[0]);
        const CentredRun start{{first.bottom}, {first.top}, {2e-3 * originV}, firstZ, {originV}, 7, 1e-3,
                               1e-3, {originV}, 3, {first.bottom}, {first.top}, {1e-3}, 2, 1e-3, 1e-3, {originV}};
        for (int variant = 0; variant < 3; ++variant) {
            const bool withCounts = variant != 0, ownBands = variant == 2;
            const std::vector<CentredRun> walk =
                centredWalk(z, v, ownBands ? &bands : nullptr, withCounts ? &counts : nullptr, frame, start);
            const std::size_t walked = walk.size() - 1, taken = takenInBlocks(walked, n);
            const CentredRun& expected = walk[taken];
            CentredRun got = start;
            const std::size_t took = blocks(z.data(), v.data(), ownBands ? bands.data() : nullptr,
                                            withCounts ? counts.data() : nullptr, n, frame, got);
            const std::string what =
                std::string(name) + " trial " + std::to_string(trial) + (ownBands ? ", own bands" : "");
            ASSERT_EQ(took, taken) << what;
            expectSameRun(got, expected, what);
            if (::testing::Test::HasFailure()) return;
            if (withCounts && !ownBands) coverage.note(walked, n, expected, start);
        }
    }
    coverage.expectEachManyTimes(name);
}

TEST(SlopeBlocks, BaselineCentredBlocksTakeWhatTheWalkWould) {
    const SlopeBlockVariants baseline = baselineSlopeBlocks();
    checkCentredVariant(baseline.centredFloats, "baseline, float values");
    checkCentredVariant(baseline.centredDoubles, "baseline, double values");
}

TEST(SlopeBlocks, Avx2CentredBlocksTakeWhatTheWalkWould) {
    const SlopeBlockVariants avx2 = avx2SlopeBlocks();
    if (!avx2.centredFloats) GTEST_SKIP() << "built without the AVX2 variant, or the processor lacks AVX2";
    checkCentredVariant(avx2.centredFloats, "AVX2, float values");
    checkCentredVariant(avx2.centredDoubles, "AVX2, double values");
}

// The same for RGB: each channel falls in its own steps and ramps (a
// coloured input), flat in every channel across the plateaus.
template <typename T>
void checkCentredRgbVariant(std::size_t (*blocks)(const float*, const T*, const std::uint32_t*, std::size_t,
                                                  const CentredFrameOf<3>&, CentredRunOf<3>&),
                            const char* name) {
    std::mt19937_64 rng(43);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    CentredCoverage coverage;
    for (int trial = 0; trial < 3000; ++trial) {
        const std::size_t n = rng() % 120;
        const float originZ = static_cast<float>(0.5 + 4.0 * unit(rng));
        const double band = trial % 7 == 0 ? 1e-9 : 0.2 * unit(rng) + 1e-6;
        CentredFrameOf<3> frame{};
        frame.margin = 0.1 * band;
        double value[3];
        for (int c = 0; c < 3; ++c) {
            value[c] = trial % 5 == 0 ? 1.0 : 0.5 + 0.5 * unit(rng);
            frame.slopes[c] = slopeFrame(originZ, value[c], band);
        }
        std::vector<float> z(n);
        std::vector<T> v(3 * n);
        std::vector<std::uint32_t> counts(n);
        // From the open segment's first vertex (at originZ + 1e-3) on: depths never fall,
        // and each differs from the origin's (the blocks' preconditions).
        double depth = originZ + 1e-3 * (1.0 + unit(rng));
        const double fall = trial % 3 == 0 ? 0.002 : 0.05;
        for (std::size_t i = 0; i < n; ++i) {
            if (rng() % 3 != 0) depth += 0.05 * unit(rng);
            const bool plateau = trial % 2 == 0 && rng() % 23 == 0;
            if (plateau) depth += 0.5 + unit(rng);
            z[i] = static_cast<float>(depth);
            for (std::size_t c = 0; c < 3; ++c) {
                if (!plateau && rng() % 4 != 0) value[c] = std::max(0.0, value[c] - fall * (c + 1) * 0.5 * unit(rng));
                v[3 * i + c] = static_cast<T>(value[c]);
            }
            counts[i] = static_cast<std::uint32_t>(rng() % 5 == 0 ? 0xffffffffu : rng() % 1000);
        }
        // An open segment, as after its first vertex, with something already
        // summed and balanced.
        const float firstZ = static_cast<float>(originZ + 1e-3);
        CentredRunOf<3> start{};
        for (int c = 0; c < 3; ++c) {
            const double originV = frame.slopes[c].originV;
            const VertexSlopes first = vertexSlopes(firstZ, originV, frame.slopes[c]);
            start.lo[c] = start.balancedLo[c] = first.bottom;
            start.hi[c] = start.balancedHi[c] = first.top;
            start.twiceIntegral[c] = 2e-3 * originV;
            start.balancedIntegral[c] = 1e-3;
            start.previousV[c] = start.longestEndV[c] = start.balancedLongestEndV[c] = originV;
        }
        start.previousZ = firstZ;
        start.count = 7;
        start.longest = start.longestEndDz = start.balancedLongest = start.balancedLongestEndDz = 1e-3;
        start.balancedAt = 3;
        start.balancedCount = 2;
        for (bool withCounts : {false, true}) {
            const std::vector<CentredRunOf<3>> walk =
                centredWalk(z, v, nullptr, withCounts ? &counts : nullptr, frame, start);
            const std::size_t walked = walk.size() - 1, taken = takenInBlocks(walked, n);
            CentredRunOf<3> got = start;
            const std::size_t took = blocks(z.data(), v.data(), withCounts ? counts.data() : nullptr, n, frame, got);
            const std::string what = std::string(name) + " trial " + std::to_string(trial);
            ASSERT_EQ(took, taken) << what;
            expectSameRun(got, walk[taken], what);
            if (::testing::Test::HasFailure()) return;
            if (withCounts) coverage.note(walked, n, walk[taken], start);
        }
    }
    coverage.expectEachManyTimes(name);
}

TEST(SlopeBlocks, BaselineCentredRgbBlocksTakeWhatTheWalkWould) {
    const SlopeBlockVariants baseline = baselineSlopeBlocks();
    checkCentredRgbVariant(baseline.centredRgbFloats, "baseline RGB, float values");
    checkCentredRgbVariant(baseline.centredRgbDoubles, "baseline RGB, double values");
}

TEST(SlopeBlocks, Avx2CentredRgbBlocksTakeWhatTheWalkWould) {
    const SlopeBlockVariants avx2 = avx2SlopeBlocks();
    if (!avx2.centredRgbFloats) GTEST_SKIP() << "built without the AVX2 variant, or the processor lacks AVX2";
    checkCentredRgbVariant(avx2.centredRgbFloats, "AVX2 RGB, float values");
    checkCentredRgbVariant(avx2.centredRgbDoubles, "AVX2 RGB, double values");
}

TEST(SlopeBlocks, FastInverseIsCloseToTheQuotient) {
    // The Newton step brings the float quotient to about 2^-45 of 1 / dz
    // across the fast range (the compressor's bound leaves 2^-25).
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> exponent(-100.0, 100.0), unit(1.0, 2.0);
    double worst = 0.0;
    for (int i = 0; i < 200000; ++i) {
        const float origin = static_cast<float>(std::ldexp(unit(rng), static_cast<int>(exponent(rng))));
        const float z = static_cast<float>(origin + std::ldexp(unit(rng), static_cast<int>(exponent(rng))));
        const double dz = static_cast<double>(z) - static_cast<double>(origin);
        if (!(dz >= kLeastFastDepth && dz <= kMostFastDepth)) continue;
        worst = std::max(worst, std::abs(fastInverse(z, origin, dz) * dz - 1.0));
    }
    EXPECT_LT(worst, 0x1p-43);
    EXPECT_GT(worst, 0.0);
}

TEST(SlopeBlocks, DepthDifferencesOutsideTheFastRangeAreDivided) {
    // Where the float quotient would overflow or lose its precision, the
    // slopes are the quotients of doubles.
    const SlopeFrame frame = slopeFrame(0.0f, 1.0, 0.25);
    for (const double dz : {1.4e-45, 1e-44, 3e-39, 0x1p-101, 1.0, 0x1p101, 1e38, 3.4e38}) {
        const VertexSlopes s = vertexSlopes(static_cast<float>(dz), 0.5, frame);
        EXPECT_EQ(s.dz, static_cast<double>(static_cast<float>(dz)));
        EXPECT_NEAR(s.top / ((0.5 + 0.25 - 1.0) / s.dz), 1.0, 1e-12) << "dz " << dz;
        EXPECT_NEAR(s.bottom / ((0.5 - 0.25 - 1.0) / s.dz), 1.0, 1e-12) << "dz " << dz;
    }
}

}  // namespace
