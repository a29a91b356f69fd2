#include "mipmap.h"

#include <algorithm>
#include <vector>

#include "dsm/compressor.h"
#include "dsm/sweep.h"

DSM_NAMESPACE_BEGIN

VisibilityFunction lightCentreFunction(const VisibilityView& f, int channels, bool withCounts) {
    VisibilityFunction out(channels, withCounts);
    const std::size_t end = f.lightEnd();
    out.reserve(end + 1);
    float v[kMaxChannels];
    for (std::size_t i = 0; i < end; ++i) {
        for (int c = 0; c < channels; ++c) v[c] = f.value(i, std::min(c, f.channels() - 1));
        out.append(f.z(i), v, f.count(i));
    }
    if (f.layerCount() > 1 && end > 0) {
        bool allZero = true;
        for (int c = 0; c < channels; ++c) allZero = allZero && out.value(end - 1, c) == 0.0f;
        if (!allZero) {
            std::fill(v, v + channels, 0.0f);
            out.append(f.z(end - 1), v, 0);
        }
    }
    return out;
}

VisibilityFunction averageFunctions(std::span<const VisibilityView> children, std::span<const double> weights,
                                    double tolerance, bool withCounts, bool centred) {
    int channels = 1;
    bool anyVertices = false;
    for (const VisibilityView& c : children) {
        channels = std::max(channels, c.channels());
        anyVertices = anyVertices || !c.empty();
    }
    if (!anyVertices) return VisibilityFunction(1, withCounts);
    // A child of one layer with the channels wanted (and no counts to drop)
    // is its own light-centre function: it is swept as it is, the others
    // through a copy.
    std::vector<VisibilityFunction> copies;
    copies.reserve(children.size());  // no reallocation: the views of the copies stay valid
    std::vector<VisibilityView> inputs;
    inputs.reserve(children.size());
    for (const VisibilityView& c : children) {
        if (c.layerCount() == 1 && c.channels() == channels && (withCounts || !c.hasCounts())) {
            inputs.push_back(c);
        } else {
            copies.push_back(lightCentreFunction(c, channels, withCounts));
            inputs.push_back(copies.back().view());
        }
    }
    CompressorOptions options;
    options.tolerance = tolerance;
    options.centred = centred;
    options.channels = channels;
    options.keepCounts = withCounts;
    Compressor compressor(options);
    Sweeper().sweep(Span<const VisibilityView>(inputs), weights, channels, compressor);
    return compressor.finish();
}

DSM_NAMESPACE_END
