// Study 1 (tolerance x samples per pixel) with, from the same maps, vertex
// growth (Lokovic & Veach Fig. 8) and the mip pyramid's overhead (§5.3).
#include <cmath>
#include <cstdio>
#include <random>

#include <dsm/reference_tracer.h>

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

/// The exact value of the pixel under each query (at a pixel centre): the
/// box-filtered visibility at depth z, i.e. the mean over the pixel's area and
/// the shutter of the transmittance from the near plane to depth z along the
/// light's rays, estimated with side x side stratified jittered rays traced
/// through the real scene by the Embree reference tracer (independent of the
/// sampler). Its own error is about 0.5 / side at an opaque edge, far less
/// elsewhere.
std::vector<double> rayTracedTruth(const Scene& scene, const MapInfo& info, const std::vector<Query>& queries,
                                   int side) {
    const ReferenceTracer tracer(scene);
    const LightCamera& c = info.camera;
    const auto& m = c.worldToLight;  // rigid: world = R^T (light - t)
    auto toWorld = [&](const Vec3& l) {
        const Vec3 d{l[0] - m[3], l[1] - m[7], l[2] - m[11]};
        return Vec3{m[0] * d[0] + m[4] * d[1] + m[8] * d[2], m[1] * d[0] + m[5] * d[1] + m[9] * d[2],
                    m[2] * d[0] + m[6] * d[1] + m[10] * d[2]};
    };
    auto lightPoint = [&](double rx, double ry, double z) {
        const auto& w = c.screenWindow;
        const double sx = w[0] + rx / info.width * (w[1] - w[0]), sy = w[3] - ry / info.height * (w[3] - w[2]);
        return c.projection == Projection::Perspective ? Vec3{sx * z, sy * z, z} : Vec3{sx, sy, z};
    };
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::vector<double> out;
    out.reserve(queries.size());
    for (const Query& q : queries) {
        const double x0 = std::floor(q.x), y0 = std::floor(q.y);
        const double near = std::max(c.nearPlane, 1e-9);
        double sum = 0.0;
        for (int j = 0; j < side; ++j)
            for (int i = 0; i < side; ++i) {
                const double rx = x0 + (i + unit(rng)) / side, ry = y0 + (j + unit(rng)) / side;
                const double time = (j * side + i + unit(rng)) / (side * side);
                if (q.z <= near) {
                    sum += 1.0;
                    continue;
                }
                sum += tracer.transmittance(toWorld(lightPoint(rx, ry, near)), toWorld(lightPoint(rx, ry, q.z)),
                                            std::min(time, 0.999999))[0];
            }
        out.push_back(sum / (side * side));
    }
    return out;
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
    bilinear.bias = 0.0;     // the maps as stored: the study measures them, not a receiver's bias
    bilinear.level = 0;
    const std::vector<Query> queries = makeQueries(*reference, config.queries, false, 11);
    const std::vector<double> truth = lookupAll(reference, queries, bilinear);
    // Independent truth at pixel centres, where a bilinear lookup is exactly
    // the pixel's value.
    const std::vector<Query> centres = makeQueries(*reference, config.tracedQueries, true, 13);
    std::vector<double> traced;
    const double tracedSeconds =
        timed([&] { traced = rayTracedTruth(scene, reference->info(), centres, config.tracedRaysPerSide); });
    out["traced_queries"] = centres.size();
    out["traced_rays_per_query"] = config.tracedRaysPerSide * config.tracedRaysPerSide;
    out["traced_seconds"] = tracedSeconds;
    out["reference_error_vs_traced"] = toJson(compare(lookupAll(reference, centres, bilinear), traced));

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
            row["error_vs_traced"] = toJson(compare(lookupAll(map, centres, bilinear), traced));
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
