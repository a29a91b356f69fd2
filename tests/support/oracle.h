// Test oracles: slow, obviously correct evaluations that the library's fast
// paths are checked against. Never used by the library itself.
#pragma once

#include <dsm/dsm.h>

#include <array>
#include <cstdint>
#include <limits>
#include <random>
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

/// The exact (double) form of one layer of a stored function: one ExactVertex
/// per distinct depth, O(n).
std::vector<ExactVertex> exactVertices(const VisibilityFunction& f, std::size_t layer = 0);

/// Largest |approx - exact| for a double-valued reference: at every vertex of
/// `exact` (left limit and value), the midpoints between them, before the first
/// and beyond the last. Channel c of `exact` is compared with channel
/// min(c, approx.channels() - 1). Binary search: O(n log m), for big functions.
double maxErrorExact(std::span<const ExactVertex> exact, const VisibilityFunction& approx, int channels,
                     std::size_t layer = 0);

/// Shape of the functions randomMonotone() makes.
struct RandomShape {
    double stepProbability = 0.3;  // a vertex repeats the previous depth (a vertical step)
    double zeroProbability = 0.02; // a channel drops straight to 0
    float depthGrid = 0.0f;        // > 0: depths on this grid (shared between functions)
    float maxGap = 1.0f;           // largest depth increment
    std::uint32_t maxCount = 3;    // counts uniform in [0, maxCount]
};

/// A random valid single-layer function: depths with repeats, values
/// non-increasing in [0, 1] (as floats), channels independent.
VisibilityFunction randomMonotone(std::mt19937_64& rng, std::size_t vertices, int channels, bool withCounts,
                                  const RandomShape& shape = {});

/// Direct evaluation of one ray's transmittance (LV §3.2): the product of
/// (1 - opacity) over hits at depth <= z (< z for the left limit), times the
/// volume transmittance, exact at the samples (trapezoid optical depth) and
/// linear between them.
double rayTransmittance(const SampleRay& ray, double z, int channel, bool leftLimit = false);

/// A sink that keeps every vertex in double, for comparing the sweep with
/// naiveAverage() beyond float precision. Refuses vertices deeper than
/// `refuseBeyond`.
struct RecordingSink final : VertexSink {
    struct Vertex {
        float z;
        std::array<double, kMaxChannels> v;
        std::uint32_t count;
    };
    std::vector<Vertex> vertices;
    float refuseBeyond = std::numeric_limits<float>::infinity();
    bool push(float z, const double* values, std::uint32_t count) override;
    int channels = 1;
};

}  // namespace dsm::test
