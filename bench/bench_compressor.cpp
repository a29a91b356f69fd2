// Throughput of the streaming L-infinity compressor (Lokovic & Veach §3.3) in
// input vertices per second, against memcpy of the same bytes (the input's z
// and V float arrays) measured in the same process. Prints the time ratio
// compressor/memcpy per input and tolerance after the Google Benchmark table.
//
//   bench_compressor [--smoke] [--benchmark_* flags]

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "support.h"

namespace {

using namespace dsm;
using namespace dsm::bench;

constexpr double kSamplesPerPixel = 256.0;

struct Input {
    std::string name;
    std::string description;
    VisibilityFunction function;
    std::size_t bytes() const { return function.depths().size_bytes() + function.allValues().size_bytes(); }
};

struct Tolerance {
    std::string name;
    double epsilon;
};

std::string compressName(const Input& in, const Tolerance& t) { return "compress/" + in.name + "/eps=" + t.name; }
std::string runName(const Input& in, const Tolerance& t) { return "pushValid-run/" + in.name + "/eps=" + t.name; }
std::string centredName(const Input& in, const Tolerance& t) {
    return "pushValid-run-centred/" + in.name + "/eps=" + t.name;
}
std::string memcpyName(const Input& in) { return "memcpy/" + in.name; }

// Outside any timing: the output is a valid function within epsilon of the
// input (checked at every input depth and between them), and the same
// whether pushed vertex by vertex or as one run. The input values are
// float already, so the bound is epsilon itself; 1e-9 covers the double
// evaluation of the two piecewise-linear functions.
bool checkOutput(const Input& in, const Tolerance& t, bool centred, std::size_t& outVertices) {
    CompressorOptions options;
    options.tolerance = t.epsilon;
    options.channels = in.function.channels();
    options.centred = centred;
    const std::string name = centred ? centredName(in, t) : compressName(in, t);
    Compressor compressor(options);
    const VisibilityFunction& f = in.function;
    for (std::size_t i = 0; i < f.size(); ++i) compressor.push(f.z(i), f.values(i), 0);
    const VisibilityFunction out = compressor.finish();
    outVertices = out.size();
    compressor.pushValid(f.depths().data(), f.allValues().data(), nullptr, f.size());
    if (compressor.finish() != out) {
        std::printf("check %s: pushValid() of the run differs from push() per vertex\n", name.c_str());
        return false;
    }
    try {
        out.validate();
    } catch (const Error& e) {
        std::printf("check %s: invalid output: %s\n", name.c_str(), e.what());
        return false;
    }
    double maxErr = 0.0;
    auto probe = [&](double z) {
        for (int c = 0; c < f.channels(); ++c) {
            const double got = out.evaluate(z, out.channels() == 1 ? 0 : c);
            maxErr = std::max(maxErr, std::abs(got - f.evaluate(z, c)));
        }
    };
    for (std::size_t i = 0; i < f.size(); ++i) {
        probe(f.z(i));
        if (i + 1 < f.size() && f.z(i + 1) > f.z(i)) probe(0.5 * (static_cast<double>(f.z(i)) + f.z(i + 1)));
    }
    const bool ok = maxErr <= t.epsilon + 1e-9;
    std::printf("check %s: %zu -> %zu vertices (%s), max |V'-V| = %.3g %s %.3g\n", name.c_str(),
                f.size(), out.size(), out.channels() == 1 ? "mono" : "rgb", maxErr, ok ? "<=" : "EXCEEDS",
                t.epsilon);
    return ok;
}

void benchCompress(benchmark::State& state, const Input* in, double epsilon, std::size_t outVertices) {
    const VisibilityFunction& f = in->function;
    CompressorOptions options;
    options.tolerance = epsilon;
    options.channels = f.channels();
    Compressor compressor(options);
    const std::size_t n = f.size();
    const std::size_t nc = static_cast<std::size_t>(f.channels());
    const float* z = f.depths().data();
    const float* v = f.allValues().data();
    for (auto _ : state) {
        for (std::size_t i = 0; i < n; ++i) compressor.push(z[i], v + i * nc, 0);
        VisibilityFunction out = compressor.finish();
        benchmark::DoNotOptimize(out.depths().data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
    state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(in->bytes()));
    state.counters["vertices"] = static_cast<double>(n);
    state.counters["out_vertices"] = static_cast<double>(outVertices);
}

// The library's own path: the whole function handed over as one run of
// vertices known to be valid (what a build does with the sweep's output).
void benchRun(benchmark::State& state, const Input* in, double epsilon, bool centred, std::size_t outVertices) {
    const VisibilityFunction& f = in->function;
    CompressorOptions options;
    options.tolerance = epsilon;
    options.centred = centred;
    options.channels = f.channels();
    Compressor compressor(options);
    for (auto _ : state) {
        compressor.pushValid(f.depths().data(), f.allValues().data(), nullptr, f.size());
        VisibilityFunction out = compressor.finish();
        benchmark::DoNotOptimize(out.depths().data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(f.size()));
    state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(in->bytes()));
    state.counters["vertices"] = static_cast<double>(f.size());
    state.counters["out_vertices"] = static_cast<double>(outVertices);
}

void benchMemcpy(benchmark::State& state, const Input* in) {
    const VisibilityFunction& f = in->function;
    std::vector<float> z(f.depths().size()), v(f.allValues().size());
    benchmark::DoNotOptimize(z.data());
    benchmark::DoNotOptimize(v.data());
    for (auto _ : state) {
        std::memcpy(z.data(), f.depths().data(), f.depths().size_bytes());
        std::memcpy(v.data(), f.allValues().data(), f.allValues().size_bytes());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(f.size()));
    state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(in->bytes()));
    state.counters["vertices"] = static_cast<double>(f.size());
}

}  // namespace

int main(int argc, char** argv) {
    const Arguments args = parseArguments(argc, argv);

    std::vector<Input> inputs;
    inputs.push_back({"smooth", "exp(-0.6 z) sampled at 8192 depths in [0, 10]", smoothDecay(8192)});
    inputs.push_back({"hair", "sweep of 256 rays, 2..20 random hits (opacity 0.05..0.6)",
                      sweptVisibility(hairPixel(256, 2, 20, 0.0, false, 7), 1)});
    inputs.push_back({"hair-rgb", "as hair, RGB: green and blue opacity scaled by 0.5..1 per hit",
                      sweptVisibility(hairPixel(256, 2, 20, 0.0, true, 8), 3)});
    const std::vector<Tolerance> tolerances = {{"auto", autoTolerance(kSamplesPerPixel)}, {"0", 0.0}};

    std::vector<std::vector<std::size_t>> outVertices(inputs.size(), std::vector<std::size_t>(tolerances.size()));
    std::vector<std::vector<std::size_t>> centredVertices = outVertices;
    bool ok = true;
    for (std::size_t i = 0; i < inputs.size(); ++i)
        for (std::size_t t = 0; t < tolerances.size(); ++t) {
            ok = checkOutput(inputs[i], tolerances[t], false, outVertices[i][t]) && ok;
            if (tolerances[t].epsilon > 0.0)
                ok = checkOutput(inputs[i], tolerances[t], true, centredVertices[i][t]) && ok;
        }
    if (!ok) return 1;
    std::printf("\n");
    std::fflush(stdout);

    for (std::size_t i = 0; i < inputs.size(); ++i) {
        for (std::size_t t = 0; t < tolerances.size(); ++t) {
            benchmark::RegisterBenchmark(compressName(inputs[i], tolerances[t]).c_str(), benchCompress, &inputs[i],
                                         tolerances[t].epsilon, outVertices[i][t])
                ->Unit(benchmark::kMicrosecond);
            benchmark::RegisterBenchmark(runName(inputs[i], tolerances[t]).c_str(), benchRun, &inputs[i],
                                         tolerances[t].epsilon, false, outVertices[i][t])
                ->Unit(benchmark::kMicrosecond);
            // Centred segments (CompressorOptions::centred) at a tolerance > 0; at 0 every vertex is kept.
            if (tolerances[t].epsilon > 0.0)
                benchmark::RegisterBenchmark(centredName(inputs[i], tolerances[t]).c_str(), benchRun, &inputs[i],
                                             tolerances[t].epsilon, true, centredVertices[i][t])
                    ->Unit(benchmark::kMicrosecond);
        }
        benchmark::RegisterBenchmark(memcpyName(inputs[i]).c_str(), benchMemcpy, &inputs[i])
            ->Unit(benchmark::kMicrosecond);
    }

    Results results;
    if (!runBenchmarks(args, results)) return 1;

    std::printf("\nInputs (auto eps = 0.25/sqrt(%g) = %g):\n", kSamplesPerPixel, autoTolerance(kSamplesPerPixel));
    for (const Input& in : inputs)
        std::printf("  %-9s %zu vertices, %d channel(s), %zu bytes of z+V: %s\n", in.name.c_str(), in.function.size(),
                    in.function.channels(), in.bytes(), in.description.c_str());
    std::printf("\nCompressor vs memcpy of the same z+V bytes; median CPU time per input function\n");
    std::printf("(spread: (max - min) / median over the repetitions)\n");
    std::printf("%-9s %-9s %9s %9s %14s %7s %14s %12s %7s %18s\n", "input", "eps", "in verts", "out verts",
                "compressor", "spread", "memcpy", "memcpy", "spread", "compressor/memcpy");
    for (std::size_t i = 0; i < inputs.size(); ++i) {
        const Input& in = inputs[i];
        const double n = static_cast<double>(in.function.size());
        const Measurement& mm = results[memcpyName(in)];
        const double tm = mm.median();
        for (std::size_t t = 0; t < tolerances.size(); ++t) {
            const Measurement& mc = results[compressName(in, tolerances[t])];
            const double tc = mc.median();
            std::printf("%-9s %-9.6g %9zu %9zu %14s %6.0f%% %14s %12s %6.0f%% %18.1f\n", in.name.c_str(),
                        tolerances[t].epsilon, in.function.size(), outVertices[i][t],
                        formatRate(n / tc, "vert").c_str(), mc.spreadPercent(), formatRate(n / tm, "vert").c_str(),
                        formatRate(static_cast<double>(in.bytes()) / tm, "B").c_str(), mm.spreadPercent(), tc / tm);
        }
    }
    std::printf("\n(push: one push() per vertex, input checked; run: pushValid() of the whole function; centred:\n"
                "the run with centred segments)\n");
    for (const Input& in : inputs)
        for (const Tolerance& t : tolerances) {
            const double memcpyTime = results[memcpyName(in)].median();
            std::printf("compressor/memcpy %s eps=%g: push %.1f, run %.1f", in.name.c_str(), t.epsilon,
                        results[compressName(in, t)].median() / memcpyTime,
                        results[runName(in, t)].median() / memcpyTime);
            if (t.epsilon > 0.0) std::printf(", centred %.1f", results[centredName(in, t)].median() / memcpyTime);
            std::printf("\n");
        }
    if (args.smoke) std::printf("(smoke run: the numbers above are not measurements)\n");
    return 0;
}
