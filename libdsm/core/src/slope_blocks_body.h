// The body of takeSlopeBlocks() (slope_blocks.h), included by the baseline
// and the AVX2 translation units; each gets its own copy, with internal
// linkage, compiled for its instruction set.
#pragma once

#include <cstring>

#include "slope_blocks.h"

#ifdef __AVX__
#include <immintrin.h>
#endif

namespace dsm::detail {
namespace {

using Double4 = double __attribute__((vector_size(32)));
using Float4 = float __attribute__((vector_size(16)));
using Count4 = std::uint32_t __attribute__((vector_size(16)));
using Sum4 = std::uint64_t __attribute__((vector_size(32)));

// Four floats as four doubles. The compiler's generic conversion splits it in
// halves even where one AVX instruction does it. The result goes through a
// reference: a function returning a 32-byte vector has another ABI with AVX
// than without.
inline void widen(const Float4& f, Double4& out) {
#ifdef __AVX__
    out = reinterpret_cast<Double4>(_mm256_cvtps_pd(reinterpret_cast<__m128>(f)));
#else
    out = __builtin_convertvector(f, Double4);
#endif
}

inline void loadValues(const float* v, Double4& out) {
    Float4 f;
    std::memcpy(&f, v, sizeof f);
    widen(f, out);
}

inline void loadValues(const double* v, Double4& out) { std::memcpy(&out, v, sizeof out); }

// Own minimum and maximum rather than std::min and std::max: an out-of-line
// copy of those that the AVX2 unit compiled could be linked in everywhere.
inline double lesser(double a, double b) { return b < a ? b : a; }
inline double greater(double a, double b) { return b > a ? b : a; }

// The least and the greatest of four lanes: a window's bounds.
inline double leastLane(const Double4& d) { return lesser(lesser(d[0], d[1]), lesser(d[2], d[3])); }
inline double greatestLane(const Double4& d) { return greater(greater(d[0], d[1]), greater(d[2], d[3])); }

// One bit for each lane of a comparison's result that holds (lane 0 lowest).
template <typename Mask>
[[gnu::always_inline]] inline unsigned laneBits(const Mask& m) {
#ifdef __AVX__
    return static_cast<unsigned>(_mm256_movemask_pd(reinterpret_cast<__m256d>(m)));
#else
    return static_cast<unsigned>(m[0] != 0) | static_cast<unsigned>(m[1] != 0) << 1 |
           static_cast<unsigned>(m[2] != 0) << 2 | static_cast<unsigned>(m[3] != 0) << 3;
#endif
}

// Four values of one channel of vertices of C channels from v (vertex k's at
// v[k * C]), as doubles.
template <int C, typename T>
[[gnu::always_inline]] inline void loadChannel(const T* v, Double4& out) {
    if constexpr (C == 1)
        loadValues(v, out);
    else
        out = Double4{static_cast<double>(v[0]), static_cast<double>(v[C]), static_cast<double>(v[2 * C]),
                      static_cast<double>(v[3 * C])};
}

// Eight vertices' least top slope and greatest bottom slope of one channel,
// four lanes each, and the last vertex's depth beyond the origin.
struct EightSlopes {
    Double4 least, greatest;
    double lastDz;
};

// The offsets of four vertices' target windows: the frame's, or each
// vertex's own band's (withBand()'s operations).
struct Offsets {
    double top, bottom;      // the frame's
    const double* bands;     // or null
};

template <bool ownBands>
[[gnu::always_inline]] inline void offsetsOf(const Offsets& o, double originV, std::size_t at, Double4& top,
                                             Double4& bottom) {
    if constexpr (ownBands) {
        Double4 band;
        std::memcpy(&band, o.bands + at, sizeof band);
        top = band - originV;
        bottom = -band - originV;
    } else {
        top = Double4{o.top, o.top, o.top, o.top};
        bottom = Double4{o.bottom, o.bottom, o.bottom, o.bottom};
    }
}

// The slopes of each of C channels (origin values originV[c], offsets
// offsets[c]) over eight vertices from `at`, with one 1 / dz a vertex.
template <int C, bool ownBands, typename T>
[[gnu::always_inline]] inline void eightSlopes(const float* z, const T* v, std::size_t at, float originZ,
                                               const double* originV, const Offsets* offsets, EightSlopes* out) {
    Double4 top[C][2], bottom[C][2], dz;
    for (int h = 0; h < 2; ++h) {
        const std::size_t i = at + 4 * static_cast<std::size_t>(h);
        Float4 depth;
        std::memcpy(&depth, z + i, sizeof depth);
        widen(depth, dz);
        dz -= static_cast<double>(originZ);
        // fastInverse(), four lanes at once: the same operations.
        Double4 q;
        widen(1.0f / (depth - originZ), q);
        const Double4 inverse = q * (2.0 - dz * q);
        for (int c = 0; c < C; ++c) {
            Double4 value, topOffset, bottomOffset;
            loadChannel<C>(v + i * static_cast<std::size_t>(C) + static_cast<std::size_t>(c), value);
            offsetsOf<ownBands>(offsets[c], originV[c], i, topOffset, bottomOffset);
            top[c][h] = (value + topOffset) * inverse;
            bottom[c][h] = (value + bottomOffset) * inverse;
        }
    }
    for (int c = 0; c < C; ++c) {
        out[c].least = top[c][1] < top[c][0] ? top[c][1] : top[c][0];
        out[c].greatest = bottom[c][1] > bottom[c][0] ? bottom[c][1] : bottom[c][0];
        out[c].lastDz = dz[3];
    }
}

// Whether the window of four lanes each way (its bounds the least hi and the
// greatest lo) is feasible at lastDz.
[[gnu::always_inline]] inline bool feasibleLanes(const Double4& hi, const Double4& lo, double originV,
                                                 double lastDz) {
    return feasibleWindow(greatestLane(lo), leastLane(hi), originV, lastDz);
}

// The counts of the block of eight vertices from `first`, added to four
// lanes of sums. Without counts, `counts` is null: no pointer is formed from it.
template <bool withCounts>
[[gnu::always_inline]] inline void addCounts(const std::uint32_t* counts, std::size_t first, Sum4& sum) {
    if constexpr (withCounts) {
        Count4 c[2];
        std::memcpy(c, counts + first, sizeof c);
        sum += __builtin_convertvector(c[0], Sum4) + __builtin_convertvector(c[1], Sum4);
    }
}

// `blocks` blocks of eight vertices, taken when every channel's window (hi[c],
// lo[c]) narrowed by all of them is feasible at their last vertex; otherwise
// the windows are left as they were. Returns whether it took them.
template <int blocks, int C, bool withCounts, bool ownBands, typename T>
[[gnu::always_inline]] inline bool takeBlocks(const float* z, const T* v, const std::uint32_t* counts, std::size_t at,
                                              float originZ, const double* originV, const Offsets* offsets,
                                              Double4* hi, Double4* lo, Sum4& sum) {
    Double4 nextHi[C], nextLo[C];
    for (int c = 0; c < C; ++c) {
        nextHi[c] = hi[c];
        nextLo[c] = lo[c];
    }
    double lastDz = 0.0;
    for (int b = 0; b < blocks; ++b) {
        EightSlopes slopes[C];
        eightSlopes<C, ownBands>(z, v, at + 8 * static_cast<std::size_t>(b), originZ, originV, offsets, slopes);
        for (int c = 0; c < C; ++c) {
            nextHi[c] = slopes[c].least < nextHi[c] ? slopes[c].least : nextHi[c];
            nextLo[c] = slopes[c].greatest > nextLo[c] ? slopes[c].greatest : nextLo[c];
        }
        lastDz = slopes[0].lastDz;
    }
    bool feasible = true;
    for (int c = 0; c < C; ++c) feasible &= feasibleLanes(nextHi[c], nextLo[c], originV[c], lastDz);
    if (!feasible) return false;
    for (int c = 0; c < C; ++c) {
        hi[c] = nextHi[c];
        lo[c] = nextLo[c];
    }
    for (int b = 0; b < blocks; ++b) addCounts<withCounts>(counts, at + 8 * static_cast<std::size_t>(b), sum);
    return true;
}

// Each channel's window is kept as four lanes each way, its bounds the least
// and the greatest lane, so that a block narrows it by one vector operation.
// Blocks go four at a time, so that the test of the windows (which reduces
// the lanes) is made once for 32 vertices; where the segment ends within four
// blocks, they are taken again one at a time (their slopes computed again),
// so that at most one block is left to be walked vertex by vertex.
template <int C, bool withCounts, bool ownBands, typename T>
std::size_t slopeBlocksOf(const float* z, const T* v, const double* bands, const std::uint32_t* counts,
                          std::size_t n, const SlopeFrame* f, double* lo, double* hi, std::uint64_t& count) {
    // Locals, not the pointers and the frames: stores through those could
    // alias the input as far as the compiler knows.
    const float originZ = f[0].originZ;
    double originV[C];
    Offsets offsets[C];
    Double4 windowLo[C], windowHi[C];
    for (int c = 0; c < C; ++c) {
        originV[c] = f[c].originV;
        offsets[c] = Offsets{f[c].topOffset, f[c].bottomOffset, ownBands ? bands : nullptr};
        windowLo[c] = Double4{lo[c], lo[c], lo[c], lo[c]};
        windowHi[c] = Double4{hi[c], hi[c], hi[c], hi[c]};
    }
    std::size_t i = 0;
    Sum4 sum = {};
    while (i + 32 <= n &&
           takeBlocks<4, C, withCounts, ownBands>(z, v, counts, i, originZ, originV, offsets, windowHi, windowLo, sum))
        i += 32;
    while (i + 8 <= n &&
           takeBlocks<1, C, withCounts, ownBands>(z, v, counts, i, originZ, originV, offsets, windowHi, windowLo, sum))
        i += 8;
    for (int c = 0; c < C; ++c) {
        hi[c] = leastLane(windowHi[c]);
        lo[c] = greatestLane(windowLo[c]);
    }
    count += sum[0] + sum[1] + sum[2] + sum[3];
    return i;
}

// The least of each lane and the lanes before it, and the greatest (through
// a reference, as widen()).
[[gnu::always_inline]] inline void leastSoFar(const Double4& x, Double4& out) {
    constexpr double kInf = __builtin_inf();
    const Double4 none = {kInf, kInf, kInf, kInf};
    const Double4 shifted = __builtin_shufflevector(none, x, 0, 4, 5, 6);
    const Double4 y = shifted < x ? shifted : x;
    const Double4 shiftedTwice = __builtin_shufflevector(none, y, 0, 1, 4, 5);
    out = shiftedTwice < y ? shiftedTwice : y;
}
[[gnu::always_inline]] inline void greatestSoFar(const Double4& x, Double4& out) {
    constexpr double kInf = __builtin_inf();
    const Double4 none = {-kInf, -kInf, -kInf, -kInf};
    const Double4 shifted = __builtin_shufflevector(none, x, 0, 4, 5, 6);
    const Double4 y = shifted > x ? shifted : x;
    const Double4 shiftedTwice = __builtin_shufflevector(none, y, 0, 1, 4, 5);
    out = shiftedTwice > y ? shiftedTwice : y;
}

// Each lane keeps its stretch (length, end depth beyond the origin, end
// values of C channels) unless the earlier one given for it is at least as
// long: the first of equals, as the walk keeps it.
template <int C>
[[gnu::always_inline]] inline void keepLongest(Double4& length, Double4& endDz, Double4* endV,
                                               const Double4& earlierLength, const Double4& earlierEndDz,
                                               const Double4* earlierEndV) {
    const auto keep = length > earlierLength;
    length = keep ? length : earlierLength;
    endDz = keep ? endDz : earlierEndDz;
    for (int c = 0; c < C; ++c) endV[c] = keep ? endV[c] : earlierEndV[c];
}

// The longest stretch of each lane and the lanes before it, and of `before`
// (the run's, ahead of the lanes), through references: one lane back, then
// two lanes back, then the run's.
template <int C>
[[gnu::always_inline]] inline void longestSoFar(Double4& length, Double4& endDz, Double4* endV, double beforeLength,
                                                double beforeEndDz, const double* beforeEndV) {
    const Double4 none = {-__builtin_inf(), -__builtin_inf(), -__builtin_inf(), -__builtin_inf()}, zero = {};
    Double4 endV1[C], endV2[C], endVBefore[C];
    const Double4 length1 = __builtin_shufflevector(none, length, 0, 4, 5, 6);
    const Double4 endDz1 = __builtin_shufflevector(zero, endDz, 0, 4, 5, 6);
    for (int c = 0; c < C; ++c) endV1[c] = __builtin_shufflevector(zero, endV[c], 0, 4, 5, 6);
    keepLongest<C>(length, endDz, endV, length1, endDz1, endV1);
    const Double4 length2 = __builtin_shufflevector(none, length, 0, 1, 4, 5);
    const Double4 endDz2 = __builtin_shufflevector(zero, endDz, 0, 1, 4, 5);
    for (int c = 0; c < C; ++c) endV2[c] = __builtin_shufflevector(zero, endV[c], 0, 1, 4, 5);
    keepLongest<C>(length, endDz, endV, length2, endDz2, endV2);
    for (int c = 0; c < C; ++c) endVBefore[c] = Double4{beforeEndV[c], beforeEndV[c], beforeEndV[c], beforeEndV[c]};
    keepLongest<C>(length, endDz, endV, Double4{beforeLength, beforeLength, beforeLength, beforeLength},
                   Double4{beforeEndDz, beforeEndDz, beforeEndDz, beforeEndDz}, endVBefore);
}

// takeCentredBlocks() and takeCentredRgbBlocks(), a block of eight vertices
// at a time, in two halves of four lanes. Each vertex's 1 / dz and each
// channel's bounds, the trapezoid it adds to the integral and the balance
// test are worked out four lanes at once, by the operations of
// takeCentredVertex() in the same order. Each channel's window after each
// vertex is the least top and the greatest bottom so far, exact in any
// order, so it is taken across the lanes; the integral is summed lane after
// lane, as the walk sums it (a sum's rounding depends on its order). A
// block is taken whole when every channel's window after it is feasible at
// its last vertex; otherwise each lane's windows are tested, and the block is
// taken up to the first lane where one is not feasible. A vertex is balanced
// where every channel is. Each vertex's band is the frame's, or bands[i]
// (ownBands, one channel); the margin is the frame's either way.
template <int C, bool withCounts, bool ownBands, typename T>
std::size_t centredBlocksOf(const float* z, const T* v, const double* bands, const std::uint32_t* counts,
                            std::size_t n, const CentredFrameOf<C>& f, CentredRunOf<C>& run) {
    static_assert(C == 1 || !ownBands, "a band for each vertex is for one channel");
    constexpr std::size_t nc = C;
    const float originZ = f.slopes[0].originZ;
    const double margin = f.margin;
    double origin[C];
    Offsets offsets[C];
    for (int c = 0; c < C; ++c) {
        origin[c] = f.slopes[c].originV;
        offsets[c] = Offsets{f.slopes[c].topOffset, f.slopes[c].bottomOffset, ownBands ? bands : nullptr};
    }
    const Double4 zero = {};
    CentredRunOf<C> r = run;  // a local: stores through `run` could alias the input as far as the compiler knows
    std::size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        Double4 depth[2], inverse[2], depthBeyond[2], stretch[2];
        Double4 value[C][2], windowLo[C][2], windowHi[C][2], integral[C][2];
        double lo[C], hi[C], lastDz = 0.0;
        double twiceIntegral[C];
        Double4 depthBefore = {r.previousZ, r.previousZ, r.previousZ, r.previousZ}, valueBefore[C];
        for (int c = 0; c < C; ++c) {
            hi[c] = r.hi[c];
            lo[c] = r.lo[c];
            twiceIntegral[c] = r.twiceIntegral[c];
            valueBefore[c] = Double4{r.previousV[c], r.previousV[c], r.previousV[c], r.previousV[c]};
        }
#pragma GCC unroll 2
        for (std::size_t h = 0; h < 2; ++h) {
            Float4 depths;
            std::memcpy(&depths, z + i + 4 * h, sizeof depths);
            widen(depths, depth[h]);
            const Double4 dz = depth[h] - static_cast<double>(originZ);
            depthBeyond[h] = dz;
            // fastInverse(), four lanes at once: the same operations.
            Double4 q;
            widen(1.0f / (depths - originZ), q);
            inverse[h] = q * (2.0 - dz * q);
            lastDz = dz[3];
            const Double4 previousDepth = __builtin_shufflevector(depthBefore, depth[h], 3, 4, 5, 6);
            stretch[h] = depth[h] - previousDepth;
            depthBefore = depth[h];
            for (int c = 0; c < C; ++c) {
                loadChannel<C>(v + (i + 4 * h) * nc + static_cast<std::size_t>(c), value[c][h]);
                Double4 topOffset, bottomOffset;
                offsetsOf<ownBands>(offsets[c], origin[c], i + 4 * h, topOffset, bottomOffset);
                const Double4 tops = (value[c][h] + topOffset) * inverse[h];
                const Double4 bottoms = (value[c][h] + bottomOffset) * inverse[h];
                Double4 hiSoFar, loSoFar;
                leastSoFar(tops, hiSoFar);
                greatestSoFar(bottoms, loSoFar);
                const Double4 hiBefore = {hi[c], hi[c], hi[c], hi[c]}, loBefore = {lo[c], lo[c], lo[c], lo[c]};
                windowHi[c][h] = hiSoFar < hiBefore ? hiSoFar : hiBefore;  // std::min(hi, top) vertex to vertex
                windowLo[c][h] = loBefore < loSoFar ? loSoFar : loBefore;  // std::max(lo, bottom)
                hi[c] = windowHi[c][h][3];
                lo[c] = windowLo[c][h][3];
                // (z - previousZ) * (previousV + value), then summed in order.
                const Double4 previousValue = __builtin_shufflevector(valueBefore[c], value[c][h], 3, 4, 5, 6);
                const Double4 trapezoid = stretch[h] * (previousValue + value[c][h]);
                const double sum0 = twiceIntegral[c] + trapezoid[0], sum1 = sum0 + trapezoid[1];
                const double sum2 = sum1 + trapezoid[2], sum3 = sum2 + trapezoid[3];
                integral[c][h] = Double4{sum0, sum1, sum2, sum3};
                twiceIntegral[c] = sum3;
                valueBefore[c] = value[c][h];
            }
        }
        // The windows after the block are feasible at its last vertex, so at
        // every vertex of it (feasibleWindow()). Otherwise the segment ends
        // within the block: its vertices before the first at which some
        // window is not feasible are taken (a window is never feasible again
        // along a segment), and the rest are left.
        bool allFeasible = true;
        for (int c = 0; c < C; ++c) allFeasible &= feasibleWindow(lo[c], hi[c], origin[c], lastDz);
        unsigned lanesTaken = 8;
        if (!allFeasible) {
            unsigned feasible = 0xffu;
            for (int c = 0; c < C; ++c) {
                unsigned feasibleInChannel = 0;
#pragma GCC unroll 2
                for (std::size_t h = 0; h < 2; ++h) {
                    const Double4 top = windowHi[c][h], bottom = windowLo[c][h];
                    feasibleInChannel |=
                        laneBits((bottom <= top) & (bottom <= zero) & (top * depthBeyond[h] >= -origin[c])) << (4 * h);
                }
                feasible &= feasibleInChannel;
            }
            lanesTaken = static_cast<unsigned>(__builtin_ctz(~feasible));
            if (lanesTaken == 0) break;
        }
        const std::size_t last = lanesTaken - 1;
        // balanced(), as the walk tests it: of the feasible slopes, one within
        // 2 margin / dz of the balanced slope whose end is within margin of
        // the input and, behind a plateau, within margin of the input at the
        // plateau's end. Each select is std::min's or std::max's, its
        // operands in the walk's order.
        unsigned balanced = (1u << lanesTaken) - 1u;
        Double4 lowestOf[C][2], highestOf[C][2];
        for (int c = 0; c < C; ++c) {
            unsigned balancedInChannel = 0;
#pragma GCC unroll 2
            for (std::size_t h = 0; h < 2; ++h) {
                const Double4 inv = inverse[h];
                const Double4 feasibleHi = zero < windowHi[c][h] ? zero : windowHi[c][h];
                const Double4 aboveZero = (-origin[c]) * inv;
                const Double4 raised = windowLo[c][h] < aboveZero ? aboveZero : windowLo[c][h];
                const Double4 feasibleLo = feasibleHi < raised ? feasibleHi : raised;
                const Double4 balancedSlope = (integral[c][h] * inv - 2.0 * origin[c]) * inv;
                const Double4 spread = (2.0 * margin) * inv;
                const Double4 belowBalance = balancedSlope - spread, aboveBalance = balancedSlope + spread;
                const Double4 endLow = ((value[c][h] - margin) - origin[c]) * inv;
                const Double4 endHigh = ((value[c][h] + margin) - origin[c]) * inv;
                const Double4 lowestOfTwo = feasibleLo < belowBalance ? belowBalance : feasibleLo;
                const Double4 lowest = lowestOfTwo < endLow ? endLow : lowestOfTwo;
                const Double4 highestOfTwo = aboveBalance < feasibleHi ? aboveBalance : feasibleHi;
                const Double4 highest = endHigh < highestOfTwo ? endHigh : highestOfTwo;
                lowestOf[c][h] = lowest;
                highestOf[c][h] = highest;
                balancedInChannel |= laneBits(lowest <= highest) << (4 * h);
            }
            balanced &= balancedInChannel;
        }
        // The longest stretch so far at each vertex, and behind a plateau
        // each channel's line near the input where it ends. Where no stretch
        // of the block is longer than the run's longest, and that one is
        // shorter than kPlateauShare of the block's first depth beyond the
        // origin (so of every later one), it stays the run's and no vertex is
        // behind a plateau: the usual case along a long segment.
        double longestAfter = r.longest, longestEndDzAfter = r.longestEndDz, longestEndVAfter[C];
        double longestAtBalance = r.longest, longestEndDzAtBalance = r.longestEndDz, longestEndVAtBalance[C];
        for (int c = 0; c < C; ++c) longestEndVAfter[c] = longestEndVAtBalance[c] = r.longestEndV[c];
        const Double4 longer = stretch[1] > stretch[0] ? stretch[1] : stretch[0];
        if (greatestLane(longer) > r.longest || isPlateau(r.longest, depthBeyond[0][0])) {
            Double4 longest[2], longestEndDz[2], longestEndV[2][C];
            unsigned kept = 0;
#pragma GCC unroll 2
            for (std::size_t h = 0; h < 2; ++h) {
                longest[h] = stretch[h];
                longestEndDz[h] = depthBeyond[h];
                for (int c = 0; c < C; ++c) longestEndV[h][c] = value[c][h];
                longestSoFar<C>(longest[h], longestEndDz[h], longestEndV[h], longestAfter, longestEndDzAfter,
                                longestEndVAfter);
                longestAfter = longest[h][3];
                longestEndDzAfter = longestEndDz[h][3];
                for (int c = 0; c < C; ++c) longestEndVAfter[c] = longestEndV[h][c][3];
                const auto plateau = longest[h] >= kPlateauShare * depthBeyond[h];
                auto endsKept = plateau | ~plateau;  // every lane, then each channel's test
                for (int c = 0; c < C; ++c) {
                    const Double4 atPlateauEnd = longestEndV[h][c] - origin[c];
                    endsKept &= (lowestOf[c][h] * longestEndDz[h] <= atPlateauEnd + margin) &
                                (highestOf[c][h] * longestEndDz[h] >= atPlateauEnd - margin);
                }
                kept |= laneBits(~plateau | endsKept) << (4 * h);
            }
            balanced &= kept;
            const std::size_t at = 31 - static_cast<std::size_t>(__builtin_clz(balanced | 1u));
            longestAtBalance = longest[at / 4][at % 4];
            longestEndDzAtBalance = longestEndDz[at / 4][at % 4];
            longestAfter = longest[last / 4][last % 4];
            longestEndDzAfter = longestEndDz[last / 4][last % 4];
            for (int c = 0; c < C; ++c) {
                longestEndVAtBalance[c] = longestEndV[at / 4][c][at % 4];
                longestEndVAfter[c] = longestEndV[last / 4][c][last % 4];
            }
        }
        // The block's last balanced vertex, taken by selects: whether a block
        // has one follows the input too closely for a branch to predict.
        const std::size_t k = 31 - static_cast<std::size_t>(__builtin_clz(balanced | 1u));
        const bool any = balanced != 0;
        std::uint64_t countAfter = r.count;
        if constexpr (withCounts) {
            Count4 c[2];
            std::memcpy(c, counts + i, sizeof c);
            alignas(32) std::uint64_t sums[8];
            Sum4 sum = {r.count, r.count, r.count, r.count};
#pragma GCC unroll 2
            for (std::size_t h = 0; h < 2; ++h) {
                // The counts so far in each lane (integers: exact in any order).
                const Sum4 x = __builtin_convertvector(c[h], Sum4), none = {};
                const Sum4 y = x + __builtin_shufflevector(none, x, 0, 4, 5, 6);
                const Sum4 soFar = y + __builtin_shufflevector(none, y, 0, 1, 4, 5);
                sum = soFar + Sum4{sum[3], sum[3], sum[3], sum[3]};
                std::memcpy(sums + 4 * h, &sum, sizeof sum);
            }
            countAfter = sums[k];
            r.count = sums[last];
        }
        r.balancedAt = any ? i + k : r.balancedAt;
        r.balancedCount = any ? countAfter : r.balancedCount;
        r.balancedLongest = any ? longestAtBalance : r.balancedLongest;
        r.balancedLongestEndDz = any ? longestEndDzAtBalance : r.balancedLongestEndDz;
        for (int c = 0; c < C; ++c) {
            r.balancedLo[c] = any ? windowLo[c][k / 4][k % 4] : r.balancedLo[c];
            r.balancedHi[c] = any ? windowHi[c][k / 4][k % 4] : r.balancedHi[c];
            r.balancedIntegral[c] = any ? integral[c][k / 4][k % 4] : r.balancedIntegral[c];
            r.balancedLongestEndV[c] = any ? longestEndVAtBalance[c] : r.balancedLongestEndV[c];
            r.lo[c] = windowLo[c][last / 4][last % 4];
            r.hi[c] = windowHi[c][last / 4][last % 4];
            r.twiceIntegral[c] = integral[c][last / 4][last % 4];
            r.longestEndV[c] = longestEndVAfter[c];
            r.previousV[c] = value[c][last / 4][last % 4];
        }
        r.longest = longestAfter;
        r.longestEndDz = longestEndDzAfter;
        r.previousZ = depth[last / 4][last % 4];
        if (lanesTaken < 8) {
            i += lanesTaken;
            break;
        }
    }
    run = r;
    return i;
}

template <typename T>
std::size_t centredBlocks(const float* z, const T* v, const double* bands, const std::uint32_t* counts,
                          std::size_t n, const CentredFrame& f, CentredRun& run) {
    if (bands)
        return counts ? centredBlocksOf<1, true, true>(z, v, bands, counts, n, f, run)
                      : centredBlocksOf<1, false, true>(z, v, bands, counts, n, f, run);
    return counts ? centredBlocksOf<1, true, false>(z, v, bands, counts, n, f, run)
                  : centredBlocksOf<1, false, false>(z, v, bands, counts, n, f, run);
}

template <typename T>
std::size_t centredRgbBlocks(const float* z, const T* v, const std::uint32_t* counts, std::size_t n,
                             const CentredFrameOf<3>& f, CentredRunOf<3>& run) {
    return counts ? centredBlocksOf<3, true, false>(z, v, nullptr, counts, n, f, run)
                  : centredBlocksOf<3, false, false>(z, v, nullptr, counts, n, f, run);
}

template <typename T>
std::size_t slopeBlocks(const float* z, const T* v, const double* bands, const std::uint32_t* counts, std::size_t n,
                        const SlopeFrame& f, double& lo, double& hi, std::uint64_t& count) {
    if (bands)
        return counts ? slopeBlocksOf<1, true, true>(z, v, bands, counts, n, &f, &lo, &hi, count)
                      : slopeBlocksOf<1, false, true>(z, v, bands, counts, n, &f, &lo, &hi, count);
    return counts ? slopeBlocksOf<1, true, false>(z, v, bands, counts, n, &f, &lo, &hi, count)
                  : slopeBlocksOf<1, false, false>(z, v, bands, counts, n, &f, &lo, &hi, count);
}

template <typename T>
std::size_t rgbSlopeBlocks(const float* z, const T* v, const std::uint32_t* counts, std::size_t n,
                           const SlopeFrame* frames, double* lo, double* hi, std::uint64_t& count) {
    return counts ? slopeBlocksOf<3, true, false>(z, v, nullptr, counts, n, frames, lo, hi, count)
                  : slopeBlocksOf<3, false, false>(z, v, nullptr, counts, n, frames, lo, hi, count);
}

}  // namespace
}  // namespace dsm::detail
