// The two steps of evaluating a piecewise-linear visibility function at a
// depth (internal): find the segment, interpolate on it. Shared by
// VisibilityView and the lookups so that both give bit-identical values.
#pragma once

#include <cstddef>

namespace dsm::detail {

/// Linear interpolation on the segment (za, va) -> (zb, vb) with za < zb.
inline double lerpSegment(double za, double va, double zb, double vb, double z) {
    const double t = (z - za) / (zb - za);
    return va + t * (vb - va);
}

/// The index of the first vertex among z[0, n) with z_k > q (n if none): the
/// std::upper_bound of q, with the same comparison, so a NaN q gives n.
/// Branch-free halving: the loop runs log2(n) times whatever q is, so the
/// processor has no search branch to mispredict. Compares in double, as the
/// evaluation does. The vertices are in non-decreasing depth order.
[[gnu::always_inline]] inline std::size_t firstDepthAbove(const float* z, std::size_t n, double q) {
    if (n == 0) return 0;
    const float* base = z;
    while (n > 1) {
        const std::size_t half = n / 2;
        base = q < static_cast<double>(base[half]) ? base : base + half;
        n -= half;
    }
    return static_cast<std::size_t>(base - z) + (q < static_cast<double>(*base) ? 0 : 1);
}

}  // namespace dsm::detail
