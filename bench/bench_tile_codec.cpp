// Size and decode speed of the tile coding of a map, against references
// measured in the same run: the same pixels encoded as 1.0 tiles (raw float
// arrays, zlib at the map's level), and zlib's inflate alone of the map's
// stored bytes. Prints, per map:
//   - bytes of each level and of the pyramid, 1.1 against 1.0, the pyramid
//     over level 0 and the bytes per stored vertex at level 0;
//   - decode throughput (CRC, inflate, parse, checks) over plain inflate of
//     the same stored bytes (a ratio of times, best of several rounds);
//   - the same raw tile bytes compressed with zstd at a few levels: size and
//     decompression time against zlib's inflate (same run);
//   - a cold read + decode per level-0 tile: the file's pages dropped from the
//     page cache (posix_fadvise DONTNEED) before each tile, which is then read
//     and decoded through a map without a tile cache; beside it, in turn, the
//     device's floor: a cold pread() of the same stored bytes alone; and the
//     same two warm.
//
//   bench_tile_codec [--smoke] [--decode-only] [--rounds=N] MAP...
//     --smoke: a small generated map; --decode-only: the decode and inflate
//     timings alone (with --rounds=1, for a profiler such as callgrind);
//     --rounds: timing rounds (5; the decode ratio takes twice as many)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

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

// The tile's bytes after decompression.
std::vector<std::uint8_t> rawBytes(const StoredTile& t) {
    if (t.summary.storedBytes == t.summary.rawBytes) return t.bytes;
    std::vector<std::uint8_t> raw(t.summary.rawBytes);
    uLongf size = t.summary.rawBytes;
    if (uncompress(raw.data(), &size, t.bytes.data(), static_cast<uLong>(t.bytes.size())) != Z_OK || size != raw.size())
        throw std::runtime_error("zlib cannot inflate a tile");
    return raw;
}

// The raw bytes of every tile compressed with zstd at a few levels (kept
// stored when zstd does not make them smaller, as the writer does with zlib):
// total size against zlib's, and decompression time against inflate's.
void measureZstd(const std::vector<StoredTile>& tiles, double inflateSeconds, int rounds) {
    std::vector<std::vector<std::uint8_t>> raws;
    std::uint64_t zlibTotal = 0, rawTotal = 0;
    for (const StoredTile& t : tiles) {
        raws.push_back(rawBytes(t));
        zlibTotal += t.bytes.size();
        rawTotal += raws.back().size();
    }
    std::printf("  zstd on the same raw tile bytes (%llu raw bytes; zlib as stored: %llu bytes, inflate %.2f ms):\n",
                static_cast<unsigned long long>(rawTotal), static_cast<unsigned long long>(zlibTotal),
                inflateSeconds * 1e3);
    ZSTD_CCtx* cctx = ZSTD_createCCtx();
    ZSTD_DCtx* dctx = ZSTD_createDCtx();
    for (const int level : {1, 3, 9, 19}) {
        std::vector<std::vector<std::uint8_t>> packed;
        std::uint64_t total = 0;
        for (const std::vector<std::uint8_t>& raw : raws) {
            std::vector<std::uint8_t> out(ZSTD_compressBound(raw.size()));
            const std::size_t n = ZSTD_compressCCtx(cctx, out.data(), out.size(), raw.data(), raw.size(), level);
            if (ZSTD_isError(n)) throw std::runtime_error(ZSTD_getErrorName(n));
            out.resize(n);
            total += std::min(n, raw.size());
            packed.push_back(n < raw.size() ? std::move(out) : std::vector<std::uint8_t>());
        }
        std::vector<std::uint8_t> scratch;
        const double seconds = bestSeconds(rounds, [&] {
            for (std::size_t i = 0; i < raws.size(); ++i) {
                if (packed[i].empty()) continue;  // stored: nothing to decompress
                scratch.resize(raws[i].size());
                const std::size_t n =
                    ZSTD_decompressDCtx(dctx, scratch.data(), scratch.size(), packed[i].data(), packed[i].size());
                if (n != raws[i].size()) throw std::runtime_error("zstd cannot decompress a tile");
            }
        });
        std::printf("    zstd level %2d: %llu bytes (%.3f x zlib), decompression %.2f ms (%.2f x faster than inflate)\n",
                    level, static_cast<unsigned long long>(total), zlibTotal ? double(total) / double(zlibTotal) : 0.0,
                    seconds * 1e3, seconds > 0.0 ? inflateSeconds / seconds : 0.0);
    }
    ZSTD_freeDCtx(dctx);
    ZSTD_freeCCtx(cctx);
}

// Microseconds per level-0 tile, each tile once: a read + decode through a
// map without a tile cache, and a plain pread() of the same stored bytes
// (the device's floor), the two in turn (which goes first alternates from
// tile to tile). With `cold`, the file's pages are dropped from the page
// cache (posix_fadvise DONTNEED, not timed) before each, so that every read
// reaches the disk.
struct TileReadTimes {
    std::vector<double> decoded, pread;
};
TileReadTimes tileReadMicroseconds(const std::string& path, const std::vector<StoredTile>& tiles, bool cold) {
    dsm::ReaderOptions options;
    options.cache = dsm::TileCache::create(0);
    const auto map = dsm::DeepShadowMap::open(path, options);
    const int fd = ::open(path.c_str(), O_RDONLY);
    if (fd < 0) throw std::runtime_error("cannot open " + path);
    TileReadTimes times;
    std::vector<std::uint8_t> bytes;
    bool preadFirst = false;
    for (const StoredTile& t : tiles) {
        if (t.level != 0) continue;
        preadFirst = !preadFirst;
        for (int k = 0; k < 2; ++k) {
            if (cold) posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
            const auto start = Clock::now();
            if ((k == 0) == preadFirst) {
                bytes.resize(t.summary.storedBytes);
                if (::pread(fd, bytes.data(), bytes.size(), static_cast<off_t>(t.summary.offset)) !=
                    static_cast<ssize_t>(bytes.size()))
                    throw std::runtime_error("cannot read a tile of " + path);
                times.pread.push_back(std::chrono::duration<double, std::micro>(Clock::now() - start).count());
            } else {
                const dsm::PixelFunction f = map->pixel(0, t.originX, t.originY);
                times.decoded.push_back(std::chrono::duration<double, std::micro>(Clock::now() - start).count());
            }
        }
    }
    ::close(fd);
    return times;
}

void measureColdReads(const std::string& path, const std::vector<StoredTile>& tiles) {
    const auto median = [](std::vector<double> times) {
        std::sort(times.begin(), times.end());
        return times.empty() ? 0.0 : times[times.size() / 2];
    };
    const auto mean = [](const std::vector<double>& times) {
        double sum = 0.0;
        for (double t : times) sum += t;
        return times.empty() ? 0.0 : sum / double(times.size());
    };
    for (const bool cold : {true, false}) {
        const TileReadTimes times = tileReadMicroseconds(path, tiles, cold);
        if (times.decoded.empty()) return;
        const double decoded = median(times.decoded), floor = median(times.pread);
        std::printf("  %s, per level-0 tile (%zu tiles): read + decode median %.1f us (mean %.1f); pread of the same "
                    "bytes alone median %.1f us (mean %.1f); read + decode / pread = %.2f\n",
                    cold ? "cold (page cache dropped before each read)" : "warm (file in the page cache)",
                    times.decoded.size(), decoded, mean(times.decoded), floor, mean(times.pread),
                    floor > 0.0 ? decoded / floor : 0.0);
    }
}

void measure(const std::string& path, int rounds, bool decodeOnly) {
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
    const int zlibLevel = info.codec == dsm::TileCodec::Zlib && info.codecLevel >= 0 ? info.codecLevel : 6;
    std::vector<std::uint64_t> oldBytes(info.levels.size(), 0), recodedBytes(info.levels.size(), 0);
    std::vector<dsm::format::EncodedTile> oldTiles;
    for (const StoredTile& t : tiles) {
        if (decodeOnly) break;
        std::vector<dsm::VisibilityFunction> pixels;
        for (std::uint32_t y = 0; y < t.height; ++y)
            for (std::uint32_t x = 0; x < t.width; ++x)
                pixels.push_back(map->pixel(t.level, t.originX + x, t.originY + y)->toFunction());
        const dsm::format::TileLayout plain{info.channels, info.hasCounts, info.maxLayers, false, 0.0};
        oldTiles.push_back(dsm::format::encodeTile(pixels, plain, zlibLevel));
        oldBytes[t.level] += oldTiles.back().stored.size();
        const dsm::format::TileLayout coded{info.channels, info.hasCounts, info.maxLayers, true,
                                            info.levels[t.level].valueStep};
        recodedBytes[t.level] += dsm::format::encodeTile(pixels, coded, zlibLevel).stored.size();
    }
    std::uint64_t total = 0, oldTotal = 0, recodedTotal = 0;
    std::printf("%s: format %d.%d, %s tiles, %s level %d (1.0 tiles here at zlib level %d)\n", path.c_str(),
                info.versionMajor, info.versionMinor, info.codedTiles ? "coded" : "1.0",
                info.codec == dsm::TileCodec::Zstd ? "zstd" : "zlib", info.codecLevel, zlibLevel);
    std::printf("  level  tolerance  value step  vertices     bytes     1.0 bytes  ratio  this build's coding\n");
    for (unsigned l = 0; l < info.levels.size(); ++l) {
        const dsm::LevelInfo& L = info.levels[l];
        total += L.storedBytes;
        oldTotal += oldBytes[l];
        recodedTotal += recodedBytes[l];
        std::printf("  %5u  %9.4g  %10.4g  %9llu  %10llu  %10llu  %5.3f  %10llu\n", l, L.tolerance, L.valueStep,
                    static_cast<unsigned long long>(L.vertexCount), static_cast<unsigned long long>(L.storedBytes),
                    static_cast<unsigned long long>(oldBytes[l]),
                    oldBytes[l] ? double(L.storedBytes) / double(oldBytes[l]) : 0.0,
                    static_cast<unsigned long long>(recodedBytes[l]));
    }
    std::printf("  all levels re-encoded by this build's tile coding at zlib level %d: %llu bytes\n", zlibLevel,
                static_cast<unsigned long long>(recodedTotal));
    const dsm::LevelInfo& base = info.levels[0];
    std::printf("  all levels: %llu bytes (1.0 tiles: %llu, ratio %.3f); file %llu bytes\n",
                static_cast<unsigned long long>(total), static_cast<unsigned long long>(oldTotal),
                oldTotal ? double(total) / double(oldTotal) : 0.0, static_cast<unsigned long long>(info.fileBytes));
    std::printf("  pyramid / level 0: %.3f; bytes per stored vertex at level 0: %.3f (1.0 tiles: %.3f)\n",
                base.storedBytes ? double(total) / double(base.storedBytes) : 0.0,
                base.vertexCount ? double(base.storedBytes) / double(base.vertexCount) : 0.0,
                base.vertexCount ? double(oldBytes[0]) / double(base.vertexCount) : 0.0);

    // Decode against plain inflate of the same stored bytes, the two timed
    // in turn in each round (so that both see the same load), best of each.
    std::vector<std::uint8_t> scratch;
    const dsm::ReaderOptions limits;
    std::size_t decodedVertices = 0;
    // (A zstd map: against zstd's decompression alone, with one context kept
    // for every tile, as the decoder keeps them.)
    const bool zstd = info.codec == dsm::TileCodec::Zstd;
    const std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> zstdContext(ZSTD_createDCtx(), &ZSTD_freeDCtx);
    const auto inflateAll = [&] {
        for (const StoredTile& t : tiles) {
            if (t.summary.storedBytes == t.summary.rawBytes) continue;  // stored: nothing to inflate
            scratch.resize(t.summary.rawBytes);
            uLongf size = t.summary.rawBytes;
            if (zstd) ZSTD_decompressDCtx(zstdContext.get(), scratch.data(), scratch.size(), t.bytes.data(), t.bytes.size());
            else uncompress(scratch.data(), &size, t.bytes.data(), static_cast<uLong>(t.bytes.size()));
        }
    };
    const auto decodeAll = [&] {
        decodedVertices = 0;
        for (const StoredTile& t : tiles) {
            dsm::format::TileLayout layout{info.channels, info.hasCounts, info.maxLayers, info.codedTiles,
                                           info.levels[t.level].valueStep};
            layout.codec = info.codec;
            layout.predictedDepths = info.predictedDepths;
            const dsm::format::DecodedTile d = dsm::format::decodeTile(t.bytes, t.summary, t.width, t.height, layout,
                                                                       limits, "bench", t.originX, t.originY);
            decodedVertices += d.records()[d.pixelCount()].vertexStart;
        }
    };
    double inflateSeconds = 1e30, decodeSeconds = 1e30;
    for (int r = 0; r < 2 * rounds; ++r) {
        inflateSeconds = std::min(inflateSeconds, bestSeconds(1, inflateAll));
        decodeSeconds = std::min(decodeSeconds, bestSeconds(1, decodeAll));
    }
    std::printf("  decode of %zu tiles (%llu vertices): %.2f ms; %s alone of the same bytes: %.2f ms; "
                "decode throughput / %s throughput = %.3f\n",
                tiles.size(), static_cast<unsigned long long>(decodedVertices), decodeSeconds * 1e3,
                zstd ? "zstd decompression" : "zlib inflate", inflateSeconds * 1e3, zstd ? "zstd" : "inflate",
                decodeSeconds > 0.0 ? inflateSeconds / decodeSeconds : 0.0);

    if (decodeOnly) return;
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

    if (!zstd) measureZstd(tiles, inflateSeconds, rounds);
    measureColdReads(path, tiles);
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
    bool smoke = false, decodeOnly = false;
    int rounds = 5;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg == "--smoke") smoke = true;
        else if (arg == "--decode-only") decodeOnly = true;
        else if (arg.rfind("--rounds=", 0) == 0) rounds = std::max(1, std::atoi(arg.c_str() + 9));
        else maps.push_back(arg);
    }
    try {
        if (smoke) maps = {smokeMap()};
        if (maps.empty()) {
            std::fprintf(stderr, "usage: bench_tile_codec [--smoke] [--decode-only] [--rounds=N] MAP...\n");
            return 2;
        }
        for (const std::string& path : maps) measure(path, smoke ? 1 : rounds, decodeOnly);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_tile_codec: ERROR: %s\n", e.what());
        return 1;
    }
    return 0;
}
