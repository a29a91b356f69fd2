// The trade harness (bench/trade): what each knob costs in time, bytes and
// error, for the example scenes. Each measurement writes one section of a
// JSON document that bench/trade_report.py turns into bench/RESULTS.md.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <dsm/dsm.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

namespace dsm::trade {

using Json = nlohmann::ordered_json;

struct Config {
    bool smoke = false;
    std::filesystem::path workDir;
    std::vector<std::string> scenes;   ///< scene files; the first drives the single-scene studies
    std::uint32_t resolution = 128;     ///< map size of the tolerance x spp grid and the deep-vs-normal study
    std::vector<std::uint32_t> spp{4, 16, 64, 256, 1024};
    std::vector<double> toleranceFactors{0.0, 0.25, 0.5, 1.0, 2.0, 4.0};  ///< times 0.25 / sqrt(N)
    std::uint32_t referenceSpp = 4096;
    double referenceTolerance = 0.0005;   ///< a quarter of the smallest tolerance tested at N = 1024
    std::uint32_t maxUncompressedSpp = 64;  ///< largest N with an uncompressed (epsilon = 0) map
    std::size_t queries = 20000;       ///< lookups per error and time measurement
    std::size_t tracedQueries = 500;   ///< pixel-centre queries checked against ray-traced truth
    int tracedRaysPerSide = 32;        ///< their truth: side x side rays per pixel
    std::uint32_t cacheResolution = 256;
    std::uint32_t cacheTileSize = 16;
    unsigned threads = 0;
};

/// One lookup: raster position and light depth of a map's level 0.
struct Query {
    double x, y, z;
};

/// Builds `scene` with options that differ only in spp, tolerance and seed
/// from the harness defaults (box filter of width 1, so a pixel is the mean of
/// its own samples; full mip pyramid). Returns the build statistics.
BuildStats buildWith(const Scene& scene, std::uint32_t resolution, std::uint32_t spp, double tolerance,
                     std::uint64_t seed, const std::string& path, unsigned threads, std::uint32_t tileSize = 32);

/// Queries at random raster positions (or, with `pixelCentres`, at pixel
/// centres) and depths drawn uniformly between the smallest and 1.1 x the
/// largest depth of the tile under each point, so they probe where the map
/// has content. Deterministic for a seed.
std::vector<Query> makeQueries(const DeepShadowMap& map, std::size_t count, bool pixelCentres, std::uint64_t seed);

/// Visibility (channel 0) of every query through a LookupContext.
std::vector<double> lookupAll(const std::shared_ptr<const DeepShadowMap>& map, const std::vector<Query>& queries,
                              const LookupOptions& options);

/// Seconds per lookup: the best of `repeats` timed passes over the queries
/// (after one untimed pass that warms the cache).
double secondsPerLookup(const std::shared_ptr<const DeepShadowMap>& map, const std::vector<Query>& queries,
                        const LookupOptions& options, int repeats = 3);

struct ErrorStats {
    double max = 0.0, mean = 0.0, rms = 0.0;
};
ErrorStats compare(const std::vector<double>& a, const std::vector<double>& b);
Json toJson(const ErrorStats& e);

/// Seconds of wall time of a callable.
template <class F>
double timed(F&& f) {
    const auto start = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// Where the grid study leaves its maps (the later studies reuse them):
/// factor < 0 names the converged reference.
std::filesystem::path gridMapPath(const Config& config, const std::string& scene, std::uint32_t spp, double factor);

/// The studies; each returns its JSON section.
Json studyToleranceAndSpp(const Config& config, const Scene& scene, const std::string& name);
Json studyDeepVersusNormal(const Config& config, const Scene& scene, const std::string& name);
Json studyFilterWidth(const Config& config, const Scene& scene, const std::string& name);
Json studyStorage(const Config& config, const Scene& scene, const std::string& name);
Json studyCacheBudget(const Config& config, const Scene& scene, const std::string& name);

}  // namespace dsm::trade
