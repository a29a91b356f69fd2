#include "dsm/build_visibility.h"

#include <chrono>
#include <limits>
#include <vector>

#include "dsm/error.h"
#include "dsm/sweep.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

// Keeps the sweep's output in double precision, so that compressing it later
// is the same as compressing the stream directly (the stages are separated
// only to time them).
class BufferingSink final : public VertexSink {
public:
    explicit BufferingSink(int channels) : channels_(channels) {}
    bool push(float z, const double* values, std::uint32_t count) override {
        z_.push_back(z);
        v_.insert(v_.end(), values, values + channels_);
        count_.push_back(count);
        return true;
    }
    void clear() {
        z_.clear();
        v_.clear();
        count_.clear();
    }
    // Feeds the compressor (the sweep's output is valid input) until it
    // refuses a vertex; returns false then.
    bool replay(Compressor& compressor) const {
        return compressor.pushValid(z_.data(), v_.data(), count_.data(), z_.size()) == z_.size();
    }

private:
    int channels_;
    std::vector<float> z_;
    std::vector<double> v_;
    std::vector<std::uint32_t> count_;
};

using Clock = std::chrono::steady_clock;
double since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

}  // namespace

VisibilityFunction buildVisibility(Span<const SampleRay> rays, Span<const double> weights,
                                   const CompressorOptions& options, PixelTimings* timings) {
    Compressor compressor(options);
    std::vector<VisibilityFunction> taus;
    taus.reserve(rays.size());
    BufferingSink swept(options.channels);
    float zStart = -std::numeric_limits<float>::infinity();
    for (;;) {
        auto start = Clock::now();
        taus.clear();
        for (std::size_t k = 0; k < rays.size(); ++k) {
            try {
                taus.push_back(transmittance(rays[k], options.channels, options.keepCounts, zStart));
            } catch (const Error& e) {
                throw Error(e.code(), detail::concat("ray ", k, ": ", e.what()));
            }
            if (timings) timings->transmittanceVertices += taus.back().size();
        }
        if (timings) {
            timings->transmittanceSeconds += since(start);
            start = Clock::now();
        }
        swept.clear();
        sweep(taus, weights, options.channels, swept);
        if (timings) {
            timings->sweepSeconds += since(start);
            start = Clock::now();
        }
        const bool complete = swept.replay(compressor);
        if (timings) timings->compressionSeconds += since(start);
        if (complete) break;
        // The compressor ended a layer: everything up to its depth is in it.
        zStart = compressor.layerEndDepth();
    }
    const auto start = Clock::now();
    VisibilityFunction result = compressor.finish();
    if (timings) timings->compressionSeconds += since(start);
    return result;
}

DSM_NAMESPACE_END
