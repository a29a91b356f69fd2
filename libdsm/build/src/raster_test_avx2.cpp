// The raster test compiled for AVX2, four lanes (this file alone is built with
// -mavx2; raster_test.cpp chooses it only on processors that have it).
#include <immintrin.h>

#include "raster_test_body.h"

namespace dsm::detail {

namespace {

using Double4 = double __attribute__((vector_size(32)));
using Mask4 = std::int64_t __attribute__((vector_size(32)));

std::uint64_t fourLanes(const double* xs, const double* ys, std::size_t n, const RasterTest& test) {
    return passingSamples<Double4, Mask4, 4>(xs, ys, n, test, [](const Mask4& m) {
        return static_cast<std::uint64_t>(_mm256_movemask_pd(reinterpret_cast<__m256d>(m)));
    });
}

}  // namespace

RasterTestFinder avx2RasterTestCompiled() { return &fourLanes; }

}  // namespace dsm::detail
