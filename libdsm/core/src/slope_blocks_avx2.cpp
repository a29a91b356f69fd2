// takeSlopeBlocks(), takeCentredBlocks(), takeRgbSlopeBlocks() and
// takeCentredRgbBlocks() compiled for AVX2 (this file alone is built with
// -mavx2; slope_blocks.cpp calls it only on processors that have it).
#include "slope_blocks.h"

#include "slope_blocks_body.h"

namespace dsm::detail {

SlopeBlockVariants avx2SlopeBlocksCompiled() {
    return {&slopeBlocks<float>,    &slopeBlocks<double>,    &centredBlocks<float>,
            &centredBlocks<double>,  &rgbSlopeBlocks<float>,  &rgbSlopeBlocks<double>,
            &centredRgbBlocks<float>, &centredRgbBlocks<double>};
}

}  // namespace dsm::detail
