#include "trade.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace dsm::trade {

BuildStats buildWith(const Scene& scene, std::uint32_t resolution, std::uint32_t spp, double tolerance,
                     std::uint64_t seed, const std::string& path, unsigned threads, std::uint32_t tileSize) {
    BuildOptions o;
    o.width = o.height = resolution;
    o.samplesPerPixel = spp;
    o.tolerance = tolerance;
    o.filter = PixelFilter::Box;
    o.filterWidth = 1.0;
    o.tileSize = tileSize;
    o.seed = seed;
    if (threads != 0) o.threads = threads;  // 0: all cores
    return buildMap(scene, o, path);
}

std::filesystem::path gridMapPath(const Config& config, const std::string& scene, std::uint32_t spp, double factor) {
    if (factor < 0.0) return config.workDir / (scene + "-reference.dsm");
    char name[128];
    std::snprintf(name, sizeof name, "%s-n%u-e%g.dsm", scene.c_str(), spp, factor);
    return config.workDir / name;
}

std::vector<Query> makeQueries(const DeepShadowMap& map, std::size_t count, bool pixelCentres, std::uint64_t seed) {
    const MapInfo& info = map.info();
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::vector<Query> out;
    out.reserve(count);
    // Tiles with content, so that queries probe shadows rather than empty space.
    std::vector<std::pair<std::uint32_t, std::uint32_t>> tiles;
    const LevelInfo& level = info.levels[0];
    for (std::uint32_t ty = 0; ty < level.tilesY; ++ty)
        for (std::uint32_t tx = 0; tx < level.tilesX; ++tx)
            if (!map.tile(0, tx, ty).empty()) tiles.emplace_back(tx, ty);
    if (tiles.empty()) tiles.emplace_back(0, 0);
    while (out.size() < count) {
        const auto [tx, ty] = tiles[rng() % tiles.size()];
        const TileSummary t = map.tile(0, tx, ty);
        const double x0 = double(tx) * info.tileSize, y0 = double(ty) * info.tileSize;
        const double w = std::min<double>(info.tileSize, info.width - x0);
        const double h = std::min<double>(info.tileSize, info.height - y0);
        Query q;
        q.x = x0 + unit(rng) * w;
        q.y = y0 + unit(rng) * h;
        if (pixelCentres) {
            q.x = std::floor(q.x) + 0.5;
            q.y = std::floor(q.y) + 0.5;
        }
        const double zMin = t.minZ, zMax = std::max<double>(t.maxZ * 1.1, t.minZ + 1e-3);
        q.z = zMin + unit(rng) * (zMax - zMin);
        out.push_back(q);
    }
    return out;
}

std::vector<double> lookupAll(const std::shared_ptr<const DeepShadowMap>& map, const std::vector<Query>& queries,
                              const LookupOptions& options) {
    LookupContext context(map);
    std::vector<double> out;
    out.reserve(queries.size());
    for (const Query& q : queries) out.push_back(context.raster(q.x, q.y, q.z, options).v[0]);
    return out;
}

double secondsPerLookup(const std::shared_ptr<const DeepShadowMap>& map, const std::vector<Query>& queries,
                        const LookupOptions& options, int repeats) {
    LookupContext context(map);
    double sink = 0.0;
    for (const Query& q : queries) sink += context.raster(q.x, q.y, q.z, options).v[0];
    double best = std::numeric_limits<double>::infinity();
    for (int r = 0; r < repeats; ++r) {
        const double s = timed([&] {
            for (const Query& q : queries) sink += context.raster(q.x, q.y, q.z, options).v[0];
        });
        best = std::min(best, s);
    }
    // Keep the loop's result alive so the lookups cannot be optimised away.
    if (sink == -1.0) std::printf("%g\n", sink);
    return best / static_cast<double>(std::max<std::size_t>(1, queries.size()));
}

ErrorStats compare(const std::vector<double>& a, const std::vector<double>& b) {
    ErrorStats e;
    const std::size_t n = std::min(a.size(), b.size());
    double sum = 0.0, sumSquares = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const double d = std::abs(a[i] - b[i]);
        e.max = std::max(e.max, d);
        sum += d;
        sumSquares += d * d;
    }
    if (n) {
        e.mean = sum / n;
        e.rms = std::sqrt(sumSquares / n);
    }
    return e;
}

Json toJson(const ErrorStats& e) { return Json{{"max", e.max}, {"mean", e.mean}, {"rms", e.rms}}; }

}  // namespace dsm::trade
