// A build against Embree: the figures of docs/dsm-build.md, "Speed against
// Embree". Every rate is measured in this run and every ratio is between two
// measurements of the same round; rounds alternate the programs so that a
// change in the machine's load reaches all of them alike.
//
// Per round, on the scene at N x N pixels and S samples per pixel:
//  1. the whole build (`buildMap`, scanline sampler) on one thread and on two,
//     and on one thread held on each of the first two processors the process
//     may use: a virtual machine's processors need not be equally fast (on the
//     2-core AMD EPYC guest the second ran the build about 40 % slower, its
//     caches slower, while a loop in registers ran alike on both), and two
//     threads can at best add the two speeds, not double the first's; Embree's
//     rays (3.) are held on each of the two as well, so that the build and
//     Embree are also compared on the same core;
//  2. the whole build with the ray-casting sampler on one thread;
//  3. Embree all-hit rays (the reference tracer: one rtcOccluded1 call a ray
//     whose filter records every crossing and lets traversal go on) through
//     the same scene (opaque surfaces traced at opacity 0.999, so that no
//     crossing ends a ray early: the sampler too finds them all), one ray per
//     map sample (N x N x S rays placed as the sampler places them: stratified
//     and jittered in each pixel), one thread.
// A build's samples per second count the map's N x N x S samples (not the
// extra samples tiles cast along their borders), so every rate is over the
// same number of samples. "Sampling alone" is the build's own sample count
// over its crossing time (placing samples and finding what they cross).
// "Work after sampling" is the one-thread build's gathering and
// transmittances, sweep, compression and writing: as a share of those
// stages' time plus the crossings', and in nanoseconds a sample the build
// took (its own count, border samples included).
//
//   bench_build_speed [--smoke] [--scene=FILE] [--size=N] [--spp=S] [--rounds=K] [--far=DEPTH]
#include <dsm/reference_tracer.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include <unistd.h>

#if defined(__linux__)
#include <sched.h>
#endif

#include "light_rays.h"

#ifndef DSM_BENCH_DEFAULT_SCENE
#define DSM_BENCH_DEFAULT_SCENE "examples/hairball.json"
#endif

namespace {

using namespace dsm;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct Config {
    bool smoke = false;
    std::string scene = DSM_BENCH_DEFAULT_SCENE;
    std::uint32_t size = 256, spp = 16;
    int rounds = 3;
    double far = 1e4;  // light-space depth where the Embree rays end
};

struct Ray {
    Vec3 from, to;
    double time;
};

// One ray per map sample, placed as the sampler places them (a stratified grid
// of about sqrt(S) x sqrt(S) cells a pixel, one jittered sample a cell).
std::vector<Ray> sampleRays(const Scene& scene, const Config& cfg) {
    LightDescription light = scene.light;
    light.width = light.height = cfg.size;
    const LightCamera camera = lightCamera(light);
    const detail::LightRayFrame frame = detail::lightRayFrame(camera, cfg.size, cfg.size);
    const std::uint32_t gy = std::max(1u, static_cast<std::uint32_t>(std::sqrt(double(cfg.spp))));
    const std::uint32_t gx = (cfg.spp + gy - 1) / gy;
    const bool moving = std::any_of(scene.objects.begin(), scene.objects.end(), [](const SceneObject& o) {
        return o.motion != Vec3{0.0, 0.0, 0.0};
    });
    std::mt19937_64 rng(1);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<Ray> rays;
    rays.reserve(std::size_t(cfg.size) * cfg.size * cfg.spp);
    for (std::uint32_t y = 0; y < cfg.size; ++y)
        for (std::uint32_t x = 0; x < cfg.size; ++x)
            for (std::uint32_t k = 0; k < cfg.spp; ++k) {
                const double rx = x + ((k % gx) + u(rng)) / gx, ry = y + ((k / gx % gy) + u(rng)) / gy;
                Vec3 o, d;
                frame.ray(rx, ry, o, d);
                Ray r;
                for (int i = 0; i < 3; ++i) {
                    r.from[i] = o[i] + camera.nearPlane * d[i];
                    r.to[i] = o[i] + cfg.far * d[i];
                }
                r.time = moving ? u(rng) : 0.0;
                rays.push_back(r);
            }
    return rays;
}

struct Round {
    BuildStats scan1, scan2, ray1;
    BuildStats onProcessor[2];        // one thread held on each of two processors
    double embreeOnProcessor[2] = {};  // Embree's seconds, held on the same two
    double embreeSeconds = 0.0;
    double embreeChecksum = 0.0;
};

BuildStats build(const Scene& scene, const Config& cfg, SamplerMethod sampler, unsigned threads,
                 const std::string& path) {
    BuildOptions o;
    o.width = o.height = cfg.size;
    o.samplesPerPixel = cfg.spp;
    o.threads = threads;
    o.sampler = sampler;
    const BuildStats s = buildMap(scene, o, path);
    fs::remove(path);
    return s;
}

#if defined(__linux__)
// The first two processors this process may run on; empty when it may run
// on fewer.
std::vector<int> firstTwoProcessors() {
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    if (sched_getaffinity(0, sizeof allowed, &allowed) != 0) return {};
    std::vector<int> found;
    for (int c = 0; c < CPU_SETSIZE && found.size() < 2; ++c)
        if (CPU_ISSET(c, &allowed)) found.push_back(c);
    return found.size() == 2 ? found : std::vector<int>{};
}

// What `work` returns, run by this thread held on `processor` (a one-thread
// build's work stays on the calling thread, as do Embree's rays here); the
// thread may then run where it could before.
template <class Work>
auto heldOn(int processor, Work&& work) {
    cpu_set_t before, only;
    CPU_ZERO(&only);
    CPU_SET(processor, &only);
    if (sched_getaffinity(0, sizeof before, &before) != 0 || sched_setaffinity(0, sizeof only, &only) != 0)
        throw std::runtime_error("cannot hold the thread on processor " + std::to_string(processor));
    const auto result = work();
    sched_setaffinity(0, sizeof before, &before);
    return result;
}
#else
std::vector<int> firstTwoProcessors() { return {}; }
template <class Work>
auto heldOn(int, Work&& work) {
    return work();
}
#endif

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const std::size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

int main(int argc, char** argv) {
    Config cfg;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&](const char* key) -> const char* {
            const std::string k = std::string(key) + "=";
            return a.rfind(k, 0) == 0 ? a.c_str() + k.size() : nullptr;
        };
        if (a == "--smoke") cfg.smoke = true;
        else if (const char* v = value("--scene")) cfg.scene = v;
        else if (const char* v = value("--size")) cfg.size = static_cast<std::uint32_t>(std::atoi(v));
        else if (const char* v = value("--spp")) cfg.spp = static_cast<std::uint32_t>(std::atoi(v));
        else if (const char* v = value("--rounds")) cfg.rounds = std::atoi(v);
        else if (const char* v = value("--far")) cfg.far = std::atof(v);
        else {
            std::fprintf(stderr, "usage: bench_build_speed [--smoke] [--scene=FILE] [--size=N] [--spp=S] "
                                 "[--rounds=K] [--far=DEPTH]\n");
            return 2;
        }
    }
    if (cfg.smoke) {
        cfg.size = 32;
        cfg.spp = 4;
        cfg.rounds = 1;
    }
    if (cfg.size < 1 || cfg.spp < 1 || cfg.rounds < 1 || !(cfg.far > 0.0)) {
        std::fprintf(stderr, "bench_build_speed: size, spp, rounds and far must be positive\n");
        return 2;
    }
    try {
        const Scene scene = loadScene(cfg.scene);
        const auto tracerStart = Clock::now();
        // Every crossing counts for the sampler, so none may end an Embree ray
        // early: opaque surfaces are traced as very nearly opaque.
        Scene allHit = scene;
        for (SceneObject& o : allHit.objects)
            for (float& a : o.opacity) a = std::min(a, 0.999f);
        const ReferenceTracer tracer(allHit);
        const double tracerSeconds = std::chrono::duration<double>(Clock::now() - tracerStart).count();
        const std::vector<Ray> rays = sampleRays(scene, cfg);
        const double n = double(rays.size());
        const std::string path =
            (fs::temp_directory_path() / ("bench_build_speed_" + std::to_string(getpid()) + ".dsm")).string();

        const std::vector<int> processors = firstTwoProcessors();
        // Embree's rays on this thread: their seconds and mean transmittance.
        const auto traceAll = [&] {
            const auto start = Clock::now();
            double sum = 0.0;
            for (const Ray& ray : rays) sum += tracer.transmittance(ray.from, ray.to, ray.time)[0];
            return std::pair{std::chrono::duration<double>(Clock::now() - start).count(), sum / n};
        };
        std::vector<Round> rounds;
        for (int r = 0; r < cfg.rounds; ++r) {
            Round round;
            round.scan1 = build(scene, cfg, SamplerMethod::scanline, 1, path);
            std::tie(round.embreeSeconds, round.embreeChecksum) = traceAll();
            round.ray1 = build(scene, cfg, SamplerMethod::raytrace, 1, path);
            round.scan2 = build(scene, cfg, SamplerMethod::scanline, 2, path);
            for (std::size_t k = 0; k < processors.size(); ++k) {
                round.onProcessor[k] =
                    heldOn(processors[k], [&] { return build(scene, cfg, SamplerMethod::scanline, 1, path); });
                round.embreeOnProcessor[k] = heldOn(processors[k], traceAll).first;
            }
            rounds.push_back(round);
        }

        std::printf("# Build against Embree: %s, %u² at %u spp, %zu rays (one a map sample), %d rounds, "
                    "%u hardware threads\n\n",
                    cfg.scene.c_str(), cfg.size, cfg.spp, rays.size(), cfg.rounds,
                    std::thread::hardware_concurrency());
        std::printf("Embree scene construction (not in any rate): %.3f s. Mean transmittance of the Embree "
                    "rays: %.4f.\n\n",
                    tracerSeconds, rounds[0].embreeChecksum);
        std::printf("| round | scanline build 1 thread, M samples/s | its sampling alone | raytrace build "
                    "1 thread | its sampling alone | Embree all-hit M rays/s | scanline build 2 threads |\n");
        std::printf("|---:|---:|---:|---:|---:|---:|---:|\n");
        std::vector<double> wholeRatio, samplingRatio, raytraceRatio, twoThreads, afterShare, afterNanoseconds;
        for (std::size_t r = 0; r < rounds.size(); ++r) {
            const Round& x = rounds[r];
            const double embree = n / x.embreeSeconds;
            const double scan1 = n / x.scan1.wallSeconds, scan2 = n / x.scan2.wallSeconds;
            const double scanSampling = double(x.scan1.samples) / x.scan1.crossingSeconds;
            const double ray1 = n / x.ray1.wallSeconds;
            const double raySampling = double(x.ray1.samples) / x.ray1.crossingSeconds;
            std::printf("| %zu | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f |\n", r + 1, scan1 / 1e6,
                        scanSampling / 1e6, ray1 / 1e6, raySampling / 1e6, embree / 1e6, scan2 / 1e6);
            wholeRatio.push_back(scan1 / embree);
            samplingRatio.push_back(scanSampling / embree);
            raytraceRatio.push_back(raySampling / embree);
            twoThreads.push_back(scan2 / scan1);
            // The work after sampling (gathering and transmittances, sweep,
            // compression, writing) against the stages' time, crossings
            // included: dsm-build --stats-json's stage times, one thread.
            const BuildStats& s = x.scan1;
            const double after = s.samplingSeconds - s.crossingSeconds + s.sweepSeconds + s.compressionSeconds +
                                 s.writingSeconds;
            afterShare.push_back(after / (s.crossingSeconds + after));
            afterNanoseconds.push_back(1e9 * after / double(s.samples));
        }
        std::printf("\n| ratio (median over rounds; range) | value |\n|---|---:|\n");
        auto row = [](const char* name, const std::vector<double>& v, int decimals = 2) {
            std::printf("| %s | %.*f (%.*f–%.*f) |\n", name, decimals, median(v), decimals,
                        *std::min_element(v.begin(), v.end()), decimals, *std::max_element(v.begin(), v.end()));
        };
        row("whole scanline build ÷ Embree all-hit rays, 1 thread", wholeRatio);
        row("scanline sampling alone ÷ Embree all-hit rays, 1 thread", samplingRatio);
        row("ray-casting sampler's sampling alone ÷ Embree all-hit rays, 1 thread", raytraceRatio);
        row("scanline build, 2 threads ÷ 1 thread", twoThreads);
        row("work after sampling ÷ all stages' time, 1 thread", afterShare);
        row("work after sampling, ns a sample, 1 thread", afterNanoseconds, 0);
        if (!processors.empty()) {
            // Two threads against the two processors' one-thread speeds: 1
            // when the second thread adds all its processor's speed.
            // The build and Embree's rays each held on one processor in turn:
            // on a machine whose processors differ in speed, and where that
            // changes over a round, the build ÷ Embree of one processor
            // compares the two on the same core.
            std::vector<double> slower, ofBoth, sameProcessor;
            std::printf("\nOne thread held on processor %d and on processor %d, M samples/s (builds) and M "
                        "rays/s (Embree), same rounds:\n\n"
                        "| round | build on %d | Embree on %d | build on %d | Embree on %d | 2 threads |\n"
                        "|---:|---:|---:|---:|---:|---:|\n",
                        processors[0], processors[1], processors[0], processors[0], processors[1], processors[1]);
            for (std::size_t r = 0; r < rounds.size(); ++r) {
                const Round& x = rounds[r];
                const double a = n / x.onProcessor[0].wallSeconds, b = n / x.onProcessor[1].wallSeconds;
                const double ea = n / x.embreeOnProcessor[0], eb = n / x.embreeOnProcessor[1];
                const double both = n / x.scan2.wallSeconds;
                std::printf("| %zu | %.3f | %.3f | %.3f | %.3f | %.3f |\n", r + 1, a / 1e6, ea / 1e6, b / 1e6,
                            eb / 1e6, both / 1e6);
                slower.push_back(std::min(a, b) / std::max(a, b));
                ofBoth.push_back(both / (a + b));
                sameProcessor.push_back(a / ea);
                sameProcessor.push_back(b / eb);
            }
            std::printf("\n| ratio (median over rounds; range) | value |\n|---|---:|\n");
            row("whole scanline build ÷ Embree all-hit rays, both held on one processor (each of two)",
                sameProcessor);
            row("slower processor ÷ faster, one thread", slower);
            row("2 threads ÷ (sum of the two processors' one-thread speeds)", ofBoth);
        }

        // What the smoke run checks: every program ran over the same samples.
        for (const Round& x : rounds)
            if (x.scan1.pixels != std::uint64_t(cfg.size) * cfg.size || x.ray1.pixels != x.scan1.pixels ||
                x.scan1.samples < rays.size() || x.scan1.crossingSeconds <= 0.0 ||
                x.scan1.crossingSeconds > x.scan1.samplingSeconds) {
                std::fprintf(stderr, "bench_build_speed: a build did not cover the map's samples\n");
                return 1;
            }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_build_speed: %s\n", e.what());
        return 1;
    }
    return 0;
}
