// The streaming interface between producers of visibility vertices (the sweep)
// and their consumers (the compressor, or a plain collector).
#pragma once

#include <cstdint>

#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// Receives vertices one at a time in z order. Values are double so that the
/// consumer decides how to round to the stored float32.
///
/// Thread safety: a sink receives one stream from one producer; libdsm's sinks
/// are not thread-safe, and a producer calls push() from one thread at a time.
class DSM_API VertexSink {
public:
    virtual ~VertexSink() = default;
    /// Takes vertex (z, values[0..channels)) carrying `count` samples. Returns
    /// false to refuse this vertex and all that follow: the producer stops.
    virtual bool push(float z, const double* values, std::uint32_t count) = 0;
};

/// A sink that stores every vertex it is given, rounded to float, unchanged
/// otherwise. Used for uncompressed functions and as a test oracle. Not
/// thread-safe: it appends to `out`, which must outlive it.
class DSM_API CollectingSink final : public VertexSink {
public:
    explicit CollectingSink(VisibilityFunction& out) : out_(out) {}
    bool push(float z, const double* values, std::uint32_t count) override;

private:
    VisibilityFunction& out_;
};

DSM_NAMESPACE_END
