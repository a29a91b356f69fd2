// The sweep of Lokovic & Veach §5.1 (dsm::sweep, O(n log n)) against the naive
// O(n^2) average (naive_average.h) for n = 16 .. 1024 transmittance functions
// of one pixel. Both run in the same process; the program prints the ratio
// naive/sweep per n after the Google Benchmark table.
//
//   bench_sweep [--smoke] [--benchmark_* flags]

#include <benchmark/benchmark.h>

#include <cstdio>
#include <string>
#include <vector>

#include "naive_average.h"
#include "support.h"

namespace {

using namespace dsm;
using namespace dsm::bench;

constexpr std::size_t kSizes[] = {16, 64, 256, 1024};
constexpr std::size_t kDisjointSizes[] = {256, 1024, 4096};
constexpr double kAgreement = 1e-9;

struct Case {
    std::string family;  // "" for the hair pixel, else a name prefix
    std::size_t n = 0;
    std::vector<VisibilityFunction> taus;
    std::vector<double> weights;
    std::size_t inputVertices = 0;
    std::size_t outputVertices = 0;
    std::size_t depths = 0;
};

// n rays through hair: 2..20 semi-transparent hits each, a quarter of them
// also through smoke; monochrome transmittances with sample counts.
Case makeCase(std::size_t n) {
    Case c;
    c.n = n;
    const PixelRays pixel = hairPixel(n, 2, 20, 0.25, false, 1000 + n);
    c.taus = pixel.transmittances(1, true);
    c.weights = pixel.weights;
    for (const VisibilityFunction& f : c.taus) c.inputVertices += f.size();
    return c;
}

// A worst case, not a typical pixel: n rays that each cross one thin smoke
// patch of their own, the patches disjoint in depth. Between two patches every
// input is flat, so the sweep's running slope sum returns to exactly 0 after
// each patch.
Case makeDisjointCase(std::size_t n) {
    Case c;
    c.family = "disjoint-volumes/";
    c.n = n;
    c.weights.assign(n, 1.0);
    for (std::size_t k = 0; k < n; ++k) {
        const float z0 = 1.0f + 4.0f * static_cast<float>(k) / static_cast<float>(n);
        const VolumeSample patch[2] = {{z0, 1.0f}, {z0 + 1.0f / static_cast<float>(n), 1.0f}};
        c.taus.push_back(transmittance(SampleRay{{}, patch}, 1, true));
        c.inputVertices += c.taus.back().size();
    }
    return c;
}

// Outside any timing: the naive average and the sweep must agree within 1e-9
// (left limit, value and count at every distinct depth), else the comparison
// would not be between two ways of computing the same thing.
bool checkAgreement(Case& c) {
    DoubleSink fast(1), slow(1);
    sweep(c.taus, c.weights, 1, fast);
    naiveAverage(c.taus, c.weights, 1, slow);
    double maxDiff = 0.0;
    const std::string why = compareStreams(fast, slow, kAgreement, maxDiff);
    c.outputVertices = fast.vertices().size();
    std::size_t depths = 0;
    for (std::size_t i = 0; i < fast.vertices().size(); ++i)
        if (i == 0 || fast.vertices()[i].z != fast.vertices()[i - 1].z) ++depths;
    c.depths = depths;
    if (!why.empty()) {
        std::printf("check %sn=%zu: sweep and naive average DISAGREE: %s\n", c.family.c_str(), c.n, why.c_str());
        return false;
    }
    std::printf("check %sn=%zu: sweep == naive within %.0e at all %zu depths (max |diff| %.2e)\n", c.family.c_str(),
                c.n, kAgreement, depths, maxDiff);
    return true;
}

void setCounters(benchmark::State& state, const Case& c) {
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(c.inputVertices));
    state.counters["n"] = static_cast<double>(c.n);
    state.counters["in_vertices"] = static_cast<double>(c.inputVertices);
    state.counters["out_vertices"] = static_cast<double>(c.outputVertices);
}

void benchSweep(benchmark::State& state, const Case* c) {
    DoubleSink sink(1);
    for (auto _ : state) {
        sink.clear();
        sweep(c->taus, c->weights, 1, sink);
        benchmark::DoNotOptimize(sink.vertices().data());
        benchmark::ClobberMemory();
    }
    setCounters(state, *c);
}

void benchNaive(benchmark::State& state, const Case* c) {
    DoubleSink sink(1);
    for (auto _ : state) {
        sink.clear();
        naiveAverage(c->taus, c->weights, 1, sink);
        benchmark::DoNotOptimize(sink.vertices().data());
        benchmark::ClobberMemory();
    }
    setCounters(state, *c);
}

std::string name(const char* what, const Case& c) { return std::string(what) + "/" + c.family + "n=" + std::to_string(c.n); }

void printTable(const std::vector<Case>& cases, Results& results) {
    std::printf("(spread: (max - min) / median over the repetitions)\n");
    std::printf("%6s %12s %8s %12s %7s %12s %7s %14s %12s\n", "n", "in vertices", "depths", "sweep", "spread",
                "naive", "spread", "sweep ns/vert", "naive/sweep");
    for (const Case& c : cases) {
        const Measurement& ms = results[name("sweep", c)];
        const Measurement& mn = results[name("naive", c)];
        const double ts = ms.median(), tn = mn.median();
        std::printf("%6zu %12zu %8zu %12s %6.0f%% %12s %6.0f%% %14.1f %12.1f\n", c.n, c.inputVertices, c.depths,
                    formatTime(ts).c_str(), ms.spreadPercent(), formatTime(tn).c_str(), mn.spreadPercent(),
                    ts * 1e9 / static_cast<double>(c.inputVertices), tn / ts);
    }
}

}  // namespace

int main(int argc, char** argv) {
    const Arguments args = parseArguments(argc, argv);

    std::vector<Case> cases, disjoint;
    for (std::size_t n : kSizes) cases.push_back(makeCase(n));
    for (std::size_t n : kDisjointSizes) disjoint.push_back(makeDisjointCase(n));
    bool agree = true;
    for (Case& c : cases) agree = checkAgreement(c) && agree;
    for (Case& c : disjoint) agree = checkAgreement(c) && agree;
    if (!agree) return 1;
    std::printf("\n");
    std::fflush(stdout);

    for (const std::vector<Case>* family : {&cases, &disjoint})
        for (const Case& c : *family) {
            benchmark::RegisterBenchmark(name("sweep", c).c_str(), benchSweep, &c)->Unit(benchmark::kMicrosecond);
            benchmark::RegisterBenchmark(name("naive", c).c_str(), benchNaive, &c)->Unit(benchmark::kMicrosecond);
        }

    Results results;
    if (!runBenchmarks(args, results)) return 1;

    std::printf("\nSweep (O(n log n)) vs naive average (O(n^2)), one monochrome hair pixel; median CPU time per pixel\n");
    printTable(cases, results);
    std::printf("\nWorst case: n disjoint thin volume patches, one per ray (the running slope returns to 0 each time)\n");
    printTable(disjoint, results);
    std::printf("\n");
    for (const Case& c : cases)
        std::printf("naive/sweep n=%zu = %.1f\n", c.n, results[name("naive", c)].median() / results[name("sweep", c)].median());
    if (args.smoke) std::printf("(smoke run: the numbers above are not measurements)\n");
    return 0;
}
