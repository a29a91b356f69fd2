// Four floats in one SIMD register (internal): SSE on x86-64, NEON on
// AArch64, through the compiler's vector extensions, and the lane mask a
// comparison of two of them gives. For tests of four rays at a time.
#pragma once

#include <cstdint>
#include <cstring>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace dsm::detail {

using Float4 = float __attribute__((vector_size(16)));
using Mask4 = std::int32_t __attribute__((vector_size(16)));

inline Float4 splat4(float v) { return Float4{v, v, v, v}; }

inline Float4 load4(const float* p) {
    Float4 v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

/// The lane-wise minimum and maximum (the processor's min and max: for
/// ordered operands, which is all these take).
inline Float4 min4(Float4 a, Float4 b) { return a < b ? a : b; }
inline Float4 max4(Float4 a, Float4 b) { return a > b ? a : b; }

/// Bit l set when lane l of a comparison is true.
inline int laneMask(Mask4 m) {
#ifdef __SSE2__
    return _mm_movemask_ps(reinterpret_cast<__m128>(m));
#else
    return static_cast<int>((m[0] & 1) | (m[1] & 2) | (m[2] & 4) | (m[3] & 8));
#endif
}

}  // namespace dsm::detail
