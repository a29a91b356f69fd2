// A primitive's raster test over a pixel's samples (internal): the scanline
// hider's innermost loop, which lets through the samples whose rays may cross
// the primitive, for the exact crossing test to decide. Built twice, for two
// lanes (SSE2, any x86-64 or NEON processor) and for four (AVX2, chosen at run
// time where the processor has it); both let through the same samples.
#pragma once

#include <cstddef>
#include <cstdint>

#include "tested_internal.h"

namespace dsm::detail {

/// What a primitive's raster test reads. For a still ribbon (radius2 >= 0):
/// its projected axis (x0, y0) + s (dx, dy), s in [0, 1], with invLength2 =
/// 1 / (dx² + dy²) (0 for an axis of no length), and the squared raster
/// distance from the axis within which a sample's ray may pass the ribbon.
/// For any other primitive (radius2 < 0): its raster bounds
/// [boundsX0, boundsX1] x [boundsY0, boundsY1].
struct RasterTest {
    double boundsX0, boundsY0, boundsX1, boundsY1;
    double x0, y0, dx, dy, invLength2, radius2;
};

/// How many positions past the n it tests a RasterTestFinder reads.
inline constexpr std::size_t kRasterTestOverread = 3;

/// Bit j set for each sample j < n <= 64 (raster position xs[j], ys[j])
/// that `test` lets through: not farther than the ribbon's radius from its
/// axis, or inside the bounds. Reads xs and ys up to kRasterTestOverread
/// positions past n (bits dropped). Several samples at a time without a
/// branch: the pixels a primitive's bounds take in are whole, so most of
/// their samples fail and the rest pass in no order a predictor learns.
using RasterTestFinder = std::uint64_t (*)(const double* xs, const double* ys, std::size_t n,
                                           const RasterTest& test);

/// The variant for this processor: four lanes where it has AVX2, else two.
DSM_TESTED_INTERNAL RasterTestFinder rasterTestFinder();
/// Each variant, for the test comparing them: two lanes; four lanes, or null
/// where not built or the processor lacks AVX2.
DSM_TESTED_INTERNAL RasterTestFinder baselineRasterTest();
DSM_TESTED_INTERNAL RasterTestFinder avx2RasterTest();

}  // namespace dsm::detail
