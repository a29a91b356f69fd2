// SIMD values through the compiler's vector extensions (internal), for
// branch-free tests of several lanes at once, and the lane mask a comparison
// of two of them gives:
//  - two doubles, one SSE2 (NEON) register: per-vertex and per-sample tests
//    two at a time;
//  - eight floats, one AVX register in code compiled for AVX, two SSE (NEON)
//    registers otherwise: tests of eight rays at a time. Keep them in local
//    variables and pass them by reference: a call that takes or returns one
//    by value is made differently with and without AVX, and clang refuses it
//    in code built without.
#pragma once

#include <cstdint>
#include <cstring>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace dsm::detail {

using Double2 = double __attribute__((vector_size(16)));
using Mask2 = std::int64_t __attribute__((vector_size(16)));

using Float8 = float __attribute__((vector_size(32)));
using Mask8 = std::int32_t __attribute__((vector_size(32)));

/// Bit l set when lane l of a comparison is true.
inline int laneMask(Mask2 m) {
#ifdef __SSE2__
    return _mm_movemask_pd(reinterpret_cast<__m128d>(m));
#else
    return static_cast<int>((m[0] & 1) | (m[1] & 2));
#endif
}

/// Bit l set when lane l of a comparison is true.
inline int laneMask(const Mask8& m) {
#ifdef __SSE2__
    __m128 low, high;
    std::memcpy(&low, &m, sizeof low);
    std::memcpy(&high, reinterpret_cast<const char*>(&m) + sizeof low, sizeof high);
    return _mm_movemask_ps(low) | _mm_movemask_ps(high) << 4;
#else
    int bits = 0;
    for (int l = 0; l < 8; ++l) bits |= (m[l] & 1) << l;
    return bits;
#endif
}

}  // namespace dsm::detail
