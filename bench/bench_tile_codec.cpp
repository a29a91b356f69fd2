// Size and decode speed of the tile coding of a map, against references
// measured in the same run: the same pixels encoded as 1.0 tiles (raw float
// arrays, zlib at the map's level), and zlib's inflate alone of the map's
// stored bytes. Prints, per map:
//   - bytes of each level and of the pyramid, 1.1 against 1.0, the pyramid
//     over level 0 and the bytes per stored vertex at level 0;
//   - decode throughput (CRC, inflate, parse, checks) over plain inflate of
//     the same stored bytes (a ratio of times, best of several rounds);
//   - a cold tile read + decode (from the file, no tile cache) in us per tile.
//
//   bench_tile_codec [--smoke] MAP...     (--smoke: a small generated map)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <zlib.h>

#include "dsm/dsm.h"
#include "tile_codec.h"

namespace {

using Clock = std::chrono::steady_clock;

struct StoredTile {
    dsm::TileSummary summary;
    std::vector<std::uint8_t> bytes;
    std::uint32_t width, height, originX, originY;
    unsigned level;
};

std::vector<std::uint8_t> readAll(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

template <class F>
double bestSeconds(int rounds, F&& run) {
    double best = 1e30;
    for (int r = 0; r < rounds; ++r) {
        const auto start = Clock::now();
        run();
        best = std::min(best, std::chrono::duration<double>(Clock::now() - start).count());
    }
    return best;
}

void measure(const std::string& path, int rounds) {
    const auto map = dsm::DeepShadowMap::open(path);
    const dsm::MapInfo& info = map->info();
    const std::vector<std::uint8_t> file = readAll(path);
    std::vector<StoredTile> tiles;
    for (unsigned l = 0; l < info.levels.size(); ++l) {
        const dsm::LevelInfo& L = info.levels[l];
        for (std::uint32_t ty = 0; ty < L.tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < L.tilesX; ++tx) {
                StoredTile t;
                t.summary = map->tile(l, tx, ty);
                if (t.summary.empty()) continue;
                t.bytes.assign(file.begin() + static_cast<std::ptrdiff_t>(t.summary.offset),
                               file.begin() + static_cast<std::ptrdiff_t>(t.summary.offset + t.summary.storedBytes));
                t.width = std::min(info.tileSize, L.width - tx * info.tileSize);
                t.height = std::min(info.tileSize, L.height - ty * info.tileSize);
                t.originX = tx * info.tileSize;
                t.originY = ty * info.tileSize;
                t.level = l;
                tiles.push_back(std::move(t));
            }
    }

    // Sizes: as stored, and the same pixels as 1.0 tiles at the map's zlib level.
    const int zlibLevel = info.codecLevel >= 0 ? info.codecLevel : 6;
    std::vector<std::uint64_t> oldBytes(info.levels.size(), 0);
    std::vector<dsm::format::EncodedTile> oldTiles;
    for (const StoredTile& t : tiles) {
        std::vector<dsm::VisibilityFunction> pixels;
        for (std::uint32_t y = 0; y < t.height; ++y)
            for (std::uint32_t x = 0; x < t.width; ++x)
                pixels.push_back(map->pixel(t.level, t.originX + x, t.originY + y)->toFunction());
        const dsm::format::TileLayout plain{info.channels, info.hasCounts, info.maxLayers, false, 0.0};
        oldTiles.push_back(dsm::format::encodeTile(pixels, plain, zlibLevel));
        oldBytes[t.level] += oldTiles.back().stored.size();
    }
    std::uint64_t total = 0, oldTotal = 0;
    std::printf("%s: format %d.%d, %s tiles, zlib level %d\n", path.c_str(), info.versionMajor, info.versionMinor,
                info.codedTiles ? "coded" : "1.0", zlibLevel);
    std::printf("  level  tolerance  value step  vertices     bytes     1.0 bytes  ratio\n");
    for (unsigned l = 0; l < info.levels.size(); ++l) {
        const dsm::LevelInfo& L = info.levels[l];
        total += L.storedBytes;
        oldTotal += oldBytes[l];
        std::printf("  %5u  %9.4g  %10.4g  %9llu  %10llu  %10llu  %5.3f\n", l, L.tolerance, L.valueStep,
                    static_cast<unsigned long long>(L.vertexCount), static_cast<unsigned long long>(L.storedBytes),
                    static_cast<unsigned long long>(oldBytes[l]),
                    oldBytes[l] ? double(L.storedBytes) / double(oldBytes[l]) : 0.0);
    }
    const dsm::LevelInfo& base = info.levels[0];
    std::printf("  all levels: %llu bytes (1.0 tiles: %llu, ratio %.3f); file %llu bytes\n",
                static_cast<unsigned long long>(total), static_cast<unsigned long long>(oldTotal),
                oldTotal ? double(total) / double(oldTotal) : 0.0, static_cast<unsigned long long>(info.fileBytes));
    std::printf("  pyramid / level 0: %.3f; bytes per stored vertex at level 0: %.3f (1.0 tiles: %.3f)\n",
                base.storedBytes ? double(total) / double(base.storedBytes) : 0.0,
                base.vertexCount ? double(base.storedBytes) / double(base.vertexCount) : 0.0,
                base.vertexCount ? double(oldBytes[0]) / double(base.vertexCount) : 0.0);

    // Decode against plain inflate of the same stored bytes.
    std::vector<std::uint8_t> scratch;
    std::uint64_t inflatedBytes = 0;
    const double inflateSeconds = bestSeconds(rounds, [&] {
        inflatedBytes = 0;
        for (const StoredTile& t : tiles) {
            if (t.summary.storedBytes == t.summary.rawBytes) continue;  // stored: nothing to inflate
            scratch.resize(t.summary.rawBytes);
            uLongf size = t.summary.rawBytes;
            uncompress(scratch.data(), &size, t.bytes.data(), static_cast<uLong>(t.bytes.size()));
            inflatedBytes += size;
        }
    });
    const dsm::ReaderOptions limits;
    std::size_t decodedVertices = 0;
    const double decodeSeconds = bestSeconds(rounds, [&] {
        decodedVertices = 0;
        for (const StoredTile& t : tiles) {
            const dsm::format::DecodedTile d = dsm::format::decodeTile(
                t.bytes, t.summary, t.width, t.height,
                {info.channels, info.hasCounts, info.maxLayers, info.codedTiles, info.levels[t.level].valueStep},
                limits, "bench", t.originX, t.originY);
            decodedVertices += d.records()[d.pixelCount()].vertexStart;
        }
    });
    std::printf("  decode of %zu tiles (%llu vertices): %.2f ms; zlib inflate alone of the same bytes: %.2f ms; "
                "decode throughput / inflate throughput = %.3f\n",
                tiles.size(), static_cast<unsigned long long>(decodedVertices), decodeSeconds * 1e3,
                inflateSeconds * 1e3, decodeSeconds > 0.0 ? inflateSeconds / decodeSeconds : 0.0);

    const double oldDecodeSeconds = bestSeconds(rounds, [&] {
        for (std::size_t i = 0; i < tiles.size(); ++i) {
            const StoredTile& t = tiles[i];
            dsm::format::decodeTile(oldTiles[i].stored, oldTiles[i].summary, t.width, t.height,
                                    {info.channels, info.hasCounts, info.maxLayers, false, 0.0}, limits, "bench",
                                    t.originX, t.originY);
        }
    });
    std::printf("  decode of the same pixels as 1.0 tiles: %.2f ms (coded / 1.0 decode time %.3f)\n",
                oldDecodeSeconds * 1e3, oldDecodeSeconds > 0.0 ? decodeSeconds / oldDecodeSeconds : 0.0);

    // Cold read + decode: every tile from the file, through no cache.
    const double validateSeconds = bestSeconds(rounds, [&] { dsm::validate(path); });
    std::printf("  cold tile read + decode (validate(), no cache): %.1f us per tile (%zu non-empty tiles)\n",
                tiles.empty() ? 0.0 : validateSeconds * 1e6 / double(tiles.size()), tiles.size());
}

std::string smokeMap() {
    const std::string path = "bench_tile_codec_smoke.dsm";
    dsm::WriterOptions o;
    o.width = 40;
    o.height = 24;
    o.tileSize = 16;
    o.tolerance = 0.02;
    o.quantiseValues = true;
    dsm::MapWriter writer(path, o);
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> gap(0.0f, 0.2f), drop(0.0f, 0.2f);
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<dsm::VisibilityFunction> pixels;
            for (std::uint32_t p = 0; p < writer.tileWidth(tx) * writer.tileHeight(ty); ++p) {
                dsm::VisibilityFunction f;
                float z = 1.0f, v = 1.0f;
                for (int i = 0; i < 6; ++i) f.append(z += gap(rng), v = std::max(0.0f, v - drop(rng)));
                pixels.push_back(dsm::roundValues(f, dsm::valueStep(o.tolerance)));
            }
            writer.writeTile(tx, ty, pixels);
        }
    writer.finish();
    return path;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> maps;
    bool smoke = false;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg == "--smoke") smoke = true;
        else maps.push_back(arg);
    }
    try {
        if (smoke) maps = {smokeMap()};
        if (maps.empty()) {
            std::fprintf(stderr, "usage: bench_tile_codec [--smoke] MAP...\n");
            return 2;
        }
        for (const std::string& path : maps) measure(path, smoke ? 1 : 5);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_tile_codec: ERROR: %s\n", e.what());
        return 1;
    }
    return 0;
}
