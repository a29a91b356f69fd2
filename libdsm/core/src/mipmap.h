// Coarser pixels from finer ones: the functions of the mip levels.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "dsm/compressor.h"
#include "dsm/sweep.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

VisibilityFunction lightCentreFunction(const VisibilityView& f, int channels, bool withCounts);

/// Averages blocks of finer pixels into coarser ones: the children's
/// light-centre functions swept with the weights, then compressed to the
/// tolerance into `out` (Compressor::finish(VisibilityFunction&): out's
/// storage is kept for the next). Keeps its working memory (sweep,
/// compressors) from call to call, so that averaging into functions handed
/// back allocates nothing once they have grown. Not thread-safe: one per
/// thread.
class FunctionAverager {
public:
    void average(std::span<const VisibilityView> children, std::span<const double> weights, double tolerance,
                 bool withCounts, bool centred, VisibilityFunction& out);

private:
    Compressor& compressorFor(const CompressorOptions& options);

    Sweeper sweeper_;
    SweptVertices swept_[2] = {SweptVertices(1), SweptVertices(kMaxChannels)};
    std::vector<VisibilityFunction> copies_;
    std::vector<SweepInput> prepared_;
    std::vector<const SweepInput*> inputs_;
    // One compressor per set of options met (a level's tolerance, mono or RGB).
    std::vector<std::pair<CompressorOptions, std::unique_ptr<Compressor>>> compressors_;
};

DSM_NAMESPACE_END
