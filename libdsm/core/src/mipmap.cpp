#include "mipmap.h"

#include <algorithm>
#include <vector>

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

void FunctionAverager::average(std::span<const VisibilityView> children, std::span<const double> weights,
                               double tolerance, bool withCounts, bool centred, VisibilityFunction& out) {
    int channels = 1;
    bool anyVertices = false;
    for (const VisibilityView& c : children) {
        channels = std::max(channels, c.channels());
        anyVertices = anyVertices || !c.empty();
    }
    if (!anyVertices) {
        out.reset(1, withCounts);
        return;
    }
    // A child of one layer with the channels wanted (and no counts to drop)
    // is its own light-centre function: it is swept as it is, the others
    // through a copy.
    copies_.clear();
    inputs_.clear();
    if (prepared_.size() < children.size()) prepared_.resize(children.size());  // never shrunk: each keeps its storage
    for (std::size_t k = 0; k < children.size(); ++k) {
        const VisibilityView& c = children[k];
        if (c.layerCount() == 1 && c.channels() == channels && (withCounts || !c.hasCounts())) {
            prepared_[k].assign(c);
        } else {
            copies_.push_back(lightCentreFunction(c, channels, withCounts));
            prepared_[k].assign(copies_.back().view());
        }
        inputs_.push_back(&prepared_[k]);
    }
    CompressorOptions options;
    options.tolerance = tolerance;
    options.centred = centred;
    options.channels = channels;
    options.keepCounts = withCounts;
    Compressor& compressor = compressorFor(options);
    // The sweep's output is valid compressor input (depths in order, values
    // in [0, 1] and never rising), taken as a run: the same result as
    // pushing it vertex by vertex through the checks.
    SweptVertices& swept = swept_[channels == 1 ? 0 : 1];
    swept.clear();
    sweeper_.sweep(Span<const SweepInput* const>(inputs_.data(), inputs_.size()),
                   Span<const double>(weights.data(), weights.size()), channels, swept);
    compressor.pushValid(swept.depths(), swept.values(), swept.counts(), swept.size());
    compressor.finish(out);
}

Compressor& FunctionAverager::compressorFor(const CompressorOptions& options) {
    for (auto& [kept, compressor] : compressors_)
        if (kept.tolerance == options.tolerance && kept.centred == options.centred &&
            kept.channels == options.channels && kept.keepCounts == options.keepCounts)
            return *compressor;
    compressors_.emplace_back(options, std::make_unique<Compressor>(options));
    return *compressors_.back().second;
}

DSM_NAMESPACE_END
