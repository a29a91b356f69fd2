// The naive O(n^2) weighted average of n transmittance functions, the baseline
// that Lokovic & Veach §5.1 describe before their sweep: sort all input
// vertices, and at each distinct depth evaluate all n functions directly.
// Lives in bench/ only, as the reference the sweep is measured against.
#pragma once

#include <span>

#include <dsm/dsm.h>

namespace dsm::bench {

/// Streams V(z) = sum_k w_k tau_k(z) / sum_k w_k into `sink` with the same
/// output convention as dsm::sweep(): at each distinct input depth a vertex
/// with the left limit V(z-), then a second vertex with V(z) when the two
/// differ; the summed input counts at that depth ride on the last vertex.
///
/// Each tau_k is evaluated with two binary searches per depth (left limit and
/// value), so the cost is O(D n log m) for D distinct depths, n inputs of at
/// most m vertices: O(n^2) when D grows like n. No input checks: the inputs
/// are single-layer, share `channels`, and the weights are positive.
void naiveAverage(std::span<const VisibilityFunction> inputs, std::span<const double> weights, int channels,
                  VertexSink& sink);

}  // namespace dsm::bench
