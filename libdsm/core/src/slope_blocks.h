// The slope bounds input vertices put on a greedy segment of one channel, and
// whole blocks of eight vertices taken at a time (internal). The compressor
// (compressor.cpp) holds a segment's window as two slopes [lo, hi] of lines
// from its origin; each input vertex bounds them by its target window
// (value +- band) less the origin value, over its depth beyond the origin.
//
// Every vertex's bounds come from the same arithmetic, whether computed alone
// (vertexSlopes()) or in a block, with or without AVX2: IEEE operations in
// the same order and no fused multiply-add (the files that compute them are
// built with -ffp-contract=off), so a map is the same on every machine and
// whatever the blocks' alignment.
//
// The helpers below are static: the AVX2 translation unit includes them, and
// a copy it compiled must not stand in for the baseline's elsewhere.
#pragma once

#include <cstddef>
#include <cstdint>

#include "tested_internal.h"

namespace dsm::detail {

// Depth differences in this range take the quotient of floats of
// vertexSlopes(); others (segments shorter than 2^-100 or longer than 2^100)
// are divided as doubles.
inline constexpr double kLeastFastDepth = 0x1p-100;
inline constexpr double kMostFastDepth = 0x1p100;

// What the bounds of a segment's vertices are measured from.
struct SlopeFrame {
    float originZ;        // the origin's depth
    double originV;       // the origin's value
    double topOffset;     // band - originV
    double bottomOffset;  // -band - originV
};

static inline SlopeFrame slopeFrame(float originZ, double originV, double band) {
    return {originZ, originV, band - originV, -band - originV};
}

// Whether a segment from an origin at V = originV to dz beyond it has a
// feasible slope in [lo, hi]: max(lo, -originV / dz) <= min(hi, 0). Along a
// segment it holds up to some vertex and never again: lo only rises, hi only
// falls, and hi * dz only falls once hi < 0.
static inline bool feasibleWindow(double lo, double hi, double originV, double dz) {
    return (lo <= hi) & (lo <= 0.0) & (hi * dz >= -originV);
}

// 1 / dz for a depth difference dz = z - originZ in [kLeastFastDepth,
// kMostFastDepth]: the quotient of floats 1 / (z - originZ), refined by one
// Newton step in double, to a relative error of about 2^-45. A division of
// doubles costs more, and takes two lanes where the floats' takes four. The
// error moves a line's value by about 1e-14, far inside the 2^-25 that the
// compressor's band leaves below its tolerance.
static inline double fastInverse(float z, float originZ, double dz) {
    const double q = static_cast<double>(1.0f / (z - originZ));
    return q * (2.0 - dz * q);
}

// 1 / dz for a vertex at depth z, dz = z - originZ beyond it: fastInverse()
// where it applies, else a division.
static inline double depthInverse(float z, float originZ, double dz) {
    return (dz >= kLeastFastDepth && dz <= kMostFastDepth) ? fastInverse(z, originZ, dz) : 1.0 / dz;
}

struct VertexSlopes {
    double top, bottom, dz;
};

// The bounds of a vertex of value v, dz beyond the origin, with 1 / dz given.
template <typename T>
static inline VertexSlopes slopesScaledBy(double inverse, double dz, T v, const SlopeFrame& f) {
    const double value = static_cast<double>(v);
    return {(value + f.topOffset) * inverse, (value + f.bottomOffset) * inverse, dz};
}

template <typename T>
static inline VertexSlopes vertexSlopes(float z, T v, const SlopeFrame& f) {
    const double dz = static_cast<double>(z) - static_cast<double>(f.originZ);
    return slopesScaledBy(depthInverse(z, f.originZ, dz), dz, v, f);
}

// The frame of a vertex with a band of its own (grey RGB input, whose band
// narrows with its channels' spread): the same offsets slopeFrame() makes.
static inline SlopeFrame withBand(const SlopeFrame& f, double band) {
    return slopeFrame(f.originZ, f.originV, band);
}

// Takes the leading whole blocks of eight vertices of a run that keep the
// window [lo, hi] feasible at their last vertex (so at every vertex: see
// feasibleWindow()), narrowing the window by each and adding their counts
// (when counts is not null) to count. Each vertex's band is the frame's, or
// bands[i] when bands is not null. Returns how many vertices it took, a
// multiple of eight; the block where the segment ends and the run's last
// vertices are left to vertexSlopes(). Preconditions: depths never fall along
// the run, and every depth difference from the origin is in
// [kLeastFastDepth, kMostFastDepth]. Runs on AVX2 where the processor has it.
DSM_TESTED_INTERNAL std::size_t takeSlopeBlocks(const float* z, const float* v, const double* bands,
                                                const std::uint32_t* counts, std::size_t n, const SlopeFrame& frame,
                                                double& lo, double& hi, std::uint64_t& count);
DSM_TESTED_INTERNAL std::size_t takeSlopeBlocks(const float* z, const double* v, const double* bands,
                                                const std::uint32_t* counts, std::size_t n, const SlopeFrame& frame,
                                                double& lo, double& hi, std::uint64_t& count);

// takeSlopeBlocks() for RGB with one band for the run (values[i * 3 + c]):
// each channel c's window [lo[c], hi[c]] from its frame frames[c] (all at
// one origin depth), narrowed by whole blocks of eight vertices while every
// channel's window stays feasible at their last vertex, as the compressor's
// RGB walk takes them one by one (one depthInverse() a vertex, then
// slopesScaledBy() for each channel). Same preconditions and result.
DSM_TESTED_INTERNAL std::size_t takeRgbSlopeBlocks(const float* z, const float* v, const std::uint32_t* counts,
                                                   std::size_t n, const SlopeFrame* frames, double* lo, double* hi,
                                                   std::uint64_t& count);
DSM_TESTED_INTERNAL std::size_t takeRgbSlopeBlocks(const float* z, const double* v, const std::uint32_t* counts,
                                                   std::size_t n, const SlopeFrame* frames, double* lo, double* hi,
                                                   std::uint64_t& count);

// A centred segment of C channels along a run (the compressor's
// extendCentredRunBySlopes()): each channel's window [lo, hi], twice the
// input's integral from the origin (the trapezoids' halves left out), the
// last vertex taken (depth and values), the counts taken, the longest stretch
// between input vertices so far (the first of equals: its length, and its
// end's depth beyond the origin and values), and the last vertex of the run
// at which every channel of the segment can be balanced, with the windows,
// integrals, counts and longest stretch there (balancedAt is kNotBalanced
// while there is none).
template <int C>
struct CentredRunOf {
    double lo[C], hi[C];
    double twiceIntegral[C];
    double previousZ, previousV[C];
    std::uint64_t count;
    double longest, longestEndDz, longestEndV[C];
    std::size_t balancedAt;
    double balancedLo[C], balancedHi[C], balancedIntegral[C];
    std::uint64_t balancedCount;
    double balancedLongest, balancedLongestEndDz, balancedLongestEndV[C];
};
using CentredRun = CentredRunOf<1>;
inline constexpr std::size_t kNotBalanced = ~std::size_t{0};

// A stretch between input vertices that makes up at least this share of a
// segment's depth is a plateau (behind a semi-transparent surface), and a
// receiver on the surface behind it reads the map where it ends: a centred
// segment that takes one in ends within the margin of the input there.
inline constexpr double kPlateauShare = 0.5;

// Whether a longest stretch of this length is a plateau of a segment dz deep.
static inline bool isPlateau(double longest, double dz) { return longest >= kPlateauShare * dz; }

// What a centred segment of C channels tests at each vertex: each channel's
// frame (all at one origin depth), and the margin by which a balanced line
// may miss the input's mean and its last value.
template <int C>
struct CentredFrameOf {
    SlopeFrame slopes[C];
    double margin;
};
using CentredFrame = CentredFrameOf<1>;

// Whether a centred segment of one channel can be balanced ending at its
// last vertex (value, 1 / dz beyond the origin given): of the feasible
// slopes in its window [lo, hi], one within 2 margin / dz of the balanced
// slope (twiceIntegral - 2 origin dz) / dz^2 whose end is within margin of
// the value, and, behind a plateau (the longest stretch, ending
// longestEndDz beyond the origin at longestEndV), within margin of the
// input where the plateau ends: the compressor's balanced(), in slopes.
[[gnu::always_inline]] static inline bool balancedInSlopes(double lo, double hi, double twiceIntegral, double value,
                                                          double inverse, bool plateau, double longestEndDz,
                                                          double longestEndV, double origin, double margin) {
    // Each select is std::min's or std::max's, its operands in that order.
    const double feasibleHi = 0.0 < hi ? 0.0 : hi;
    const double aboveZero = -origin * inverse;
    const double raised = lo < aboveZero ? aboveZero : lo;
    const double feasibleLo = feasibleHi < raised ? feasibleHi : raised;
    const double balancedSlope = (twiceIntegral * inverse - 2.0 * origin) * inverse;
    const double spread = 2.0 * margin * inverse;
    const double belowBalance = balancedSlope - spread, aboveBalance = balancedSlope + spread;
    const double endLow = (value - margin - origin) * inverse, endHigh = (value + margin - origin) * inverse;
    const double lowestOfTwo = feasibleLo < belowBalance ? belowBalance : feasibleLo;
    const double lowest = lowestOfTwo < endLow ? endLow : lowestOfTwo;
    const double highestOfTwo = aboveBalance < feasibleHi ? aboveBalance : feasibleHi;
    const double highest = endHigh < highestOfTwo ? endHigh : highestOfTwo;
    // The line at the plateau's end, origin + slope longestEndDz, within
    // margin of the input there: compared times longestEndDz (> 0).
    const double atPlateauEnd = longestEndV - origin;
    const bool plateauEndKept =
        lowest * longestEndDz <= atPlateauEnd + margin && highest * longestEndDz >= atPlateauEnd - margin;
    return lowest <= highest && (!plateau || plateauEndKept);
}

// One step of the compressor's centred walk: takes vertex `index` of a run
// (depth z, values[c] of each channel, count) into the run state when every
// channel's window narrowed by its bounds stays feasible (one 1 / dz for the
// channels), and tests whether the segment can be balanced ending there, in
// every channel (balanced(): of the feasible slopes, one within 2 margin / dz
// of the balanced slope (twiceIntegral - 2 origin dz) / dz^2 whose end is
// within margin of the input, and, when the longest stretch is a plateau,
// within margin of the input at that stretch's end). Returns false, the
// state untouched, when the vertex leaves some channel no feasible slope.
template <int C, typename T>
static inline bool takeCentredVertex(float z, const T* values, std::uint64_t count, std::size_t index,
                                     const CentredFrameOf<C>& f, CentredRunOf<C>& r) {
    const float originZ = f.slopes[0].originZ;
    // vertexSlopes(), keeping its 1 / dz for the balance below.
    const double dz = static_cast<double>(z) - static_cast<double>(originZ);
    const double inverse = depthInverse(z, originZ, dz);
    double nextLo[C], nextHi[C];
    bool feasible = true;
    for (int c = 0; c < C; ++c) {
        const VertexSlopes s = slopesScaledBy(inverse, dz, values[c], f.slopes[c]);
        nextHi[c] = s.top < r.hi[c] ? s.top : r.hi[c];
        nextLo[c] = r.lo[c] < s.bottom ? s.bottom : r.lo[c];
        feasible &= feasibleWindow(nextLo[c], nextHi[c], f.slopes[c].originV, dz);
    }
    if (!feasible) return false;
    for (int c = 0; c < C; ++c) {
        r.hi[c] = nextHi[c];
        r.lo[c] = nextLo[c];
    }
    r.count += count;
    const double stretch = static_cast<double>(z) - r.previousZ;
    for (int c = 0; c < C; ++c) {
        const double value = static_cast<double>(values[c]);
        r.twiceIntegral[c] += stretch * (r.previousV[c] + value);
        r.previousV[c] = value;
    }
    if (stretch > r.longest) {
        r.longest = stretch;
        r.longestEndDz = dz;
        for (int c = 0; c < C; ++c) r.longestEndV[c] = r.previousV[c];
    }
    r.previousZ = z;
    const bool plateau = isPlateau(r.longest, dz);
    bool balanced = true;
    for (int c = 0; c < C; ++c)
        balanced &= balancedInSlopes(r.lo[c], r.hi[c], r.twiceIntegral[c], r.previousV[c], inverse, plateau,
                                     r.longestEndDz, r.longestEndV[c], f.slopes[c].originV, f.margin);
    if (balanced) {
        r.balancedAt = index;
        for (int c = 0; c < C; ++c) {
            r.balancedLo[c] = r.lo[c];
            r.balancedHi[c] = r.hi[c];
            r.balancedIntegral[c] = r.twiceIntegral[c];
            r.balancedLongestEndV[c] = r.longestEndV[c];
        }
        r.balancedCount = r.count;
        r.balancedLongest = r.longest;
        r.balancedLongestEndDz = r.longestEndDz;
    }
    return true;
}

// Takes a run's vertices eight at a time, as takeCentredVertex() would take
// them one by one: the window narrowed by each vertex's bounds, the
// integral and the counts (when counts is not null) summed in order, and
// each vertex tested for balance; the run state ends as that walk leaves
// it, bit for bit. Whole blocks go while the window stays feasible at their
// last vertex; of the block where the segment ends, the vertices before the
// one that ends it. Returns how many vertices it took: the run's last
// vertices short of a block are left to the walk. Each vertex's band is
// the frame's, or bands[i] when bands is not null (the walk's frame then
// withBand(frame.slopes, bands[i]), its margin the frame's). Preconditions
// as takeSlopeBlocks()'s (depths never fall, every depth difference from the
// origin in [kLeastFastDepth, kMostFastDepth]).
DSM_TESTED_INTERNAL std::size_t takeCentredBlocks(const float* z, const float* v, const double* bands,
                                                  const std::uint32_t* counts, std::size_t n,
                                                  const CentredFrame& frame, CentredRun& run);
DSM_TESTED_INTERNAL std::size_t takeCentredBlocks(const float* z, const double* v, const double* bands,
                                                  const std::uint32_t* counts, std::size_t n,
                                                  const CentredFrame& frame, CentredRun& run);

// takeCentredBlocks() for RGB with one band for the run (values[i * 3 + c]),
// as takeCentredVertex<3>() would take the vertices one by one: a vertex is
// taken while every channel's window stays feasible, and is balanced where
// every channel is. Same preconditions and result.
DSM_TESTED_INTERNAL std::size_t takeCentredRgbBlocks(const float* z, const float* v, const std::uint32_t* counts,
                                                     std::size_t n, const CentredFrameOf<3>& frame,
                                                     CentredRunOf<3>& run);
DSM_TESTED_INTERNAL std::size_t takeCentredRgbBlocks(const float* z, const double* v, const std::uint32_t* counts,
                                                     std::size_t n, const CentredFrameOf<3>& frame,
                                                     CentredRunOf<3>& run);

// takeSlopeBlocks(), takeCentredBlocks(), takeRgbSlopeBlocks() and
// takeCentredRgbBlocks() on the baseline instruction set, and on AVX2 (null
// where the library was built without it, or the processor lacks it): for the
// tests, which check that the two agree bit for bit.
using SlopeBlocksOfFloats = std::size_t (*)(const float*, const float*, const double*, const std::uint32_t*,
                                            std::size_t, const SlopeFrame&, double&, double&, std::uint64_t&);
using SlopeBlocksOfDoubles = std::size_t (*)(const float*, const double*, const double*, const std::uint32_t*,
                                             std::size_t, const SlopeFrame&, double&, double&, std::uint64_t&);
using CentredBlocksOfFloats = std::size_t (*)(const float*, const float*, const double*, const std::uint32_t*,
                                              std::size_t, const CentredFrame&, CentredRun&);
using CentredBlocksOfDoubles = std::size_t (*)(const float*, const double*, const double*, const std::uint32_t*,
                                               std::size_t, const CentredFrame&, CentredRun&);
using RgbBlocksOfFloats = std::size_t (*)(const float*, const float*, const std::uint32_t*, std::size_t,
                                          const SlopeFrame*, double*, double*, std::uint64_t&);
using RgbBlocksOfDoubles = std::size_t (*)(const float*, const double*, const std::uint32_t*, std::size_t,
                                           const SlopeFrame*, double*, double*, std::uint64_t&);
using CentredRgbBlocksOfFloats = std::size_t (*)(const float*, const float*, const std::uint32_t*, std::size_t,
                                                 const CentredFrameOf<3>&, CentredRunOf<3>&);
using CentredRgbBlocksOfDoubles = std::size_t (*)(const float*, const double*, const std::uint32_t*, std::size_t,
                                                  const CentredFrameOf<3>&, CentredRunOf<3>&);
struct SlopeBlockVariants {
    SlopeBlocksOfFloats floats;
    SlopeBlocksOfDoubles doubles;
    CentredBlocksOfFloats centredFloats;
    CentredBlocksOfDoubles centredDoubles;
    RgbBlocksOfFloats rgbFloats;
    RgbBlocksOfDoubles rgbDoubles;
    CentredRgbBlocksOfFloats centredRgbFloats;
    CentredRgbBlocksOfDoubles centredRgbDoubles;
};
DSM_TESTED_INTERNAL SlopeBlockVariants baselineSlopeBlocks();
DSM_TESTED_INTERNAL SlopeBlockVariants avx2SlopeBlocks();

}  // namespace dsm::detail
