// Vertex samples: a map's exact vertices (every layer, with counts) carried in
// a deep EXR as alpha-0 samples with dsm.* channels, which other readers
// ignore and our import reads back losslessly (internal;
// spec/exr-interop.md "Vertex samples").
#pragma once

#include <span>
#include <string>
#include <vector>

#include "deep_band.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN
namespace exr {

inline constexpr const char* kLayerChannel = "dsm.layer";
inline constexpr const char* kCountChannel = "dsm.count";
inline constexpr const char* kMonoValueChannel = "dsm.V";
inline constexpr const char* kRgbValueChannels[3] = {"dsm.VR", "dsm.VG", "dsm.VB"};

/// The value channels of a map of `channels` channels.
std::vector<std::string> vertexValueChannels(int channels);

/// Appends one sample per vertex of `function` (every layer, in storage
/// order) to `samples` and `fields`: Z = ZBack = the vertex depth, alpha 0,
/// layer L + 1, the vertex's count and values. `fields` gets a zeroed entry
/// for each sample already in `samples` first.
void appendVertexSamples(const VisibilityView& function, int channels, std::vector<DeepSample>& samples,
                         std::vector<VertexFields>& fields);

/// The function the vertex samples of a pixel describe (samples of layer 0
/// are ignored): vertices in file order, a new layer wherever the layer
/// number changes. Values and counts as stored; no compression. Throws
/// dsm::Error (without file or pixel) when they do not make a valid function.
VisibilityFunction functionFromVertexSamples(std::span<const DeepSample> samples,
                                             std::span<const VertexFields> fields, int channels, bool withCounts);

}  // namespace exr
DSM_NAMESPACE_END
