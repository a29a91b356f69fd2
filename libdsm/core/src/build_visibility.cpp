#include "dsm/build_visibility.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <vector>

#include "dsm/error.h"
#include "dsm/sweep.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

void checkOnePerRay(std::size_t transmittances, std::size_t rays) {
    if (transmittances != rays)
        throw Error(ErrorCode::argument, detail::concat("pixel: ", transmittances, " transmittances but ", rays, " rays"));
}

}  // namespace

struct PixelBuilder::Impl {
    explicit Impl(const CompressorOptions& o) : options(o), compressor(o), swept(o.channels) {}

    // taus[k] = the transmittance of rays[k] beyond zStart, prepared for the
    // sweep in inputs[k].
    void buildTransmittances(Span<const SampleRay> rays, float zStart, PixelTimings* timings) {
        const auto start = Clock::now();
        if (taus.size() < rays.size()) taus.resize(rays.size());  // never shrunk: each keeps its storage
        for (std::size_t k = 0; k < rays.size(); ++k) {
            try {
                transmittances.build(rays[k], options.channels, options.keepCounts, zStart, taus[k]);
            } catch (const Error& e) {
                throw Error(e.code(), detail::concat("ray ", k, ": ", e.what()));
            }
        }
        prepare(Span<const VisibilityFunction>(taus.data(), rays.size()));
        if (timings) timings->transmittanceSeconds += since(start);
    }

    template <class Function>
    void prepare(Span<const Function> functions) {
        if (prepared.size() < functions.size()) prepared.resize(functions.size());  // never shrunk, as taus
        inputs.clear();
        for (std::size_t k = 0; k < functions.size(); ++k) {
            prepared[k].assign(VisibilityView(functions[k]));
            inputs.push_back(&prepared[k]);
        }
    }

    void run(Span<const SweepInput* const> first, Span<const SampleRay> rays, Span<const double> weights,
             VisibilityFunction& out, PixelTimings* timings) {
        // An error may have left the compressor inside a function: drop that.
        if (compressorInUse) compressor.finish();
        compressorInUse = true;
        Span<const SweepInput* const> layerInputs = first;
        // One clock reading per boundary between stages (each reading is a
        // percent or two of a build's time).
        Clock::time_point mark = timings ? Clock::now() : Clock::time_point{};
        const auto lap = [&](double& seconds) {
            const Clock::time_point now = Clock::now();
            seconds += std::chrono::duration<double>(now - mark).count();
            mark = now;
        };
        for (;;) {
            if (timings)
                for (const SweepInput* tau : layerInputs) timings->transmittanceVertices += tau->vertexCount();
            swept.clear();
            sweeper.sweep(layerInputs, weights, options.channels, swept);
            if (timings) lap(timings->sweepSeconds);
            // The sweep's output is valid input: the compressor takes it
            // until it refuses a vertex (a layer ended).
            const bool complete =
                compressor.pushValid(swept.depths(), swept.values(), swept.counts(), swept.size()) == swept.size();
            if (complete) break;
            if (timings) lap(timings->compressionSeconds);
            // The compressor ended a layer: everything up to its depth is in
            // it; the next layer sees what lies beyond.
            buildTransmittances(rays, compressor.layerEndDepth(), timings);
            if (timings) mark = Clock::now();
            layerInputs = inputs;
        }
        compressor.finish(out);
        compressorInUse = false;
        if (timings) lap(timings->compressionSeconds);
    }

    VisibilityFunction run(Span<const SweepInput* const> first, Span<const SampleRay> rays, Span<const double> weights,
                           PixelTimings* timings) {
        VisibilityFunction result;
        run(first, rays, weights, result, timings);
        return result;
    }

    CompressorOptions options;
    Compressor compressor;
    bool compressorInUse = false;
    TransmittanceBuilder transmittances;
    Sweeper sweeper;
    // The sweep's output in double precision, so that compressing it later is
    // the same as compressing the stream directly (the stages are separated
    // only to time them).
    SweptVertices swept;
    std::vector<VisibilityFunction> taus;
    std::vector<SweepInput> prepared;
    std::vector<const SweepInput*> inputs;
};

PixelBuilder::PixelBuilder(const CompressorOptions& options) : impl_(std::make_unique<Impl>(options)) {}
PixelBuilder::~PixelBuilder() = default;
PixelBuilder::PixelBuilder(PixelBuilder&&) noexcept = default;
PixelBuilder& PixelBuilder::operator=(PixelBuilder&&) noexcept = default;

VisibilityFunction PixelBuilder::build(Span<const SampleRay> rays, Span<const double> weights,
                                       PixelTimings* timings) {
    impl_->buildTransmittances(rays, -std::numeric_limits<float>::infinity(), timings);
    return impl_->run(impl_->inputs, rays, weights, timings);
}

VisibilityFunction PixelBuilder::build(Span<const VisibilityView> transmittances, Span<const SampleRay> rays,
                                       Span<const double> weights, PixelTimings* timings) {
    checkOnePerRay(transmittances.size(), rays.size());
    impl_->prepare(transmittances);
    return impl_->run(impl_->inputs, rays, weights, timings);
}

VisibilityFunction PixelBuilder::build(Span<const SweepInput* const> transmittances, Span<const SampleRay> rays,
                                       Span<const double> weights, PixelTimings* timings) {
    VisibilityFunction result;
    build(transmittances, rays, weights, result, timings);
    return result;
}

void PixelBuilder::build(Span<const SweepInput* const> transmittances, Span<const SampleRay> rays,
                         Span<const double> weights, VisibilityFunction& out, PixelTimings* timings) {
    checkOnePerRay(transmittances.size(), rays.size());
    impl_->run(transmittances, rays, weights, out, timings);
}

VisibilityFunction buildVisibility(Span<const SampleRay> rays, Span<const double> weights,
                                   const CompressorOptions& options, PixelTimings* timings) {
    return PixelBuilder(options).build(rays, weights, timings);
}

DSM_NAMESPACE_END
