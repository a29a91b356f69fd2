#include "support.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <sstream>

#include <unistd.h>

#include <benchmark/benchmark.h>

namespace dsm::bench {

// ---------------------------------------------------------------- inputs

std::vector<SampleRay> PixelRays::rays() const {
    std::vector<SampleRay> out;
    out.reserve(hits.size());
    for (std::size_t k = 0; k < hits.size(); ++k) out.push_back({hits[k], volume[k]});
    return out;
}

std::vector<VisibilityFunction> PixelRays::transmittances(int channels, bool withCounts) const {
    std::vector<VisibilityFunction> out;
    out.reserve(hits.size());
    for (const SampleRay& ray : rays()) out.push_back(transmittance(ray, channels, withCounts));
    return out;
}

PixelRays hairPixel(std::size_t n, int minHits, int maxHits, double volumeFraction, bool rgb, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<int> hitCount(minHits, maxHits);
    std::uniform_real_distribution<double> depth(1.0, 3.0);
    std::uniform_real_distribution<double> opacity(0.05, 0.6);
    std::uniform_real_distribution<double> tint(0.5, 1.0);
    std::uniform_real_distribution<double> weight(0.25, 1.0);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::uniform_int_distribution<int> volumeSamples(6, 16);

    PixelRays pixel;
    pixel.hits.resize(n);
    pixel.volume.resize(n);
    pixel.weights.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
        const int m = hitCount(rng);
        for (int i = 0; i < m; ++i) {
            SurfaceHit h;
            h.z = static_cast<float>(depth(rng));
            const double o = opacity(rng);
            if (rgb)
                h.opacity = {static_cast<float>(o), static_cast<float>(o * tint(rng)), static_cast<float>(o * tint(rng))};
            else
                h.opacity = {static_cast<float>(o), static_cast<float>(o), static_cast<float>(o)};
            pixel.hits[k].push_back(h);
        }
        if (unit(rng) < volumeFraction) {
            const int s = volumeSamples(rng);
            const double start = 0.5 + 2.0 * unit(rng);
            const double length = 0.3 + 0.7 * unit(rng);
            for (int i = 0; i < s; ++i)
                pixel.volume[k].push_back({static_cast<float>(start + length * i / (s - 1)),
                                           static_cast<float>(2.0 * unit(rng))});
        }
        pixel.weights[k] = weight(rng);
    }
    return pixel;
}

VisibilityFunction sweptVisibility(const PixelRays& pixel, int channels) {
    const std::vector<VisibilityFunction> taus = pixel.transmittances(channels, false);
    VisibilityFunction out(channels, false);
    CollectingSink sink(out);
    sweep(taus, pixel.weights, channels, sink);
    return out;
}

VisibilityFunction smoothDecay(std::size_t samples) {
    VisibilityFunction out(1, false);
    out.reserve(samples);
    for (std::size_t i = 0; i < samples; ++i) {
        const double z = 10.0 * static_cast<double>(i) / static_cast<double>(samples - 1);
        out.append(static_cast<float>(z), static_cast<float>(std::exp(-0.6 * z)));
    }
    return out;
}

// ---------------------------------------------------------------- sinks

bool DoubleSink::push(float z, const double* values, std::uint32_t count) {
    Vertex v{z, {0.0, 0.0, 0.0}, count};
    std::copy(values, values + channels_, v.v);
    vertices_.push_back(v);
    return true;
}

namespace {

struct DepthRecord {
    float z;
    double left[kMaxChannels];
    double value[kMaxChannels];
    std::uint64_t count;
};

std::vector<DepthRecord> byDepth(const DoubleSink& s) {
    std::vector<DepthRecord> out;
    const auto& vs = s.vertices();
    for (std::size_t i = 0; i < vs.size();) {
        DepthRecord r{vs[i].z, {}, {}, 0};
        std::copy(vs[i].v, vs[i].v + kMaxChannels, r.left);
        std::size_t j = i;
        for (; j < vs.size() && vs[j].z == vs[i].z; ++j) r.count += vs[j].count;
        std::copy(vs[j - 1].v, vs[j - 1].v + kMaxChannels, r.value);
        out.push_back(r);
        i = j;
    }
    return out;
}

}  // namespace

std::string compareStreams(const DoubleSink& a, const DoubleSink& b, double tolerance, double& maxDiff) {
    maxDiff = 0.0;
    const std::vector<DepthRecord> ra = byDepth(a), rb = byDepth(b);
    std::ostringstream why;
    if (ra.size() != rb.size()) {
        why << ra.size() << " distinct depths vs " << rb.size();
        return why.str();
    }
    const int nc = std::min(a.channels(), b.channels());
    for (std::size_t i = 0; i < ra.size(); ++i) {
        if (ra[i].z != rb[i].z) {
            why << "depth " << i << ": z " << ra[i].z << " vs " << rb[i].z;
            return why.str();
        }
        if (ra[i].count != rb[i].count) {
            why << "depth " << i << " (z " << ra[i].z << "): count " << ra[i].count << " vs " << rb[i].count;
            return why.str();
        }
        for (int c = 0; c < nc; ++c) {
            const double dl = std::abs(ra[i].left[c] - rb[i].left[c]);
            const double dv = std::abs(ra[i].value[c] - rb[i].value[c]);
            maxDiff = std::max({maxDiff, dl, dv});
            if (dl > tolerance || dv > tolerance) {
                why.precision(17);
                why << "depth " << i << " (z " << ra[i].z << ") channel " << c << ": left " << ra[i].left[c]
                    << " vs " << rb[i].left[c] << ", value " << ra[i].value[c] << " vs " << rb[i].value[c];
                return why.str();
            }
        }
    }
    return {};
}

// ---------------------------------------------------------------- runner

double Measurement::median() const {
    if (cpuSeconds.empty()) return std::nan("");
    std::vector<double> t = cpuSeconds;
    std::sort(t.begin(), t.end());
    const std::size_t h = t.size() / 2;
    return t.size() % 2 ? t[h] : 0.5 * (t[h - 1] + t[h]);
}

double Measurement::spreadPercent() const {
    if (cpuSeconds.empty()) return std::nan("");
    const auto [lo, hi] = std::minmax_element(cpuSeconds.begin(), cpuSeconds.end());
    return 100.0 * (*hi - *lo) / median();
}

Arguments parseArguments(int argc, char** argv) {
    Arguments args;
    args.benchmarkArgs.push_back(argc > 0 ? argv[0] : "bench");
    args.benchmarkArgs.push_back("--benchmark_min_time=0.3");
    args.benchmarkArgs.push_back("--benchmark_repetitions=5");
    args.benchmarkArgs.push_back("--benchmark_enable_random_interleaving=true");
    std::vector<std::string> user;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--smoke")
            args.smoke = true;
        else
            user.push_back(a);
    }
    if (args.smoke) {
        args.benchmarkArgs.push_back("--benchmark_min_time=0.001");
        args.benchmarkArgs.push_back("--benchmark_repetitions=1");
    }
    args.benchmarkArgs.insert(args.benchmarkArgs.end(), user.begin(), user.end());
    return args;
}

namespace {

// Records every repetition; shows the console table, but with repetitions only
// the aggregates (mean, median, stddev, cv), to keep it short.
class RecordingReporter final : public benchmark::ConsoleReporter {
public:
    // Colours only on a terminal, so that redirected output stays plain text.
    explicit RecordingReporter(Results& results)
        : ConsoleReporter(isatty(fileno(stdout)) ? OO_ColorTabular : OO_Tabular), results_(results) {}

    void ReportRuns(const std::vector<Run>& runs) override {
        std::vector<Run> shown;
        for (const Run& run : runs) {
            if (run.error_occurred) {
                failed_ = true;
                shown.push_back(run);
                continue;
            }
            if (run.run_type == Run::RT_Aggregate) {
                shown.push_back(run);
                continue;
            }
            Measurement& m = results_[run.run_name.function_name];
            const double iterations = static_cast<double>(std::max<benchmark::IterationCount>(run.iterations, 1));
            m.cpuSeconds.push_back(run.cpu_accumulated_time / iterations);
            for (const auto& [name, counter] : run.counters) m.counters[name] = counter.value;
            if (run.repetitions <= 1) shown.push_back(run);
        }
        if (!shown.empty()) ConsoleReporter::ReportRuns(shown);
    }

    bool failed() const { return failed_; }

private:
    Results& results_;
    bool failed_ = false;
};

}  // namespace

bool runBenchmarks(const Arguments& args, Results& results) {
    std::vector<std::string> storage = args.benchmarkArgs;
    std::vector<char*> argv;
    for (std::string& s : storage) argv.push_back(s.data());
    argv.push_back(nullptr);
    int argc = static_cast<int>(storage.size());
    benchmark::Initialize(&argc, argv.data());
    if (benchmark::ReportUnrecognizedArguments(argc, argv.data())) return false;
    RecordingReporter reporter(results);
    benchmark::RunSpecifiedBenchmarks(&reporter);
    benchmark::Shutdown();
    std::fflush(stdout);
    return !reporter.failed();
}

std::string formatRate(double perSecond, const char* unit) {
    char buf[64];
    if (!std::isfinite(perSecond)) return "n/a";
    if (perSecond >= 1e9)
        std::snprintf(buf, sizeof buf, "%.2f G%s/s", perSecond / 1e9, unit);
    else if (perSecond >= 1e6)
        std::snprintf(buf, sizeof buf, "%.1f M%s/s", perSecond / 1e6, unit);
    else
        std::snprintf(buf, sizeof buf, "%.1f k%s/s", perSecond / 1e3, unit);
    return buf;
}

std::string formatTime(double seconds) {
    char buf[64];
    if (!std::isfinite(seconds)) return "n/a";
    if (seconds >= 1e-3)
        std::snprintf(buf, sizeof buf, "%.2f ms", seconds * 1e3);
    else
        std::snprintf(buf, sizeof buf, "%.1f us", seconds * 1e6);
    return buf;
}

}  // namespace dsm::bench
