// Study 1 (tolerance x samples per pixel) with, from the same maps, vertex
// growth (Lokovic & Veach Fig. 8) and the mip pyramid's overhead (§5.3).
#include <cmath>
#include <cstdio>

#include "trade.h"

namespace dsm::trade {

namespace {

/// Mean vertices per non-empty pixel of level 0 (a visibility function of an
/// empty pixel has none and is left out, as in LV's count of functions).
double meanVertices(const MapInfo& info) {
    const LevelInfo& l = info.levels[0];
    return l.nonEmptyPixels ? double(l.vertexCount) / double(l.nonEmptyPixels) : 0.0;
}

std::uint64_t pyramidBytes(const MapInfo& info) {
    std::uint64_t total = 0;
    for (const LevelInfo& l : info.levels) total += l.storedBytes;
    return total;
}

}  // namespace

Json studyToleranceAndSpp(const Config& config, const Scene& scene, const std::string& name) {
    Json out;
    out["scene"] = name;
    out["resolution"] = config.resolution;
    out["reference_spp"] = config.referenceSpp;
    out["reference_tolerance"] = config.referenceTolerance;
    out["max_uncompressed_spp"] = config.maxUncompressedSpp;
    out["queries"] = config.queries;

    // The converged reference: many samples, another seed, and a tolerance far
    // below any tested one (an uncompressed map at 4096 samples per pixel would
    // take gigabytes: hair and volume samples rarely share depths).
    const auto referencePath = gridMapPath(config, name, config.referenceSpp, -1.0);
    const double referenceSeconds = timed([&] {
        buildWith(scene, config.resolution, config.referenceSpp, config.referenceTolerance, 2,
                  referencePath.string(), config.threads);
    });
    std::printf("  %s: reference (%u spp) built in %.1f s\n", name.c_str(), config.referenceSpp, referenceSeconds);
    const auto reference = DeepShadowMap::open(referencePath.string());
    out["reference_build_seconds"] = referenceSeconds;
    out["reference_file_bytes"] = reference->info().fileBytes;

    LookupOptions bilinear;  // box of width 1 at level 0: bilinear between pixel centres
    bilinear.level = 0;
    const std::vector<Query> queries = makeQueries(*reference, config.queries, false, 11);
    const std::vector<double> truth = lookupAll(reference, queries, bilinear);

    Json rows = Json::array();
    for (const std::uint32_t n : config.spp) {
        std::vector<double> uncompressed;
        for (const double factor : config.toleranceFactors) {
            // Uncompressed maps grow with N (every sample's vertices): only small N.
            if (factor == 0.0 && n > config.maxUncompressedSpp) continue;
            const double tolerance = factor * 0.25 / std::sqrt(double(n));
            const auto path = gridMapPath(config, name, n, factor);
            const BuildStats stats = buildWith(scene, config.resolution, n, tolerance, 1, path.string(), config.threads);
            const auto map = DeepShadowMap::open(path.string());
            const std::vector<double> values = lookupAll(map, queries, bilinear);
            if (factor == 0.0) uncompressed = values;
            const MapInfo& info = map->info();
            Json row{{"spp", n},
                     {"tolerance_factor", factor},
                     {"tolerance", tolerance},
                     {"build_seconds", stats.wallSeconds},
                     {"sampling_seconds", stats.samplingSeconds},
                     {"compression_seconds", stats.compressionSeconds},
                     {"file_bytes", info.fileBytes},
                     {"level0_bytes", info.levels[0].storedBytes},
                     {"pyramid_ratio", double(pyramidBytes(info)) / double(std::max<std::uint64_t>(1, info.levels[0].storedBytes))},
                     {"raw_sample_bytes", stats.rawBytes},
                     {"mean_vertices", meanVertices(info)},
                     {"non_empty_pixels", info.levels[0].nonEmptyPixels},
                     {"error_bound", info.levels[0].errorBound},
                     {"seconds_per_lookup", secondsPerLookup(map, queries, bilinear)},
                     {"error_vs_reference", toJson(compare(values, truth))}};
            if (!uncompressed.empty()) row["error_vs_uncompressed"] = toJson(compare(values, uncompressed));
            char compression[48] = "";
            if (row.contains("error_vs_uncompressed"))
                std::snprintf(compression, sizeof compression, " (compression %.4f)",
                              row["error_vs_uncompressed"]["max"].get<double>());
            std::printf("  %s: N=%4u eps=%.4f  %8.2f s  %9llu bytes  %.2f vertices  max err %.4f%s\n", name.c_str(), n,
                        tolerance, stats.wallSeconds, static_cast<unsigned long long>(info.fileBytes),
                        meanVertices(info), row["error_vs_reference"]["max"].get<double>(), compression);
            std::fflush(stdout);
            rows.push_back(std::move(row));
        }
    }
    out["rows"] = std::move(rows);
    return out;
}

}  // namespace dsm::trade
