// Studies 2 and 4: deep shadow maps against conventional depth shadow maps
// with percentage-closer filtering (Lokovic & Veach §6, Figs. 7 and 9).
//
// Fig. 7's rule: the same number of depth samples. A deep map of R x R pixels
// with N samples each faces a depth map of R sqrt(N) x R sqrt(N) pixels whose
// PCF lookup reads the N depth pixels under one deep pixel. Both estimate the
// same quantity, the box-filtered visibility over that deep pixel, so both are
// queried at deep pixel centres and compared with the converged reference
// map's pixel there.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "depth_shadow_map.h"

#include "trade.h"

namespace dsm::trade {

namespace {

/// PCF lookups of deep-map queries in a depth map `scale` times finer.
std::vector<double> pcfAll(const DepthShadowMap& depth, const std::vector<Query>& queries, double scale,
                           double deepWidth, unsigned sampledGrid) {
    std::vector<double> out;
    out.reserve(queries.size());
    for (std::size_t i = 0; i < queries.size(); ++i) {
        const Query& q = queries[i];
        out.push_back(sampledGrid ? depth.lookupRasterSampled(q.x * scale, q.y * scale, q.z, deepWidth * scale,
                                                              sampledGrid, i)
                                  : depth.lookupRaster(q.x * scale, q.y * scale, q.z, deepWidth * scale));
    }
    return out;
}

double pcfSecondsPerLookup(const DepthShadowMap& depth, const std::vector<Query>& queries, double scale,
                           double deepWidth, unsigned sampledGrid, int repeats = 3) {
    double best = std::numeric_limits<double>::infinity(), sink = 0.0;
    for (int r = 0; r < repeats; ++r)
        best = std::min(best, timed([&] {
                            for (double v : pcfAll(depth, queries, scale, deepWidth, sampledGrid)) sink += v;
                        }));
    if (sink == -1.0) std::printf("%g\n", sink);
    return best / static_cast<double>(std::max<std::size_t>(1, queries.size()));
}

bool isSquare(std::uint32_t n) {
    const auto r = static_cast<std::uint32_t>(std::lround(std::sqrt(double(n))));
    return r * r == n;
}

}  // namespace

Json studyDeepVersusNormal(const Config& config, const Scene& scene, const std::string& name) {
    Json out;
    out["scene"] = name;
    out["deep_resolution"] = config.resolution;
    const auto reference = DeepShadowMap::open(gridMapPath(config, name, config.referenceSpp, -1.0).string());
    LookupOptions pixel;
    pixel.bias = 0.0;  // the maps as stored: the study measures them, not a receiver's bias
    pixel.level = 0;
    const std::vector<Query> queries = makeQueries(*reference, config.queries, true, 23);
    const std::vector<double> truth = lookupAll(reference, queries, pixel);

    Json rows = Json::array();
    for (const std::uint32_t n : config.spp) {
        if (!isSquare(n)) continue;
        const auto side = static_cast<std::uint32_t>(std::lround(std::sqrt(double(n))));
        // The deep map compressed at half the expected error 0.5/sqrt(N), as LV.
        const auto deepPath = gridMapPath(config, name, n, 1.0);
        const auto deep = DeepShadowMap::open(deepPath.string());
        const std::vector<double> deepValues = lookupAll(deep, queries, pixel);

        DepthMapOptions depthOptions;
        depthOptions.width = depthOptions.height = config.resolution * side;
        if (config.threads != 0) depthOptions.threads = config.threads;  // 0: all cores
        DepthShadowMap depth;
        const double depthSeconds = timed([&] { depth = DepthShadowMap::render(scene, depthOptions); });
        const std::uint64_t exrBytes = depth.writeExr((config.workDir / (name + "-depth.exr")).string());
        const double scale = side;
        const std::vector<double> pcfValues = pcfAll(depth, queries, scale, 1.0, 0);
        const std::vector<double> sampledValues = pcfAll(depth, queries, scale, 1.0, side);

        std::uint64_t level0 = deep->info().levels[0].storedBytes;
        Json row{{"spp", n},
                 {"expected_error", 0.5 / std::sqrt(double(n))},
                 {"deep",
                  {{"file_bytes", deep->info().fileBytes},
                   {"level0_bytes", level0},
                   {"seconds_per_lookup", secondsPerLookup(deep, queries, pixel)},
                   {"error", toJson(compare(deepValues, truth))}}},
                 {"normal",
                  {{"resolution", *depthOptions.width},
                   {"bytes", depth.bytes()},
                   {"exr_bytes", exrBytes},
                   {"render_seconds", depthSeconds},
                   {"seconds_per_lookup", pcfSecondsPerLookup(depth, queries, scale, 1.0, 0)},
                   {"error", toJson(compare(pcfValues, truth))},
                   {"sampled_seconds_per_lookup", pcfSecondsPerLookup(depth, queries, scale, 1.0, side)},
                   {"sampled_error", toJson(compare(sampledValues, truth))}}}};
        std::printf("  %s: N=%4u deep %8llu B  err %.4f | normal %4u^2 %9llu B  err %.4f  (sampled %.4f)\n",
                    name.c_str(), n, static_cast<unsigned long long>(deep->info().fileBytes),
                    row["deep"]["error"]["max"].get<double>(), *depthOptions.width,
                    static_cast<unsigned long long>(depth.bytes()), row["normal"]["error"]["max"].get<double>(),
                    row["normal"]["sampled_error"]["max"].get<double>());
        std::fflush(stdout);
        rows.push_back(std::move(row));
    }
    out["rows"] = std::move(rows);
    return out;
}

Json studyFilterWidth(const Config& config, const Scene& scene, const std::string& name) {
    // The pair at 64 samples per pixel (LV's Fig. 9 filters normal maps with
    // 8 x 8 samples), or the largest square spp of the run below it.
    std::uint32_t n = 0;
    for (const std::uint32_t s : config.spp)
        if (isSquare(s) && s <= 64) n = std::max(n, s);
    Json out;
    if (n == 0) return out;
    const auto side = static_cast<std::uint32_t>(std::lround(std::sqrt(double(n))));
    const auto deep = DeepShadowMap::open(gridMapPath(config, name, n, 1.0).string());
    DepthMapOptions depthOptions;
    depthOptions.width = depthOptions.height = config.resolution * side;
    if (config.threads != 0) depthOptions.threads = config.threads;  // 0: all cores
    const DepthShadowMap depth = DepthShadowMap::render(scene, depthOptions);
    const std::vector<Query> queries = makeQueries(*deep, config.queries, false, 31);
    // The exact PCF reads every depth pixel of the footprint: keep its query
    // count small enough for wide filters.
    const std::vector<Query> fewQueries(queries.begin(), queries.begin() + std::min<std::size_t>(queries.size(), 1000));
    out["scene"] = name;
    out["spp"] = n;
    out["deep_resolution"] = config.resolution;
    out["normal_resolution"] = *depthOptions.width;
    Json rows = Json::array();
    for (double width = 1.0; width <= config.resolution / 2.0; width *= 2.0) {
        LookupOptions mipmapped;
        mipmapped.bias = 0.0;
        mipmapped.filterWidth = width;
        LookupOptions level0 = mipmapped;
        level0.level = 0;
        Json row{{"width", width},
                 {"width_fraction", width / config.resolution},
                 {"deep_mipmapped_seconds", secondsPerLookup(deep, queries, mipmapped)},
                 {"deep_level0_seconds", secondsPerLookup(deep, fewQueries, level0)},
                 {"pcf_exact_seconds", pcfSecondsPerLookup(depth, fewQueries, side, width, 0, 1)},
                 {"pcf_8x8_seconds", pcfSecondsPerLookup(depth, queries, side, width, 8)}};
        std::printf("  %s: width %5.1f  deep %.3g s  deep level 0 %.3g s  pcf %.3g s  pcf 8x8 %.3g s\n", name.c_str(),
                    width, row["deep_mipmapped_seconds"].get<double>(), row["deep_level0_seconds"].get<double>(),
                    row["pcf_exact_seconds"].get<double>(), row["pcf_8x8_seconds"].get<double>());
        std::fflush(stdout);
        rows.push_back(std::move(row));
    }
    out["rows"] = std::move(rows);
    return out;
}

}  // namespace dsm::trade
