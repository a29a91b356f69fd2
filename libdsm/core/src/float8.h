// Eight floats as one SIMD value (internal), through the compiler's vector
// extensions: one AVX register in code compiled for AVX, two SSE (or NEON)
// registers otherwise; and the lane mask a comparison of two of them gives.
// For tests of eight rays at a time.
#pragma once

#include <cstdint>
#include <cstring>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

// The helpers are always inlined, into code compiled for AVX or not: eight
// floats never cross a call, so how a call would pass them (GCC's -Wpsabi
// note, silenced where this is included) does not matter.

namespace dsm::detail {

using Float8 = float __attribute__((vector_size(32)));
using Mask8 = std::int32_t __attribute__((vector_size(32)));

[[gnu::always_inline]] inline Float8 splat8(float v) { return Float8{v, v, v, v, v, v, v, v}; }

[[gnu::always_inline]] inline Float8 load8(const float* p) {
    Float8 v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

/// The lane-wise minimum and maximum (the processor's min and max: for
/// ordered operands, which is all these take).
[[gnu::always_inline]] inline Float8 min8(Float8 a, Float8 b) { return a < b ? a : b; }
[[gnu::always_inline]] inline Float8 max8(Float8 a, Float8 b) { return a > b ? a : b; }

/// Bit l set when lane l of a comparison is true.
[[gnu::always_inline]] inline int laneMask(Mask8 m) {
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
