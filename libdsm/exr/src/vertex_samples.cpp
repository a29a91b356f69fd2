// Vertex samples (spec/exr-interop.md "Vertex samples").
#include "vertex_samples.h"

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN
namespace exr {

std::vector<std::string> vertexValueChannels(int channels) {
    if (channels == 1) return {kMonoValueChannel};
    return {kRgbValueChannels[0], kRgbValueChannels[1], kRgbValueChannels[2]};
}

void appendVertexSamples(const VisibilityView& function, int channels, std::vector<DeepSample>& samples,
                         std::vector<VertexFields>& fields) {
    fields.assign(samples.size(), VertexFields{});
    for (std::size_t layer = 0; layer < function.layerCount(); ++layer)
        for (std::size_t i = function.layerBegin(layer); i < function.layerEnd(layer); ++i) {
            DeepSample s;
            s.z = s.zBack = function.z(i);
            samples.push_back(s);
            VertexFields f;
            f.layer = std::uint32_t(layer + 1);
            f.count = function.count(i);
            for (int c = 0; c < channels; ++c)
                f.value[std::size_t(c)] = function.value(i, function.channels() == 1 ? 0 : c);
            fields.push_back(f);
        }
}

VisibilityFunction functionFromVertexSamples(std::span<const DeepSample> samples,
                                             std::span<const VertexFields> fields, int channels, bool withCounts) {
    VisibilityFunction f(channels, withCounts);
    std::uint32_t layer = 0;
    for (std::size_t i = 0; i < samples.size() && i < fields.size(); ++i) {
        const VertexFields& v = fields[i];
        if (v.layer == 0) continue;
        if (layer != 0 && v.layer != layer) {
            if (v.layer != layer + 1)
                throw Error(ErrorCode::corrupt, detail::concat("sample ", i, ": layer ", v.layer - 1,
                                                               " follows layer ", layer - 1));
            f.beginLayer();
        } else if (layer == 0 && v.layer != 1) {
            throw Error(ErrorCode::corrupt,
                        detail::concat("sample ", i, ": the first vertex is in layer ", v.layer - 1, ", not 0"));
        }
        layer = v.layer;
        f.append(samples[i].z, v.value.data(), v.count);
    }
    f.validate();
    return f;
}

}  // namespace exr
DSM_NAMESPACE_END
