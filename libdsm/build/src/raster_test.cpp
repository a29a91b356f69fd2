#include "raster_test.h"

#include "raster_test_body.h"
#include "simd_lanes.h"

namespace dsm::detail {

#ifdef DSM_RASTER_TEST_AVX2
RasterTestFinder avx2RasterTestCompiled();  // raster_test_avx2.cpp
#endif

namespace {

std::uint64_t twoLanes(const double* xs, const double* ys, std::size_t n, const RasterTest& test) {
    return passingSamples<Double2, Mask2, 2>(xs, ys, n, test,
                                             [](const Mask2& m) { return static_cast<std::uint64_t>(laneMask(m)); });
}

}  // namespace

RasterTestFinder baselineRasterTest() { return &twoLanes; }

RasterTestFinder avx2RasterTest() {
#ifdef DSM_RASTER_TEST_AVX2
    if (__builtin_cpu_supports("avx2")) return avx2RasterTestCompiled();
#endif
    return nullptr;
}

RasterTestFinder rasterTestFinder() {
    static const RasterTestFinder chosen = [] {
        const RasterTestFinder avx2 = avx2RasterTest();
        return avx2 ? avx2 : baselineRasterTest();
    }();
    return chosen;
}

}  // namespace dsm::detail
