// Eight floats as one SIMD value (internal), through the compiler's vector
// extensions: one AVX register in code compiled for AVX, two SSE (or NEON)
// registers otherwise. For tests of eight rays at a time. Keep them in local
// variables and pass them by reference: a call that takes or returns one by
// value is made differently with and without AVX, and clang refuses it in
// code built without.
#pragma once

#include <cstdint>
#include <cstring>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace dsm::detail {

using Float8 = float __attribute__((vector_size(32)));
using Mask8 = std::int32_t __attribute__((vector_size(32)));

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
