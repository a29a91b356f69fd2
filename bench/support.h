// Shared pieces of the benchmark programs: realistic inputs, a sink that keeps
// the sweep's double values, and a runner that records every measurement so a
// program can print ratios of benchmarks measured in the same run.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <dsm/dsm.h>

namespace dsm::bench {

// ---------------------------------------------------------------- inputs

/// The sample rays of one pixel, owning their hits and volume samples.
struct PixelRays {
    std::vector<std::vector<SurfaceHit>> hits;
    std::vector<std::vector<VolumeSample>> volume;
    std::vector<double> weights;  // filter weights, one per ray

    std::vector<SampleRay> rays() const;
    /// transmittance() of every ray.
    std::vector<VisibilityFunction> transmittances(int channels, bool withCounts) const;
};

/// n rays through hair: each ray crosses `minHits`..`maxHits` semi-transparent
/// strands (opacity 0.05..0.6) at random depths in [1, 3). With `rgb`, each
/// strand absorbs the channels differently. A fraction `volumeFraction` of the
/// rays also crosses a patch of smoke (6..16 extinction samples over a random
/// interval inside [0.5, 3.5)). Weights are random in [0.25, 1], like a
/// filter's. Deterministic for a given seed.
PixelRays hairPixel(std::size_t n, int minHits, int maxHits, double volumeFraction, bool rgb, std::uint64_t seed);

/// The uncompressed visibility function of a pixel: the sweep of its
/// transmittances into a CollectingSink (what the compressor receives).
VisibilityFunction sweptVisibility(const PixelRays& pixel, int channels);

/// A smooth volume-like function: V(z) = exp(-0.6 z) sampled at `samples`
/// evenly spaced depths in [0, 10].
VisibilityFunction smoothDecay(std::size_t samples);

// ---------------------------------------------------------------- sinks

/// Keeps every vertex it is pushed with its double values (no float rounding),
/// so two producers can be compared to 1e-9. Storage is reused across clear().
class DoubleSink final : public VertexSink {
public:
    struct Vertex {
        float z;
        double v[kMaxChannels];
        std::uint32_t count;
    };
    explicit DoubleSink(int channels) : channels_(channels) {}
    bool push(float z, const double* values, std::uint32_t count) override;
    void clear() { vertices_.clear(); }
    const std::vector<Vertex>& vertices() const { return vertices_; }
    int channels() const { return channels_; }

private:
    int channels_;
    std::vector<Vertex> vertices_;
};

/// Compares two vertex streams as functions: the same distinct depths, and at
/// each depth the left limit (first vertex), the value (last vertex) and the
/// summed count agree. Returns an empty string when they agree within
/// `tolerance`, else a description of the first difference. `maxDiff` receives
/// the largest value difference seen.
std::string compareStreams(const DoubleSink& a, const DoubleSink& b, double tolerance, double& maxDiff);

// ---------------------------------------------------------------- runner

/// Median CPU time per iteration of one benchmark over its repetitions, and
/// its user counters (from the last repetition).
struct Measurement {
    std::vector<double> cpuSeconds;  // per iteration, one entry per repetition
    std::map<std::string, double> counters;
    double median() const;
    /// (max - min) / median over the repetitions, in percent: the noise.
    double spreadPercent() const;
};
using Results = std::map<std::string, Measurement>;

/// Command line of a benchmark program. Our own flag:
///   --smoke   run every benchmark once, briefly (for ctest: proves the program
///             runs; the numbers mean nothing)
/// Defaults (overridable with the usual --benchmark_* flags, later flags win):
///   --benchmark_min_time=0.3 --benchmark_repetitions=5
///   --benchmark_enable_random_interleaving=true
struct Arguments {
    bool smoke = false;
    std::vector<std::string> benchmarkArgs;  // argv[0], defaults, then the user's
};
Arguments parseArguments(int argc, char** argv);

/// Initializes Google Benchmark with `args`, runs the registered benchmarks
/// and records every repetition in `results`, keyed by the registered name.
/// The console shows the usual table (only the aggregates with repetitions).
/// Returns false on unknown arguments or when a benchmark reported an error.
bool runBenchmarks(const Arguments& args, Results& results);

/// "12.3 M/s"-style formatting helpers for the summary tables.
std::string formatRate(double perSecond, const char* unit);
std::string formatTime(double seconds);

}  // namespace dsm::bench
