// Study 6: lookup throughput and tiles read against the tile cache's budget,
// for receivers in scanline order (coherent) and the same receivers shuffled.
#include <algorithm>
#include <cstdio>
#include <random>

#include "trade.h"

namespace dsm::trade {

Json studyCacheBudget(const Config& config, const Scene& scene, const std::string& name) {
    const auto path = config.workDir / (name + "-cache.dsm");
    BuildOptions o;
    o.width = o.height = config.cacheResolution;
    o.samplesPerPixel = 16;
    o.tileSize = config.cacheTileSize;
    if (config.threads != 0) o.threads = config.threads;  // 0: all cores
    buildMap(scene, o, path.string());

    // Decoded bytes of every tile of every level: a budget of 100% holds the map.
    std::uint64_t decoded = 0, tiles = 0;
    {
        const auto map = DeepShadowMap::open(path.string());
        for (unsigned l = 0; l < map->info().levels.size(); ++l) {
            const LevelInfo& level = map->info().levels[l];
            for (std::uint32_t ty = 0; ty < level.tilesY; ++ty)
                for (std::uint32_t tx = 0; tx < level.tilesX; ++tx) {
                    decoded += map->tile(l, tx, ty).rawBytes;
                    ++tiles;
                }
        }
    }

    // One receiver per pixel, row by row, at a depth inside the pixel's tile
    // content; then the same receivers shuffled.
    std::vector<Query> scanline;
    {
        const auto map = DeepShadowMap::open(path.string());
        std::mt19937_64 rng(41);
        std::uniform_real_distribution<double> unit(0.0, 1.0);
        const MapInfo& info = map->info();
        for (std::uint32_t y = 0; y < info.height; ++y)
            for (std::uint32_t x = 0; x < info.width; ++x) {
                const TileSummary t = map->tile(0, x / info.tileSize, y / info.tileSize);
                const double z = t.empty() ? 1.0 : t.minZ + unit(rng) * (t.maxZ * 1.1 - t.minZ);
                scanline.push_back({x + unit(rng), y + unit(rng), z});
            }
    }
    std::vector<Query> shuffled = scanline;
    std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937_64(43));

    Json out;
    out["scene"] = name;
    out["resolution"] = config.cacheResolution;
    out["tile_size"] = config.cacheTileSize;
    out["tiles"] = tiles;
    out["decoded_bytes"] = decoded;
    out["queries"] = scanline.size();
    Json rows = Json::array();
    for (const double fraction : {0.01, 0.02, 0.05, 0.1, 0.25, 0.5, 1.0}) {
        for (const bool coherent : {true, false}) {
            const std::vector<Query>& queries = coherent ? scanline : shuffled;
            ReaderOptions reader;
            reader.cache = TileCache::create(static_cast<std::size_t>(fraction * double(decoded)));
            const auto map = DeepShadowMap::open(path.string(), reader);
            LookupOptions options;  // bilinear at level 0: the level with the most tiles
            options.bias = 0.0;
            LookupContext context(map);
            double sink = 0.0;
            const double seconds = timed([&] {
                for (const Query& q : queries) sink += context.raster(q.x, q.y, q.z, options).v[0];
            });
            if (sink == -1.0) std::printf("%g\n", sink);
            const TileCacheStats stats = reader.cache->stats();
            rows.push_back({{"budget_fraction", fraction},
                            {"order", coherent ? "scanline" : "random"},
                            {"lookups_per_second", double(queries.size()) / seconds},
                            {"tiles_read", stats.tilesRead},
                            {"bytes_read", stats.bytesRead},
                            {"hits", stats.hits},
                            {"misses", stats.misses}});
            std::printf("  %s: cache %5.1f%% %-8s %10.0f lookups/s  %7llu tiles read\n", name.c_str(),
                        100.0 * fraction, coherent ? "scanline" : "random", double(queries.size()) / seconds,
                        static_cast<unsigned long long>(stats.tilesRead));
            std::fflush(stdout);
        }
    }
    out["rows"] = std::move(rows);
    return out;
}

}  // namespace dsm::trade
