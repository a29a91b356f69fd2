// The shadow system at renderer speed: the figures of bench/COMPONENTS.md,
// "Shadow system". Every rate is measured in this run, and every ratio is
// between two measurements of this run.
//  1. warm random bilinear lookups in the hair ball (512², 16 spp, 32² tiles):
//     ShadowSystem single and batched, LookupContext, and the direct
//     evaluation of the same four functions from memory;
//  2. warm coherent (scanline order) lookups;
//  3. Gaussian width 4 and mip-blended (box width 3) lookups;
//  4. a fully cached 4096² map, random points, batched against single;
//  5. a row scan with the budget at 90 % of a tile row: tiles read against the
//     tiles of level 0, and against the optimum (Belady's MIN on the same
//     sequence of tiles and the same budget);
//  6. eight threads hammering one map with a budget of 5 % of it: duplicate
//     reads and the peak bytes held;
//  7. the per-thread state with 1 and 100 maps open.
// Timings are medians of several repetitions on one thread (except 6).
//
//   bench_shadow_system [--smoke] [--scene=FILE] [--size=N] [--spp=N] [--big-size=N] [--big-spp=N]
//                       [--repeat=N] [--keep-maps]
#include <dsm/dsm.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include <unistd.h>

#ifndef DSM_BENCH_DEFAULT_SCENE
#define DSM_BENCH_DEFAULT_SCENE "examples/hairball.json"
#endif

namespace {

using namespace dsm;
namespace fs = std::filesystem;
using Point = std::array<double, 3>;

struct Config {
    bool smoke = false;
    bool keepMaps = false;
    std::string scene = DSM_BENCH_DEFAULT_SCENE;
    std::uint32_t size = 512, spp = 16;
    std::uint32_t bigSize = 4096, bigSpp = 1;
    int repeat = 7;
    std::size_t points = 1 << 16;
};

double seconds(const std::function<void()>& f) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Median over `repeat` runs of f (each run after one untimed warm-up run).
double median(int repeat, const std::function<void()>& f) {
    f();
    std::vector<double> t;
    for (int i = 0; i < repeat; ++i) t.push_back(seconds(f));
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
}

std::string buildMapFile(const Scene& scene, std::uint32_t size, std::uint32_t spp, const fs::path& dir) {
    const std::string path = (dir / ("hair-" + std::to_string(size) + "-spp" + std::to_string(spp) + ".dsm")).string();
    if (fs::exists(path)) return path;
    BuildOptions o;
    o.width = o.height = size;
    o.samplesPerPixel = spp;
    const auto t = seconds([&] { buildMap(scene, o, path); });
    std::printf("built %s in %.1f s\n", path.c_str(), t);
    return path;
}

// Random points over the non-empty pixels, z uniform in the pixel's depths.
std::vector<Point> randomPoints(const DeepShadowMap& map, std::size_t n, std::uint64_t seed) {
    const MapInfo& info = map.info();
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<std::uint32_t> ux(0, info.width - 1), uy(0, info.height - 1);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::vector<Point> pts;
    for (std::size_t tries = 0; pts.size() < n && tries < 100 * n; ++tries) {
        const std::uint32_t x = ux(rng), y = uy(rng);
        const PixelFunction f = map.pixel(0, x, y);
        if (f->empty()) continue;
        pts.push_back({x + unit(rng), y + unit(rng), f->z(0) + (f->z(f->size() - 1) - f->z(0)) * unit(rng)});
    }
    return pts;
}

// Every pixel of level 0 in scanline order, z halfway through the pixel's
// depths (lit pixels at the map's mean depth).
std::vector<Point> scanlinePoints(const DeepShadowMap& map) {
    const MapInfo& info = map.info();
    std::vector<Point> pts;
    for (std::uint32_t y = 0; y < info.height; ++y)
        for (std::uint32_t x = 0; x < info.width; ++x) {
            const PixelFunction f = map.pixel(0, x, y);
            const double z = f->empty() ? 1.0 : 0.5 * (f->z(0) + f->z(f->size() - 1));
            pts.push_back({x + 0.37, y + 0.61, z});
        }
    return pts;
}

// The bilinear weights and pixels of a lookup at level 0, evaluated straight
// from in-memory functions: what any lookup must at least do.
struct DirectMap {
    std::uint32_t width = 0, height = 0;
    std::vector<VisibilityFunction> pixels;
    explicit DirectMap(const DeepShadowMap& map) : width(map.info().width), height(map.info().height) {
        pixels.reserve(std::size_t(width) * height);
        for (std::uint32_t y = 0; y < height; ++y)
            for (std::uint32_t x = 0; x < width; ++x) pixels.push_back(map.pixel(0, x, y).view().toFunction(false));
    }
    double bilinear(const Point& p) const {
        const double cx = p[0] - 0.5, cy = p[1] - 0.5;
        const double fx = std::floor(cx), fy = std::floor(cy);
        const long x0 = static_cast<long>(fx), y0 = static_cast<long>(fy);
        const double wx[2] = {1.0 - (cx - fx), cx - fx}, wy[2] = {1.0 - (cy - fy), cy - fy};
        double sum = 0.0, total = 0.0;
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) {
                const long x = x0 + i, y = y0 + j;
                if (x < 0 || y < 0 || x >= long(width) || y >= long(height)) continue;
                const double w = wx[i] * wy[j];
                sum += w * pixels[std::size_t(y) * width + std::size_t(x)].evaluate(p[2]);
                total += w;
            }
        return total > 0.0 ? sum / total : 1.0;
    }
};

struct Rate {
    double perSecond = 0.0;
    double nsEach = 0.0;
};

Rate rateOf(double secondsPerRun, std::size_t lookups) {
    return {double(lookups) / secondsPerRun, 1e9 * secondsPerRun / double(lookups)};
}

Rate singleRate(ShadowSystem& system, MapHandle* h, const std::vector<Point>& pts, const LookupOptions& o, int repeat,
                double& checksum) {
    auto thread = system.createThread();
    LookupResult r;
    const double t = median(repeat, [&] {
        for (const Point& p : pts) {
            system.lookup(*thread, h, LookupSpace::raster, p, o, r);
            checksum += r.v[0];
        }
    });
    return rateOf(t, pts.size());
}

Rate batchRate(ShadowSystem& system, MapHandle* h, const std::vector<Point>& pts, const LookupOptions& o, int repeat,
               std::size_t batch, double& checksum) {
    auto thread = system.createThread();
    std::vector<LookupResult> results(pts.size());
    const double t = median(repeat, [&] {
        for (std::size_t b = 0; b < pts.size(); b += batch) {
            const std::size_t n = std::min(batch, pts.size() - b);
            system.lookup(*thread, h, LookupSpace::raster, Span<const Point>(pts.data() + b, n), o,
                          Span<LookupResult>(results.data() + b, n));
        }
        checksum += results[pts.size() / 2].v[0];
    });
    return rateOf(t, pts.size());
}

// Belady's MIN with tiles of different sizes: on a miss, while the new tile
// does not fit, evict the resident tile whose next use is furthest away.
// (With sizes this is a heuristic, the classic optimum for equal sizes; it
// is what the cache is compared with.)
std::uint64_t beladyReads(const std::vector<std::uint64_t>& trace, const std::unordered_map<std::uint64_t, std::size_t>& bytes,
                          std::size_t budget) {
    std::vector<std::size_t> nextUse(trace.size());
    std::unordered_map<std::uint64_t, std::size_t> seen;
    for (std::size_t i = trace.size(); i-- > 0;) {
        auto it = seen.find(trace[i]);
        nextUse[i] = it == seen.end() ? SIZE_MAX : it->second;
        seen[trace[i]] = i;
    }
    std::map<std::uint64_t, std::size_t> residentNext;  // key -> next use
    std::size_t held = 0;
    std::uint64_t reads = 0;
    for (std::size_t i = 0; i < trace.size(); ++i) {
        const std::uint64_t key = trace[i];
        auto it = residentNext.find(key);
        if (it != residentNext.end()) {
            it->second = nextUse[i];
            continue;
        }
        ++reads;
        const std::size_t size = bytes.at(key);
        while (!residentNext.empty() && held + size > budget) {
            auto victim = std::max_element(residentNext.begin(), residentNext.end(),
                                           [](const auto& a, const auto& b) { return a.second < b.second; });
            if (victim->second < nextUse[i]) break;  // everything resident is needed before this tile
            held -= bytes.at(victim->first);
            residentNext.erase(victim);
        }
        if (held + size <= budget || residentNext.empty()) {
            residentNext[key] = nextUse[i];
            held += size;
        }
    }
    return reads;
}

void printRate(const char* what, const Rate& r, double ratioTo, const char* ratioName) {
    std::printf("  %-58s %8.2f M/s %8.1f ns", what, r.perSecond / 1e6, r.nsEach);
    if (ratioTo > 0) std::printf("   %5.2fx %s", r.nsEach / ratioTo, ratioName);
    std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
    Config cfg;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&](const char* name) -> const char* {
            const std::string prefix = std::string(name) + "=";
            return a.rfind(prefix, 0) == 0 ? argv[i] + prefix.size() : nullptr;
        };
        if (a == "--smoke") cfg.smoke = true;
        else if (a == "--keep-maps") cfg.keepMaps = true;
        else if (const char* v = value("--scene")) cfg.scene = v;
        else if (const char* v = value("--size")) cfg.size = std::uint32_t(std::stoul(v));
        else if (const char* v = value("--spp")) cfg.spp = std::uint32_t(std::stoul(v));
        else if (const char* v = value("--big-size")) cfg.bigSize = std::uint32_t(std::stoul(v));
        else if (const char* v = value("--big-spp")) cfg.bigSpp = std::uint32_t(std::stoul(v));
        else if (const char* v = value("--repeat")) cfg.repeat = std::stoi(v);
        else {
            std::fprintf(stderr, "bench_shadow_system: unknown argument %s\n", argv[i]);
            return 2;
        }
    }
    if (cfg.smoke) {
        cfg.size = 64;
        cfg.spp = 4;
        cfg.bigSize = 128;
        cfg.repeat = 1;
        cfg.points = 2048;
    }
    try {
        const Scene scene = loadScene(cfg.scene);
        const fs::path dir = fs::temp_directory_path() / ("dsm-bench-system-" + std::to_string(::getpid()));
        fs::create_directories(dir);
        const std::string path = buildMapFile(scene, cfg.size, cfg.spp, dir);
        double checksum = 0.0;

        // ---------------------------------------------------------------- 1-3
        ShadowSystemOptions wide;
        wide.cacheBytes = std::size_t(4) << 30;
        auto system = ShadowSystem::create(wide);
        MapHandle* h = system->open(path);
        const auto map = system->map(h);
        LookupOptions bilinear;
        bilinear.bias = 0.0;  // the stored functions exactly, as the direct evaluation reads them
        bilinear.level = 0;
        const DirectMap direct(*map);
        ShadowSystemOptions bigTable = wide;
        bigTable.threadTiles = 1024;
        auto system1024 = ShadowSystem::create(bigTable);
        MapHandle* h1024 = system1024->open(path);
        LookupContext context(map);
        // Two sets of random points: 4096 (their pixels stay in the processor's
        // caches once warm, as bench_lookup's) and cfg.points (they spread over
        // the whole decoded map, which does not).
        Rate rSingle;
        std::vector<Point> random;
        for (const std::size_t count : {std::size_t(4096), cfg.points}) {
            random = randomPoints(*map, count, 1);
            const double tDirect = median(cfg.repeat, [&] {
                for (const Point& p : random) checksum += direct.bilinear(p);
            });
            const Rate rDirect = rateOf(tDirect, random.size());
            rSingle = singleRate(*system, h, random, bilinear, cfg.repeat, checksum);
            const Rate rSingle1024 = singleRate(*system1024, h1024, random, bilinear, cfg.repeat, checksum);
            const Rate rBatch = batchRate(*system, h, random, bilinear, cfg.repeat, 4096, checksum);
            const Rate rContext = rateOf(median(cfg.repeat,
                                                [&] {
                                                    for (const Point& p : random)
                                                        checksum += context.raster(p[0], p[1], p[2], bilinear).v[0];
                                                }),
                                         random.size());
            const TileCacheStats warm = system->cache().stats();
            std::printf("\nShadow system, %s %u² at %u spp, %u² tiles, %zu random points over non-empty pixels\n",
                        fs::path(cfg.scene).stem().c_str(), cfg.size, cfg.spp, map->info().tileSize, random.size());
            std::printf("(decoded map %.1f MiB in %llu tiles, all cached)\n", double(warm.bytesInUse) / (1 << 20),
                        static_cast<unsigned long long>(warm.tilesInUse));
            std::printf("1. Warm random bilinear lookups (box width 1, level 0), one thread:\n");
            printRate("direct: four in-memory VisibilityFunction::evaluate", rDirect, 0, "");
            printRate("ShadowSystem::lookup, one point (threadTiles 64, default)", rSingle, rDirect.nsEach, "direct");
            printRate("ShadowSystem::lookup, one point (threadTiles 1024)", rSingle1024, rDirect.nsEach, "direct");
            printRate("ShadowSystem::lookup, batches of 4096 (threadTiles 64)", rBatch, rDirect.nsEach, "direct");
            printRate("LookupContext::raster", rContext, rDirect.nsEach, "direct");
        }

        const std::vector<Point> scan = scanlinePoints(*map);
        const Rate rScan = singleRate(*system, h, scan, bilinear, cfg.repeat, checksum);
        std::printf("2. Warm coherent lookups, every pixel in scanline order (%zu points):\n", scan.size());
        printRate("ShadowSystem::lookup, one point", rScan, 0, "");

        LookupOptions gaussian;
        gaussian.bias = 0.0;
        gaussian.filter = PixelFilter::Gaussian;
        gaussian.filterWidth = 4.0;
        LookupOptions blended;
        blended.bias = 0.0;
        blended.filterWidth = 3.0;  // level auto: levels 1 and 2 blended
        const Rate rGauss = singleRate(*system, h, random, gaussian, cfg.repeat, checksum);
        const Rate rBlend = singleRate(*system, h, random, blended, cfg.repeat, checksum);
        std::printf("3. Wider footprints, random points, one point per call:\n");
        printRate("Gaussian width 4 (level auto: level 1, 3x3 pixels)", rGauss, rSingle.nsEach, "bilinear");
        printRate("box width 3, level auto (levels 1 and 2 blended)", rBlend, rSingle.nsEach, "bilinear");

        // ---------------------------------------------------------------- 4
        {
            const std::string bigPath = buildMapFile(scene, cfg.bigSize, cfg.bigSpp, dir);
            ShadowSystemOptions o;
            o.cacheBytes = std::size_t(16) << 30;
            auto big = ShadowSystem::create(o);
            MapHandle* bh = big->open(bigPath);
            const auto bigMap = big->map(bh);
            const MapInfo& info = bigMap->info();
            std::mt19937_64 rng(4);
            std::uniform_real_distribution<double> ux(0.0, info.width), uy(0.0, info.height), uz(0.5, 3.5);
            std::vector<Point> pts(cfg.smoke ? 4096 : std::size_t(1) << 20);
            for (Point& p : pts) p = {ux(rng), uy(rng), uz(rng)};
            // Fully cached: one pass over every tile of level 0 first.
            {
                auto t = big->createThread();
                LookupResult r;
                const std::uint32_t T = info.tileSize;
                for (std::uint32_t y = 0; y < info.height; y += T)
                    for (std::uint32_t x = 0; x < info.width; x += T)
                        big->lookup(*t, bh, LookupSpace::raster, {x + 0.5, y + 0.5, 1.0}, bilinear, r);
            }
            const Rate single = singleRate(*big, bh, pts, bilinear, std::max(1, cfg.repeat / 2), checksum);
            const Rate batched = batchRate(*big, bh, pts, bilinear, std::max(1, cfg.repeat / 2), 65536, checksum);
            const Rate batchedAll = batchRate(*big, bh, pts, bilinear, std::max(1, cfg.repeat / 2), pts.size(), checksum);
            const TileCacheStats s = big->cache().stats();
            std::printf("4. Fully cached %u² map (%u spp, %.1f MiB decoded in %llu tiles), %zu uniform random points:\n",
                        info.width, cfg.bigSpp, double(s.bytesInUse) / (1 << 20),
                        static_cast<unsigned long long>(s.tilesInUse), pts.size());
            printRate("one point per call", single, 0, "");
            printRate("batches of 65536", batched, single.nsEach, "one per call");
            printRate("one batch of all the points", batchedAll, single.nsEach, "one per call");
        }

        // ---------------------------------------------------------------- 5
        const MapInfo& info = map->info();
        const LevelInfo& L0 = info.levels[0];
        std::unordered_map<std::uint64_t, std::size_t> tileBytes;  // decoded size of each level-0 tile
        std::size_t largestRow = 0, largestTile = 0;
        {
            {
                auto probe = ShadowSystem::create(wide);  // measures each tile's decoded size
                MapHandle* ph = probe->open(path);
                auto t = probe->createThread();
                LookupResult r;
                for (std::uint32_t ty = 0; ty < L0.tilesY; ++ty) {
                    std::size_t row = 0;
                    for (std::uint32_t tx = 0; tx < L0.tilesX; ++tx) {
                        const std::uint64_t before = probe->cache().stats().bytesInUse;
                        probe->lookup(*t, ph, LookupSpace::raster,
                                      {tx * info.tileSize + 1.0, ty * info.tileSize + 1.0, 1.0}, bilinear, r);
                        const std::size_t b = probe->cache().stats().bytesInUse - before;
                        tileBytes[std::uint64_t(ty) * L0.tilesX + tx] = b;
                        largestTile = std::max(largestTile, b);
                        row += b;
                    }
                    largestRow = std::max(largestRow, row);
                }
            }
            const std::size_t budget = largestRow * 9 / 10;
            // The tiles the scan asks for, in order (a lookup's tiles, once each).
            std::vector<std::uint64_t> trace;
            const std::uint32_t T = info.tileSize;
            for (const Point& p : scan) {
                const long x0 = long(std::floor(p[0] - 0.5)), y0 = long(std::floor(p[1] - 0.5));
                std::uint64_t last[4];
                int n = 0;
                for (int j = 0; j < 2; ++j)
                    for (int i = 0; i < 2; ++i) {
                        const long x = x0 + i, y = y0 + j;
                        if (x < 0 || y < 0 || x >= long(info.width) || y >= long(info.height)) continue;
                        const std::uint64_t key = std::uint64_t(y / T) * L0.tilesX + std::uint64_t(x / T);
                        if (std::find(last, last + n, key) == last + n) {
                            last[n++] = key;
                            trace.push_back(key);
                        }
                    }
            }
            const std::uint64_t optimum = beladyReads(trace, tileBytes, budget);
            std::printf("5. Row scan (every pixel, scanline order), budget %.0f KiB = 90%% of the largest tile row "
                        "(%.0f KiB); %u tiles in level 0:\n",
                        budget / 1024.0, largestRow / 1024.0, L0.tilesX * L0.tilesY);
            for (unsigned slots : {2u, kDefaultThreadTiles}) {
                ShadowSystemOptions o;
                o.cacheBytes = budget;
                o.threadTiles = slots;
                auto s = ShadowSystem::create(o);
                MapHandle* sh = s->open(path);
                auto t = s->createThread();
                LookupResult r;
                for (const Point& p : scan) s->lookup(*t, sh, LookupSpace::raster, p, bilinear, r);
                const TileCacheStats st = s->cache().stats();
                std::printf("  threadTiles %-4u tiles read %6llu = %.2f x level-0 tiles (peak %.0f KiB held by the cache)\n",
                            slots, static_cast<unsigned long long>(st.tilesRead),
                            double(st.tilesRead) / (L0.tilesX * L0.tilesY), st.peakBytesInUse / 1024.0);
            }
            std::printf("  optimum (Belady's MIN on the same %zu tile requests): %llu = %.2f x level-0 tiles\n",
                        trace.size(), static_cast<unsigned long long>(optimum),
                        double(optimum) / (L0.tilesX * L0.tilesY));
        }

        // ---------------------------------------------------------------- 6
        {
            const TileCacheStats full = system->cache().stats();
            ShadowSystemOptions o;
            o.cacheBytes = full.bytesInUse / 20;
            o.threadTiles = 2;
            auto s = ShadowSystem::create(o);
            MapHandle* sh = s->open(path);
            std::vector<std::thread> threads;
            std::atomic<std::uint64_t> failures{0};
            for (int k = 0; k < 8; ++k)
                threads.emplace_back([&, k] {
                    auto t = s->createThread();
                    std::vector<Point> pts = randomPoints(*map, cfg.smoke ? 500 : 20000, 100 + k);
                    LookupResult r;
                    for (const Point& p : pts)
                        if (!s->lookup(*t, sh, LookupSpace::raster, p, bilinear, r)) ++failures;
                });
            for (auto& t : threads) t.join();
            const TileCacheStats st = s->cache().stats();
            std::printf("6. Eight threads, random points, budget %.0f KiB (5%% of the map's %.0f KiB):\n",
                        o.cacheBytes / 1024.0, full.bytesInUse / 1024.0);
            std::printf("  tiles read %llu, duplicate reads %llu, waits for another thread's read %llu, failures %llu\n",
                        static_cast<unsigned long long>(st.tilesRead),
                        static_cast<unsigned long long>(st.duplicateReads), static_cast<unsigned long long>(st.waits),
                        static_cast<unsigned long long>(failures.load()));
            std::printf("  peak bytes held by the cache %.0f KiB (budget + largest tile: %.0f KiB)\n",
                        st.peakBytesInUse / 1024.0, (o.cacheBytes + largestTile) / 1024.0);
        }

        // ---------------------------------------------------------------- 7
        {
            auto s = ShadowSystem::create();
            auto t = s->createThread();
            LookupResult r;
            MapHandle* first = s->open(path);
            s->lookup(*t, first, LookupSpace::raster, {1.0, 1.0, 1.0}, bilinear, r);
            const std::size_t one = t->memoryBytes();
            for (int i = 0; i < 100; ++i) {
                const fs::path copy = dir / ("copy-" + std::to_string(i) + ".dsm");
                if (!fs::exists(copy)) fs::create_symlink(path, copy);
                s->lookup(*t, s->open(copy.string()), LookupSpace::raster, {1.0, 1.0, 1.0}, bilinear, r);
            }
            std::printf("7. Per-thread state: %zu bytes with 1 map open, %zu bytes with 101 maps open\n", one,
                        t->memoryBytes());
        }
        std::printf("(checksum %.6g)\n", checksum);
        if (!cfg.keepMaps) fs::remove_all(dir);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_shadow_system: %s\n", e.what());
        return 1;
    }
    return 0;
}
