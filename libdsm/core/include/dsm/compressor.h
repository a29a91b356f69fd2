// Greedy L-infinity compression of visibility functions (Lokovic & Veach 2000,
// §3.3), with sample counts and multilayer resets (Xie et al. 2007, §5.1).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

#include "dsm/version.h"
#include "dsm/vertex_sink.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

struct CompressorOptions {
    /// The L-infinity tolerance epsilon, >= 0. 0 keeps every vertex except
    /// collinear ones; values >= 1 reduce any function to one segment (two
    /// vertices, three for some RGB input), still within the bound.
    double tolerance = 0.0;
    /// Channels of the input: 1, or 3 for RGB.
    int channels = 1;
    /// Keep per-vertex sample counts in the output.
    bool keepCounts = false;
    /// Maximum number of layers K >= 1. With K > 1 (a multilayer transparent
    /// shadow map) the compressor ends a layer when the visibility falls to the
    /// tolerance or below in every channel, and asks its producer, by refusing
    /// the next deeper vertex, to restart behind that depth with V = 1. At most
    /// K - 1 such resets happen; the last layer runs to the end.
    int maxLayers = 1;
    /// For RGB input: store a monochrome function when the channels agree
    /// within the tolerance everywhere (Lokovic & Veach §5.2).
    bool allowMonochrome = true;
    /// Centred segments: each segment's line is chosen, and where needed the
    /// segment ended early, so that its signed error against the input
    /// averages to at most a tenth of the tolerance, its end lies within that
    /// of the input, and so does its value where a plateau it takes in ends
    /// (a stretch between input vertices of at least half the segment's
    /// depth: a receiver behind a semi-transparent surface reads it there;
    /// of those lines it takes the one passing nearest the input there).
    /// Lokovic & Veach's greedy rule (false) lets a segment along a plateau
    /// tilt into the fall that follows it, so plateaus behind semi-transparent
    /// surfaces read too dark. Costs larger maps (docs/dsm-build.md measures
    /// both); the L-infinity bound is the same.
    bool centred = false;
};

/// Streaming compressor: push() input vertices in z order (a VertexSink), then
/// finish() and take the result. Constant working state per layer, O(1) per
/// input vertex.
///
/// Guarantee (for input vertices that pass validation):
///  - |V'(z) - V(z)| <= max(epsilon, 2^-25) for every z, where V' is the
///    output *as stored* in float32 and V is the input as given; per layer, and
///    for the light-centre function. The 2^-25 term is the float32 rounding of
///    double input values; when the input values are float32 numbers already,
///    the bound is epsilon itself, and epsilon = 0 is lossless.
///  - Output depths are a subset of input depths.
///  - Output values lie in [0, 1] and never increase within a layer.
///  - Output counts sum to the input counts (when counts are kept).
///  - With RGB input, a monochrome result (when allowed and chosen) obeys the
///    same bound in every input channel.
///
/// Input checks: z finite, >= 0, non-decreasing; values finite, in [0, 1],
/// non-increasing within a layer. A violation throws dsm::Error naming the
/// input vertex index, channel and value; the compressor is then in an
/// unspecified state until finish() (whose result is to be dropped) resets it.
/// Bad options throw dsm::Error from the constructor.
///
/// Thread safety: not thread-safe; one compressor per thread (it holds the
/// state of the function being compressed). Separate compressors are
/// independent. compress() and autoTolerance() are thread-safe.
class DSM_API Compressor final : public VertexSink {
public:
    explicit Compressor(const CompressorOptions& options);
    ~Compressor() override;
    Compressor(const Compressor&) = delete;
    Compressor& operator=(const Compressor&) = delete;

    bool push(float z, const double* values, std::uint32_t count) override;
    /// Convenience for float input.
    bool push(float z, const float* values, std::uint32_t count);

    /// push() for input already known to pass the input checks (the library's
    /// own sweep, functions that passed validate()): the checks run only in
    /// debug builds. Invalid input then gives an unspecified (but memory-safe)
    /// result instead of an error.
    bool pushValid(float z, const double* values, std::uint32_t count);
    /// pushValid() over n vertices: depths z[i], values[i * channels + c],
    /// counts[i] (counts may be null: all 0). Returns how many it took: n, or
    /// fewer when it refused a vertex (as push() returning false).
    std::size_t pushValid(const float* z, const float* values, const std::uint32_t* counts, std::size_t n);
    std::size_t pushValid(const float* z, const double* values, const std::uint32_t* counts, std::size_t n);

    /// Ends the current layer and starts a new one at V = 1, for input that is
    /// already split into layers. Does not count against maxLayers.
    void beginLayer();

    /// Depth at which the last layer ended (valid after push() returned false).
    float layerEndDepth() const;
    /// Layers begun so far.
    int layersUsed() const;

    /// Closes the last segment and returns the compressed function. The
    /// compressor is then reset and may be reused.
    VisibilityFunction finish();
    /// finish() into `out`, whose storage the compressor keeps for the next
    /// function: a caller that hands the same functions back (a tile's pixels
    /// rebuilt tile after tile) allocates nothing once they have grown.
    void finish(VisibilityFunction& out);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// One-shot helper: compresses a stored function (all its layers, as layers).
DSM_API VisibilityFunction compress(const VisibilityFunction& input, double tolerance, bool allowMonochrome = true);

/// Lokovic & Veach's default tolerance 0.25 / sqrt(N) for N samples per pixel
/// (§4): half the expected noise 0.5 / sqrt(N) of N stratified samples.
DSM_API double autoTolerance(double samplesPerPixel);

DSM_NAMESPACE_END
