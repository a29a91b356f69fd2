// The weighted average of many piecewise-linear functions in O(n log n)
// (Lokovic & Veach 2000, §5.1, equation 1).
#pragma once

#include <memory>
#include <optional>

#include "dsm/span.h"
#include "dsm/version.h"
#include "dsm/vertex_sink.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// Streams V(z) = sum_k w_k tau_k(z) / sum_k w_k into `sink`, in z order.
///
/// Each input is read as a single-layer function (implicit 1 before its first
/// vertex, constant after its last). The sweep keeps the next vertex of every
/// input in a heap and tracks the output's value and slope, so each input vertex
/// costs O(log n). Vertical steps change the value, not the slope.
///
/// Output: one vertex per distinct input depth z carrying the left limit V(z-),
/// followed by a second vertex at the same z with V(z) when any input steps
/// there. The count of a depth (the sum of the counts of all input vertices at
/// it) rides on the last vertex emitted at that depth. The result is clamped to
/// [0, 1] and made non-increasing, which only removes rounding noise: it agrees
/// with the direct O(n^2) evaluation to about 1e-12.
///
/// Ties between inputs at one depth are taken in input order, so the output
/// is deterministic. Inputs must share one channel count (1 or 3) equal to
/// `channels`; weights must be finite, >= 0, with a positive sum. Throws
/// dsm::Error otherwise, naming the input index.
///
/// Returns the depth of the vertex the sink refused, or nothing when the sink
/// took every vertex.
DSM_API std::optional<float> sweep(Span<const VisibilityFunction> inputs, Span<const double> weights,
                           int channels, VertexSink& sink);

/// sweep() with its working memory (heap, per-input state) kept between
/// calls, for a caller that sweeps many pixels on one thread: once its buffers
/// have grown to the most inputs, sweeping allocates nothing. Same results and
/// errors as sweep(), over functions or views of them. Not thread-safe: one
/// per thread.
class DSM_API Sweeper {
public:
    Sweeper();
    ~Sweeper();
    Sweeper(Sweeper&&) noexcept;
    Sweeper& operator=(Sweeper&&) noexcept;

    std::optional<float> sweep(Span<const VisibilityFunction> inputs, Span<const double> weights, int channels,
                               VertexSink& sink);
    std::optional<float> sweep(Span<const VisibilityView> inputs, Span<const double> weights, int channels,
                               VertexSink& sink);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
