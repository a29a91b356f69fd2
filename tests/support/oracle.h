// Test oracles: slow, obviously correct evaluations that the library's fast
// paths are checked against. Never used by the library itself.
#pragma once

#include <dsm/dsm.h>

#include <span>
#include <vector>

namespace dsm::test {

/// V(z-) of one layer of `f`: the limit from below (the value before any step
/// at z), by linear scan. Layer 0 of a layered function is returned as is
/// (without the 0 beyond its end).
double leftLimit(const VisibilityFunction& f, double z, int channel = 0, std::size_t layer = 0);
/// V(z) of one layer by linear scan (right-continuous, as documented).
double valueAt(const VisibilityFunction& f, double z, int channel = 0, std::size_t layer = 0);

/// The weighted average of `inputs` evaluated directly at every distinct input
/// depth (left limit and value), O(n^2): the oracle for dsm::sweep. Values are
/// kept in double.
struct ExactVertex {
    double z;
    double left[kMaxChannels];
    double right[kMaxChannels];
};
std::vector<ExactVertex> naiveAverage(std::span<const VisibilityFunction> inputs, std::span<const double> weights,
                                      int channels);

/// Largest |approx - exact| over every vertex of `exact` (left limits and
/// values) and every segment midpoint of `exact` and `approx`, for one layer.
/// `exact` is taken as given (float values, linear between vertices).
double maxError(const VisibilityFunction& exact, const VisibilityFunction& approx, std::size_t layer = 0);

/// Same, with a per-channel mapping: compares channel c of `exact` with
/// channel min(c, approx.channels() - 1) of `approx` (for monochrome results of
/// RGB input).
double maxErrorAllChannels(const VisibilityFunction& exact, const VisibilityFunction& approx, std::size_t layer = 0);

}  // namespace dsm::test
