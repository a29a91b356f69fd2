// The streaming interface between producers of visibility vertices (the sweep)
// and their consumers (the compressor, or a plain collector).
#pragma once

#include <cstdint>

#include "dsm/visibility.h"

namespace dsm {

/// Receives vertices one at a time in z order. Values are double so that the
/// consumer decides how to round to the stored float32.
class VertexSink {
public:
    virtual ~VertexSink() = default;
    /// Takes vertex (z, values[0..channels)) carrying `count` samples. Returns
    /// false to refuse this vertex and all that follow: the producer stops.
    virtual bool push(float z, const double* values, std::uint32_t count) = 0;
};

/// A sink that stores every vertex it is given, rounded to float, unchanged
/// otherwise. Used for uncompressed functions and as a test oracle.
class CollectingSink final : public VertexSink {
public:
    explicit CollectingSink(VisibilityFunction& out) : out_(out) {}
    bool push(float z, const double* values, std::uint32_t count) override;

private:
    VisibilityFunction& out_;
};

}  // namespace dsm
