#include "slope_blocks.h"

#include "slope_blocks_body.h"

namespace dsm::detail {

#ifdef DSM_SLOPE_BLOCKS_AVX2
SlopeBlockVariants avx2SlopeBlocksCompiled();  // slope_blocks_avx2.cpp
#endif

SlopeBlockVariants baselineSlopeBlocks() {
    return {&slopeBlocks<float>,    &slopeBlocks<double>,    &centredBlocks<float>,
            &centredBlocks<double>,  &rgbSlopeBlocks<float>,  &rgbSlopeBlocks<double>,
            &centredRgbBlocks<float>, &centredRgbBlocks<double>};
}

SlopeBlockVariants avx2SlopeBlocks() {
#ifdef DSM_SLOPE_BLOCKS_AVX2
    if (__builtin_cpu_supports("avx2")) return avx2SlopeBlocksCompiled();
#endif
    return {nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr};
}

namespace {

const SlopeBlockVariants& chosenSlopeBlocks() {
    static const SlopeBlockVariants chosen = [] {
        const SlopeBlockVariants avx2 = avx2SlopeBlocks();
        return avx2.floats ? avx2 : baselineSlopeBlocks();
    }();
    return chosen;
}

}  // namespace

std::size_t takeSlopeBlocks(const float* z, const float* v, const double* bands, const std::uint32_t* counts,
                            std::size_t n, const SlopeFrame& frame, double& lo, double& hi, std::uint64_t& count) {
    return chosenSlopeBlocks().floats(z, v, bands, counts, n, frame, lo, hi, count);
}

std::size_t takeSlopeBlocks(const float* z, const double* v, const double* bands, const std::uint32_t* counts,
                            std::size_t n, const SlopeFrame& frame, double& lo, double& hi, std::uint64_t& count) {
    return chosenSlopeBlocks().doubles(z, v, bands, counts, n, frame, lo, hi, count);
}

std::size_t takeRgbSlopeBlocks(const float* z, const float* v, const std::uint32_t* counts, std::size_t n,
                               const SlopeFrame* frames, double* lo, double* hi, std::uint64_t& count) {
    return chosenSlopeBlocks().rgbFloats(z, v, counts, n, frames, lo, hi, count);
}

std::size_t takeRgbSlopeBlocks(const float* z, const double* v, const std::uint32_t* counts, std::size_t n,
                               const SlopeFrame* frames, double* lo, double* hi, std::uint64_t& count) {
    return chosenSlopeBlocks().rgbDoubles(z, v, counts, n, frames, lo, hi, count);
}

std::size_t takeCentredBlocks(const float* z, const float* v, const double* bands, const std::uint32_t* counts,
                              std::size_t n, const CentredFrame& frame, CentredRun& run) {
    return chosenSlopeBlocks().centredFloats(z, v, bands, counts, n, frame, run);
}

std::size_t takeCentredBlocks(const float* z, const double* v, const double* bands, const std::uint32_t* counts,
                              std::size_t n, const CentredFrame& frame, CentredRun& run) {
    return chosenSlopeBlocks().centredDoubles(z, v, bands, counts, n, frame, run);
}

std::size_t takeCentredRgbBlocks(const float* z, const float* v, const std::uint32_t* counts, std::size_t n,
                                 const CentredFrameOf<3>& frame, CentredRunOf<3>& run) {
    return chosenSlopeBlocks().centredRgbFloats(z, v, counts, n, frame, run);
}

std::size_t takeCentredRgbBlocks(const float* z, const double* v, const std::uint32_t* counts, std::size_t n,
                                 const CentredFrameOf<3>& frame, CentredRunOf<3>& run) {
    return chosenSlopeBlocks().centredRgbDoubles(z, v, counts, n, frame, run);
}

}  // namespace dsm::detail
