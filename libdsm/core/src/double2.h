// Two doubles in one SIMD register (internal): SSE2 on x86-64, NEON on
// AArch64, through the compiler's vector extensions, and the lane mask a
// comparison of two of them gives. For per-vertex and per-sample tests that
// are worth doing two at a time without a branch.
#pragma once

#include <cstdint>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace dsm::detail {

using Double2 = double __attribute__((vector_size(16)));
using Mask2 = std::int64_t __attribute__((vector_size(16)));

/// Bit l set when lane l of a comparison is true.
inline int laneMask(Mask2 m) {
#ifdef __SSE2__
    return _mm_movemask_pd(reinterpret_cast<__m128d>(m));
#else
    return static_cast<int>((m[0] & 1) | (m[1] & 2));
#endif
}

}  // namespace dsm::detail
