// Lookups in .dsm files (Lokovic & Veach 2000, §5.3, §5.4, §6 Fig. 9):
//  1. warm-cache bilinear lookups (LookupContext::raster, box width 1, level 0)
//     against evaluating the same four pixel functions directly from in-memory
//     VisibilityFunctions;
//  2. lookup time against box filter width 1 .. 256, with mip-maps (level auto)
//     and forced to level 0, in scanline and random order;
//  3. cold-cache lookups (cache cleared before every repetition) and the cost of
//     reading and decoding one tile;
//  4. the size of the mip pyramid against its base level for hair-ball maps
//     built with 4, 16 and 64 samples per pixel.
// The maps are built from a scene (default examples/hairball.json) into a
// temporary directory before anything is timed. The program prints its tables
// after the Google Benchmark run; see bench/COMPONENTS.md.
//
//   bench_lookup [--smoke] [--scene=FILE] [--lookup-size=N] [--lookup-spp=N]
//                [--pyramid-sizes=N,N] [--pyramid-spp=N,N,N] [--keep-maps]
//                [--benchmark_* flags]

#include <benchmark/benchmark.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <variant>
#include <vector>

#include "support.h"

#ifndef DSM_BENCH_DEFAULT_SCENE
#define DSM_BENCH_DEFAULT_SCENE "examples/hairball.json"
#endif

namespace {

using namespace dsm;
using namespace dsm::bench;
namespace fs = std::filesystem;

constexpr double kAgreement = 1e-9;
constexpr std::size_t kCacheBudget = std::size_t(4) << 30;  // holds any map built here, decoded
constexpr double kWidths[] = {1, 2, 4, 8, 16, 32, 64, 128, 256};
constexpr double kBetweenWidths[] = {1.5, 3, 6, 12, 24, 48, 96, 192};

// ---------------------------------------------------------------- configuration

struct Config {
    bool smoke = false;
    bool keepMaps = false;
    std::string scene = DSM_BENCH_DEFAULT_SCENE;
    std::uint32_t lookupSize = 512;
    std::uint32_t lookupSpp = 16;
    std::vector<std::uint32_t> pyramidSizes{256, 512};
    std::vector<std::uint32_t> pyramidSpp{4, 16, 64};
    std::size_t randomPoints = 4096;                  // warm and direct bilinear, cold batch
    std::size_t widePoints = 512;                     // scanline length; random batch of the width sweep
    std::size_t coldSmallBatch = 64;                  // first-touch batch
    PixelFilter buildFilter = PixelFilter::Gaussian;  // BuildOptions' defaults
    double buildWidth = 2.0;
};

std::vector<std::uint32_t> parseList(const std::string& s) {
    std::vector<std::uint32_t> out;
    std::size_t i = 0;
    while (i < s.size()) {
        const std::size_t j = s.find(',', i);
        out.push_back(static_cast<std::uint32_t>(std::stoul(s.substr(i, j - i))));
        if (j == std::string::npos) break;
        i = j + 1;
    }
    return out;
}

// Takes our own flags out of argv; the rest goes to parseArguments().
Config parseConfig(int& argc, char** argv) {
    Config c;
    int kept = 1;
    bool sizesGiven = false, sppGiven = false, pyrSizesGiven = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&](const char* prefix) -> const char* {
            const std::size_t n = std::char_traits<char>::length(prefix);
            return a.compare(0, n, prefix) == 0 ? argv[i] + n : nullptr;
        };
        if (const char* v = value("--scene="))
            c.scene = v;
        else if (const char* v2 = value("--lookup-size=")) {
            c.lookupSize = static_cast<std::uint32_t>(std::stoul(v2));
            sizesGiven = true;
        } else if (const char* v3 = value("--lookup-spp=")) {
            c.lookupSpp = static_cast<std::uint32_t>(std::stoul(v3));
            sppGiven = true;
        } else if (const char* v4 = value("--pyramid-sizes=")) {
            c.pyramidSizes = parseList(v4);
            pyrSizesGiven = true;
        } else if (const char* v5 = value("--pyramid-spp="))
            c.pyramidSpp = parseList(v5);
        else if (const char* v6 = value("--build-filter=")) {
            const std::string f = v6;
            if (f == "box")
                c.buildFilter = PixelFilter::Box;
            else if (f == "triangle")
                c.buildFilter = PixelFilter::Triangle;
            else if (f == "gaussian")
                c.buildFilter = PixelFilter::Gaussian;
            else
                throw Error(ErrorCode::argument, "--build-filter: box, triangle or gaussian");
        } else if (const char* v7 = value("--build-width="))
            c.buildWidth = std::stod(v7);
        else if (a == "--keep-maps")
            c.keepMaps = true;
        else {
            if (a == "--smoke") c.smoke = true;
            argv[kept++] = argv[i];
        }
    }
    argc = kept;
    if (c.smoke) {
        if (!sizesGiven) c.lookupSize = 64;
        if (!sppGiven) c.lookupSpp = 4;
        if (!pyrSizesGiven) c.pyramidSizes = {32};
        c.randomPoints = 256;
        c.widePoints = 64;
        c.coldSmallBatch = 16;
    }
    return c;
}

// ---------------------------------------------------------------- maps

struct TempDir {
    fs::path path;
    bool keep = false;
    TempDir() {
        std::string pattern = (fs::temp_directory_path() / "dsm-bench-lookup-XXXXXX").string();
        if (!mkdtemp(pattern.data())) throw Error(ErrorCode::io, "cannot create a temporary directory");
        path = pattern;
    }
    ~TempDir() {
        std::error_code ec;
        if (keep)
            std::printf("maps kept in %s\n", path.c_str());
        else
            fs::remove_all(path, ec);
    }
};

// Where the scene's hair lies in a map: its curves rasterised (each segment
// sampled every half pixel), with the light-space depth range of the hair in
// every pixel. Without curves in the scene, `any` stays false.
struct HairRaster {
    std::uint32_t W = 0, H = 0;
    bool any = false;
    std::vector<float> zmin, zmax;  // +inf / -inf where there is no hair
    bool has(std::uint32_t x, std::uint32_t y) const {
        return zmin[std::size_t(y) * W + x] <= zmax[std::size_t(y) * W + x];
    }
};

HairRaster rasterizeHair(const Scene& scene, const LightCamera& camera, std::uint32_t W, std::uint32_t H) {
    HairRaster h;
    h.W = W;
    h.H = H;
    h.zmin.assign(std::size_t(W) * H, std::numeric_limits<float>::infinity());
    h.zmax.assign(std::size_t(W) * H, -std::numeric_limits<float>::infinity());
    for (const SceneObject& o : scene.objects) {
        const Curves* c = std::get_if<Curves>(&o.geometry);
        if (!c) continue;
        const auto& M = o.objectToWorld;
        auto toRaster = [&](const std::array<float, 3>& p, std::array<double, 3>& r) {
            const std::array<double, 3> w{M[0] * p[0] + M[1] * p[1] + M[2] * p[2] + M[3],
                                          M[4] * p[0] + M[5] * p[1] + M[6] * p[2] + M[7],
                                          M[8] * p[0] + M[9] * p[1] + M[10] * p[2] + M[11]};
            return camera.lightToRaster(camera.worldToLightSpace(w), int(W), int(H), r[0], r[1], r[2]);
        };
        std::size_t first = 0;
        for (std::uint32_t n : c->pointsPerCurve) {
            for (std::size_t i = first; i + 1 < first + n; ++i) {
                std::array<double, 3> a, b;
                if (!toRaster(c->points[i], a) || !toRaster(c->points[i + 1], b)) continue;
                const int steps =
                    1 + static_cast<int>(std::ceil(2.0 * std::max(std::abs(b[0] - a[0]), std::abs(b[1] - a[1]))));
                for (int k = 0; k <= steps; ++k) {
                    const double t = double(k) / steps;
                    const double rx = a[0] + t * (b[0] - a[0]), ry = a[1] + t * (b[1] - a[1]),
                                 z = a[2] + t * (b[2] - a[2]);
                    if (!(rx >= 0.0 && rx < W && ry >= 0.0 && ry < H)) continue;
                    const std::size_t idx = std::size_t(ry) * W + std::size_t(rx);
                    h.zmin[idx] = std::min(h.zmin[idx], static_cast<float>(z));
                    h.zmax[idx] = std::max(h.zmax[idx], static_cast<float>(z));
                    h.any = true;
                }
            }
            first += n;
        }
    }
    return h;
}

struct BuiltMap {
    std::uint32_t size = 0;
    std::uint32_t spp = 0;
    std::string path;
    BuildStats stats;
    MapInfo info;
    // Per level: non-empty pixels over the hair (a level-l pixel is over the
    // hair when its 2^l x 2^l block of level 0 holds a hair pixel) and their
    // vertices.
    std::vector<std::uint64_t> hairPixels, hairVertices;
};

BuiltMap build(const Scene& scene, std::uint32_t size, std::uint32_t spp, const fs::path& dir, const Config& cfg) {
    BuiltMap m;
    m.size = size;
    m.spp = spp;
    m.path = (dir / ("hair-" + std::to_string(size) + "-spp" + std::to_string(spp) + ".dsm")).string();
    BuildOptions o;  // defaults: tolerance auto, full pyramid, 32-pixel tiles
    o.filter = cfg.buildFilter;
    o.filterWidth = cfg.buildWidth;
    o.width = o.height = size;
    o.samplesPerPixel = spp;
    m.stats = buildMap(scene, o, m.path);
    const auto map = DeepShadowMap::open(m.path, ReaderOptions{.cache = TileCache::create(std::size_t(1) << 30)});
    m.info = map->info();
    const HairRaster hair = rasterizeHair(scene, m.info.camera, m.info.width, m.info.height);
    std::vector<std::uint8_t> mask(std::size_t(hair.W) * hair.H);
    for (std::uint32_t y = 0; y < hair.H; ++y)
        for (std::uint32_t x = 0; x < hair.W; ++x) mask[std::size_t(y) * hair.W + x] = hair.has(x, y);
    std::uint32_t mw = hair.W, mh = hair.H;
    for (unsigned l = 0; l < m.info.levels.size(); ++l) {
        const LevelInfo& L = m.info.levels[l];
        if (l > 0) {  // 2 x 2 OR of the level above
            std::vector<std::uint8_t> next(std::size_t(L.width) * L.height, 0);
            for (std::uint32_t y = 0; y < mh; ++y)
                for (std::uint32_t x = 0; x < mw; ++x)
                    if (mask[std::size_t(y) * mw + x]) next[std::size_t(y / 2) * L.width + x / 2] = 1;
            mask = std::move(next);
            mw = L.width;
            mh = L.height;
        }
        std::uint64_t pixels = 0, vertices = 0;
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x) {
                if (!mask[std::size_t(y) * mw + x]) continue;
                const std::size_t n = map->pixel(l, x, y).view().size();
                if (n == 0) continue;
                ++pixels;
                vertices += n;
            }
        m.hairPixels.push_back(pixels);
        m.hairVertices.push_back(vertices);
    }
    std::printf("built %ux%u spp %u: %.1f s wall, %llu level-0 vertices, %.2f MB file, tolerance %.6g\n", size, size,
                spp, m.stats.wallSeconds, static_cast<unsigned long long>(m.stats.vertices),
                static_cast<double>(m.stats.fileBytes) / 1e6, m.stats.tolerance);
    std::fflush(stdout);
    return m;
}

// ---------------------------------------------------------------- queries

struct Query {
    double rx, ry, z;
};

struct Inputs {
    std::uint32_t W = 0, H = 0;
    std::vector<VisibilityFunction> level0;  // row-major, in memory (the direct baseline)
    HairRaster hair;
    double zlo = 0, zhi = 0;  // depth range of the hair (of everything without hair)
    std::vector<std::array<std::uint32_t, 2>> nonEmpty;
    std::vector<std::array<std::uint32_t, 2>> footprint;  // non-empty pixels over the hair
    std::uint64_t footprintVertices = 0, nonEmptyVertices = 0;
    std::vector<Query> random;     // uniform over the hair footprint, z uniform in the pixel's hair depths
    std::vector<Query> randomAll;  // uniform over the non-empty pixels, z uniform in [zlo, zhi]
    std::vector<Query> scanline;   // one row through the hair, left to right, z smooth
    std::uint32_t scanRow = 0;
    double scanX0 = 0, scanX1 = 0, scanZ0 = 0, scanZ1 = 0;
};

Inputs makeInputs(const DeepShadowMap& map, const Scene& scene, const Config& cfg) {
    Inputs in;
    const MapInfo& info = map.info();
    in.W = info.width;
    in.H = info.height;
    in.level0.reserve(std::size_t(in.W) * in.H);
    in.hair = rasterizeHair(scene, info.camera, in.W, in.H);
    in.zlo = std::numeric_limits<double>::infinity();
    in.zhi = -in.zlo;
    for (std::uint32_t y = 0; y < in.H; ++y)
        for (std::uint32_t x = 0; x < in.W; ++x) {
            in.level0.push_back(map.pixel(0, x, y).view().toFunction(false));
            const VisibilityFunction& f = in.level0.back();
            if (f.empty()) continue;
            in.nonEmpty.push_back({x, y});
            in.nonEmptyVertices += f.size();
            if (!in.hair.any) {  // every non-empty pixel, through all its depths
                in.footprint.push_back({x, y});
                in.footprintVertices += f.size();
                const std::size_t idx = std::size_t(y) * in.W + x;
                in.hair.zmin[idx] = f.z(0);
                in.hair.zmax[idx] = f.z(f.size() - 1);
            } else if (in.hair.has(x, y)) {
                in.footprint.push_back({x, y});
                in.footprintVertices += f.size();
            }
        }
    if (in.footprint.empty()) throw Error(ErrorCode::argument, "the map is empty where the hair is");
    for (const auto& p : in.footprint) {
        const std::size_t idx = std::size_t(p[1]) * in.W + p[0];
        in.zlo = std::min(in.zlo, double(in.hair.zmin[idx]));
        in.zhi = std::max(in.zhi, double(in.hair.zmax[idx]));
    }

    std::mt19937_64 rng(20000);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    auto pick = [&](const std::vector<std::array<std::uint32_t, 2>>& from) {
        return from[std::uniform_int_distribution<std::size_t>(0, from.size() - 1)(rng)];
    };
    for (std::size_t i = 0; i < cfg.randomPoints; ++i) {
        const auto p = pick(in.footprint);
        const std::size_t idx = std::size_t(p[1]) * in.W + p[0];
        const double rx = p[0] + unit(rng), ry = p[1] + unit(rng);
        in.random.push_back({rx, ry, in.hair.zmin[idx] + (in.hair.zmax[idx] - in.hair.zmin[idx]) * unit(rng)});
    }
    for (std::size_t i = 0; i < cfg.randomPoints; ++i) {
        const auto p = pick(in.nonEmpty);
        const double rx = p[0] + unit(rng), ry = p[1] + unit(rng);
        in.randomAll.push_back({rx, ry, in.zlo + (in.zhi - in.zlo) * unit(rng)});
    }

    // The row with the most hair pixels; the scanline spans its hair off the
    // pixel centres (ry = row + 0.3), its depth a smooth wave through the
    // row's hair depths.
    std::vector<std::uint32_t> perRow(in.H, 0), rowMin(in.H, in.W), rowMax(in.H, 0);
    for (const auto& p : in.footprint) {
        ++perRow[p[1]];
        rowMin[p[1]] = std::min(rowMin[p[1]], p[0]);
        rowMax[p[1]] = std::max(rowMax[p[1]], p[0]);
    }
    in.scanRow = static_cast<std::uint32_t>(std::max_element(perRow.begin(), perRow.end()) - perRow.begin());
    in.scanX0 = rowMin[in.scanRow];
    in.scanX1 = rowMax[in.scanRow] + 1.0;
    in.scanZ0 = std::numeric_limits<double>::infinity();
    in.scanZ1 = -in.scanZ0;
    for (std::uint32_t x = rowMin[in.scanRow]; x <= rowMax[in.scanRow]; ++x) {
        const std::size_t idx = std::size_t(in.scanRow) * in.W + x;
        if (!(in.hair.zmin[idx] <= in.hair.zmax[idx])) continue;
        in.scanZ0 = std::min(in.scanZ0, double(in.hair.zmin[idx]));
        in.scanZ1 = std::max(in.scanZ1, double(in.hair.zmax[idx]));
    }
    const double zmid = 0.5 * (in.scanZ0 + in.scanZ1), amp = 0.4 * (in.scanZ1 - in.scanZ0);
    for (std::size_t k = 0; k < cfg.widePoints; ++k) {
        const double t = (static_cast<double>(k) + 0.37) / static_cast<double>(cfg.widePoints);
        in.scanline.push_back({in.scanX0 + (in.scanX1 - in.scanX0) * t, in.scanRow + 0.3,
                               zmid + amp * std::sin(3.0 * std::numbers::pi * t)});
    }
    return in;
}

// Bilinear (box width 1) over the in-memory level-0 functions, the same
// weights and pixels as LookupContext::raster at level 0.
inline double directBilinear(const Inputs& in, const Query& q) {
    const double cx = q.rx - 0.5, cy = q.ry - 0.5;
    const double fx0 = std::floor(cx), fy0 = std::floor(cy);
    const long x0 = static_cast<long>(fx0), y0 = static_cast<long>(fy0);
    const double wx[2] = {1.0 - (cx - fx0), cx - fx0}, wy[2] = {1.0 - (cy - fy0), cy - fy0};
    double sum = 0.0, total = 0.0;
    for (int j = 0; j < 2; ++j) {
        const long y = y0 + j;
        if (y < 0 || y >= static_cast<long>(in.H) || wy[j] == 0.0) continue;
        for (int i = 0; i < 2; ++i) {
            const long x = x0 + i;
            if (x < 0 || x >= static_cast<long>(in.W) || wx[i] == 0.0) continue;
            const double w = wx[i] * wy[j];
            sum += w * in.level0[std::size_t(y) * in.W + std::size_t(x)].evaluate(q.z);
            total += w;
        }
    }
    return total > 0.0 ? sum / total : 1.0;
}

// ---------------------------------------------------------------- benchmarks

/// A box lookup; `level` < 0 chooses the levels from the width.
LookupOptions boxOptions(double width, int level) {
    LookupOptions o;
    o.bias = 0.0;  // the stored functions exactly, as the direct evaluation reads them
    o.filter = PixelFilter::Box;
    o.filterWidth = width;
    if (level >= 0) o.level = static_cast<unsigned>(level);
    return o;
}

void benchLookups(benchmark::State& state, std::shared_ptr<const DeepShadowMap> map, const std::vector<Query>* queries,
                  LookupOptions options) {
    LookupContext context(map);
    std::uint64_t pixels = 0;
    double sum = 0.0;
    for (auto _ : state) {
        for (const Query& q : *queries) {
            const LookupResult r = context.raster(q.rx, q.ry, q.z, options);
            sum += r.v[0];
            pixels += static_cast<std::uint64_t>(r.pixelsUsed);
        }
        benchmark::DoNotOptimize(sum);
    }
    const double lookups = static_cast<double>(state.iterations()) * static_cast<double>(queries->size());
    state.SetItemsProcessed(static_cast<std::int64_t>(lookups));
    state.counters["batch"] = static_cast<double>(queries->size());
    state.counters["px_per_lookup"] = static_cast<double>(pixels) / lookups;
}

void benchDirect(benchmark::State& state, const Inputs* in, const std::vector<Query>* queries) {
    double sum = 0.0;
    for (auto _ : state) {
        for (const Query& q : *queries) sum += directBilinear(*in, q);
        benchmark::DoNotOptimize(sum);
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(queries->size()));
    state.counters["batch"] = static_cast<double>(queries->size());
}

// First-touch lookups: every iteration starts with an empty cache and a new
// context (its private tiles gone too); clearing is not timed.
void benchCold(benchmark::State& state, std::shared_ptr<const DeepShadowMap> map, std::shared_ptr<TileCache> cache,
               const std::vector<Query>* queries, std::size_t n) {
    std::uint64_t tiles = 0, bytes = 0;
    double sum = 0.0;
    std::unique_ptr<LookupContext> context;
    const LookupOptions options = boxOptions(1.0, 0);
    for (auto _ : state) {
        state.PauseTiming();
        context.reset();
        cache->clear();
        cache->resetStats();
        context = std::make_unique<LookupContext>(map);
        state.ResumeTiming();
        for (std::size_t i = 0; i < n; ++i) {
            const Query& q = (*queries)[i];
            sum += context->raster(q.rx, q.ry, q.z, options).v[0];
        }
        benchmark::DoNotOptimize(sum);
        state.PauseTiming();
        const TileCacheStats s = cache->stats();
        tiles += s.tilesRead;
        bytes += s.bytesRead;
        state.ResumeTiming();
    }
    context.reset();
    const double it = static_cast<double>(state.iterations());
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
    state.counters["batch"] = static_cast<double>(n);
    state.counters["tiles_read"] = static_cast<double>(tiles) / it;
    state.counters["bytes_read"] = static_cast<double>(bytes) / it;
}

struct TileRef {
    unsigned level;
    std::uint32_t tx, ty;
};

// Reads and decodes every listed tile once through an emptied cache.
void benchDecode(benchmark::State& state, std::shared_ptr<const DeepShadowMap> map, std::shared_ptr<TileCache> cache,
                 const std::vector<TileRef>* tiles) {
    const std::uint32_t T = map->info().tileSize;
    std::uint64_t read = 0, bytes = 0;
    std::size_t sum = 0;
    for (auto _ : state) {
        state.PauseTiming();
        cache->clear();
        cache->resetStats();
        state.ResumeTiming();
        for (const TileRef& t : *tiles) sum += map->pixel(t.level, t.tx * T, t.ty * T).view().size();
        benchmark::DoNotOptimize(sum);
        state.PauseTiming();
        const TileCacheStats s = cache->stats();
        read += s.tilesRead;
        bytes += s.bytesRead;
        state.ResumeTiming();
    }
    const double it = static_cast<double>(state.iterations());
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(tiles->size()));
    state.counters["tiles_read"] = static_cast<double>(read) / it;
    state.counters["bytes_read"] = static_cast<double>(bytes) / it;
}

// ---------------------------------------------------------------- output helpers

std::string perLookup(double seconds) {
    char buf[64];
    if (!std::isfinite(seconds)) return "n/a";
    if (seconds < 1e-6)
        std::snprintf(buf, sizeof buf, "%.0f ns", seconds * 1e9);
    else if (seconds < 1e-3)
        std::snprintf(buf, sizeof buf, "%.2f us", seconds * 1e6);
    else
        std::snprintf(buf, sizeof buf, "%.2f ms", seconds * 1e3);
    return buf;
}

std::string widthName(double w) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", w);
    return buf;
}

std::string bytesText(double b) {
    char buf[64];
    if (b >= 1e6)
        std::snprintf(buf, sizeof buf, "%.2f MB", b / 1e6);
    else
        std::snprintf(buf, sizeof buf, "%.1f kB", b / 1e3);
    return buf;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        Config cfg = parseConfig(argc, argv);
        const Arguments args = parseArguments(argc, argv);

        // -------------------------------------------------------- maps (not timed)
        TempDir dir;
        dir.keep = cfg.keepMaps;
        const auto sceneStart = std::chrono::steady_clock::now();
        const Scene scene = loadScene(cfg.scene);
        std::printf("scene %s loaded in %.1f s; maps in %s\n", cfg.scene.c_str(),
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - sceneStart).count(),
                    dir.path.c_str());
        std::fflush(stdout);
        const BuiltMap lookupMap = build(scene, cfg.lookupSize, cfg.lookupSpp, dir.path, cfg);
        std::vector<BuiltMap> pyramids;
        for (std::uint32_t size : cfg.pyramidSizes)
            for (std::uint32_t spp : cfg.pyramidSpp)
                pyramids.push_back(size == cfg.lookupSize && spp == cfg.lookupSpp
                                       ? lookupMap
                                       : build(scene, size, spp, dir.path, cfg));

        // Warm: its own cache, every tile of every level decoded before timing.
        auto warmCache = TileCache::create(kCacheBudget);
        std::shared_ptr<const DeepShadowMap> warm =
            DeepShadowMap::open(lookupMap.path, ReaderOptions{.cache = warmCache});
        const MapInfo& info = warm->info();
        const std::uint32_t T = info.tileSize;
        std::size_t allTiles = 0;
        std::vector<TileRef> level0Tiles;
        std::uint64_t level0Stored = 0, level0Raw = 0;
        for (unsigned l = 0; l < info.levels.size(); ++l)
            for (std::uint32_t ty = 0; ty < info.levels[l].tilesY; ++ty)
                for (std::uint32_t tx = 0; tx < info.levels[l].tilesX; ++tx) {
                    (void)warm->pixel(l, tx * T, ty * T);
                    ++allTiles;
                    const TileSummary s = warm->tile(l, tx, ty);
                    if (l == 0 && !s.empty()) {
                        level0Tiles.push_back({0, tx, ty});
                        level0Stored += s.storedBytes;
                        level0Raw += s.rawBytes;
                    }
                }
        const TileCacheStats warmed = warmCache->stats();
        std::printf("warm cache: %llu of %zu tiles held, %.1f MB decoded, %llu evictions\n",
                    static_cast<unsigned long long>(warmed.tilesInUse), allTiles, warmed.bytesInUse / 1e6,
                    static_cast<unsigned long long>(warmed.evictions));
        if (warmed.tilesInUse != allTiles || warmed.evictions != 0) {
            std::printf("check FAILED: the warm cache does not hold the whole file\n");
            return 1;
        }
        // Cold: a second handle on the same file with a cache of its own.
        auto coldCache = TileCache::create(kCacheBudget);
        std::shared_ptr<const DeepShadowMap> cold =
            DeepShadowMap::open(lookupMap.path, ReaderOptions{.cache = coldCache});

        const Inputs in = makeInputs(*warm, scene, cfg);
        const std::vector<Query> randomWide(
            in.random.begin(), in.random.begin() + static_cast<long>(std::min(cfg.widePoints, in.random.size())));
        std::printf(
            "map %ux%u, %zu levels, %u-pixel tiles (%zu level-0 tiles with data); %zu non-empty level-0 pixels "
            "(%.1f %%), %.2f vertices each\n",
            in.W, in.H, info.levels.size(), T, level0Tiles.size(), in.nonEmpty.size(),
            100.0 * double(in.nonEmpty.size()) / (double(in.W) * in.H),
            double(in.nonEmptyVertices) / double(in.nonEmpty.size()));
        std::printf("level tolerances:");
        for (const LevelInfo& L : info.levels) std::printf(" %.6g", L.tolerance);
        std::printf(
            "\nhair footprint (%s): %zu non-empty pixels (%.1f %%), %.2f vertices each; hair depths %.4f .. %.4f\n",
            in.hair.any ? "the scene's curves rasterised" : "no curves: all non-empty pixels", in.footprint.size(),
            100.0 * double(in.footprint.size()) / (double(in.W) * in.H),
            double(in.footprintVertices) / double(in.footprint.size()), in.zlo, in.zhi);
        std::printf("scanline: row %u, x %.0f .. %.0f, %zu receivers, z %.4f .. %.4f\n", in.scanRow, in.scanX0,
                    in.scanX1, in.scanline.size(), in.scanZ0, in.scanZ1);

        // -------------------------------------------------------- checks (not timed)
        {
            LookupContext context(warm);
            double maxDiff = 0.0;
            for (const std::vector<Query>* set : {&in.random, &in.randomAll})
                for (const Query& q : *set) {
                    const LookupResult r = context.raster(q.rx, q.ry, q.z, boxOptions(1.0, 0));
                    maxDiff = std::max(maxDiff, std::abs(r.v[0] - directBilinear(in, q)));
                }
            if (!(maxDiff <= kAgreement)) {
                std::printf("check FAILED: lookup and direct bilinear differ by %.3g\n", maxDiff);
                return 1;
            }
            std::printf("check: lookup == direct bilinear within %.0e at all %zu random points (max |diff| %.2e)\n",
                        kAgreement, in.random.size() + in.randomAll.size(), maxDiff);
        }
        // Informative: how far the mip-mapped answer is from the level-0 one.
        std::map<double, std::array<double, 2>> mipDiff;  // width -> mean, max |V_auto - V_level0|
        {
            LookupContext a(warm), b(warm);
            for (double w : kWidths) {
                double sum = 0.0, mx = 0.0;
                for (const Query& q : in.scanline) {
                    const double d = std::abs(a.raster(q.rx, q.ry, q.z, boxOptions(w, -1)).v[0] -
                                              b.raster(q.rx, q.ry, q.z, boxOptions(w, 0)).v[0]);
                    sum += d;
                    mx = std::max(mx, d);
                }
                mipDiff[w] = {sum / double(in.scanline.size()), mx};
            }
        }
        std::printf("\n");
        std::fflush(stdout);

        // -------------------------------------------------------- benchmarks
        auto reg = [](const std::string& name, auto&&... a) {
            return benchmark::RegisterBenchmark(name.c_str(), a...)->Unit(benchmark::kMicrosecond);
        };
        reg("warm/bilinear/random", benchLookups, warm, &in.random, boxOptions(1.0, 0));
        reg("direct/bilinear/random", benchDirect, &in, &in.random);
        reg("warm/bilinear/random-nonempty", benchLookups, warm, &in.randomAll, boxOptions(1.0, 0));
        reg("direct/bilinear/random-nonempty", benchDirect, &in, &in.randomAll);
        for (double w : kWidths) {
            reg("width/mip/scanline/w=" + widthName(w), benchLookups, warm, &in.scanline, boxOptions(w, -1));
            reg("width/level0/scanline/w=" + widthName(w), benchLookups, warm, &in.scanline, boxOptions(w, 0));
        }
        for (double w : {1.0, 256.0}) {
            reg("width/mip/random/w=" + widthName(w), benchLookups, warm, &randomWide, boxOptions(w, -1));
            reg("width/level0/random/w=" + widthName(w), benchLookups, warm, &randomWide, boxOptions(w, 0));
        }
        for (double w : kBetweenWidths)
            reg("width/mip/scanline/w=" + widthName(w), benchLookups, warm, &in.scanline, boxOptions(w, -1));
        const std::size_t coldBatches[] = {std::min(cfg.coldSmallBatch, in.random.size()), in.random.size()};
        for (std::size_t n : coldBatches)
            reg("cold/bilinear/random/batch=" + std::to_string(n), benchCold, cold, coldCache, &in.random, n);
        reg("decode/level0-tiles", benchDecode, cold, coldCache, &level0Tiles);

        warmCache->resetStats();
        Results results;
        if (!runBenchmarks(args, results)) return 1;
        const TileCacheStats warmAfter = warmCache->stats();

        // -------------------------------------------------------- tables
        auto med = [&](const std::string& name) { return results[name].median(); };
        auto spread = [&](const std::string& name) { return results[name].spreadPercent(); };
        auto counter = [&](const std::string& name, const char* c) { return results[name].counters[c]; };
        auto per = [&](const std::string& name) { return med(name) / counter(name, "batch"); };

        std::printf(
            "\nMap: %ux%u, spp %u, tolerance %.6g, %zu levels, %.2f MB; warm cache during the timed runs: "
            "%llu hits, %llu misses\n",
            in.W, in.H, cfg.lookupSpp, lookupMap.stats.tolerance, info.levels.size(), info.fileBytes / 1e6,
            static_cast<unsigned long long>(warmAfter.hits), static_cast<unsigned long long>(warmAfter.misses));
        if (warmAfter.misses != 0) {
            std::printf("check FAILED: the warm cache missed during the timed runs\n");
            return 1;
        }
        std::printf("(median CPU time over the repetitions; spread = (max - min) / median)\n");

        std::printf("\n1. Warm bilinear lookups (box width 1, level 0), %zu random points\n", in.random.size());
        const double tWarm = per("warm/bilinear/random"), tDirect = per("direct/bilinear/random");
        std::printf("%-14s %-36s %12s %14s %7s %10s %15s\n", "points", "", "per lookup", "lookups/s", "spread",
                    "px/lookup", "lookup/direct");
        for (const char* set : {"random", "random-nonempty"}) {
            const std::string w = std::string("warm/bilinear/") + set, d = std::string("direct/bilinear/") + set;
            const char* label = std::string(set) == "random" ? "hair" : "all non-empty";
            std::printf("%-14s %-36s %12s %14s %6.0f%% %10.2f %15.2f\n", label,
                        "LookupContext::raster, warm cache", perLookup(per(w)).c_str(),
                        formatRate(1.0 / per(w), "").c_str(), spread(w), counter(w, "px_per_lookup"),
                        per(w) / per(d));
            std::printf("%-14s %-36s %12s %14s %6.0f%%\n", label, "direct VisibilityFunction::evaluate",
                        perLookup(per(d)).c_str(), formatRate(1.0 / per(d), "").c_str(), spread(d));
        }
        std::printf(
            "(hair: over the hair footprint, z uniform in the pixel's hair depths; all non-empty: over every "
            "non-empty pixel, z uniform in the hair's depth range)\n");

        std::printf("\n2. Lookup time vs box filter width (level-0 pixels), scanline of %zu receivers\n",
                    in.scanline.size());
        std::printf("%6s | %10s %6s %9s %8s | %10s %6s %9s %8s | %12s %12s\n", "width", "mip", "spread", "px/lookup",
                    "w/w=1", "level 0", "spread", "px/lookup", "w/w=1", "mean|dV|", "max|dV|");
        const std::string m1 = "width/mip/scanline/w=1", l1 = "width/level0/scanline/w=1";
        for (double w : kWidths) {
            const std::string m = "width/mip/scanline/w=" + widthName(w), l = "width/level0/scanline/w=" + widthName(w);
            std::printf("%6s | %10s %5.0f%% %9.1f %8.2f | %10s %5.0f%% %9.1f %8.1f | %12.2e %12.2e\n",
                        widthName(w).c_str(), perLookup(per(m)).c_str(), spread(m), counter(m, "px_per_lookup"),
                        per(m) / per(m1), perLookup(per(l)).c_str(), spread(l), counter(l, "px_per_lookup"),
                        per(l) / per(l1), mipDiff[w][0], mipDiff[w][1]);
        }
        std::printf("(|dV| = |V(mip) - V(level 0)| over the scanline: the mip-map's approximation of the wide box)\n");
        std::printf("\nRandom order (%zu random points):\n", randomWide.size());
        std::printf("%6s | %10s %6s %9s | %10s %6s %9s\n", "width", "mip", "spread", "px/lookup", "level 0", "spread",
                    "px/lookup");
        for (double w : {1.0, 256.0}) {
            const std::string m = "width/mip/random/w=" + widthName(w), l = "width/level0/random/w=" + widthName(w);
            std::printf("%6s | %10s %5.0f%% %9.1f | %10s %5.0f%% %9.1f\n", widthName(w).c_str(),
                        perLookup(per(m)).c_str(), spread(m), counter(m, "px_per_lookup"), perLookup(per(l)).c_str(),
                        spread(l), counter(l, "px_per_lookup"));
        }
        std::printf("w=256 / w=1 random: mip %.2f, level 0 %.1f\n",
                    per("width/mip/random/w=256") / per("width/mip/random/w=1"),
                    per("width/level0/random/w=256") / per("width/level0/random/w=1"));
        std::printf("\nBetween powers of two (mip, scanline; two levels blended):\n");
        std::printf("%6s | %10s %6s %9s %8s\n", "width", "mip", "spread", "px/lookup", "w/w=1");
        for (double w : kBetweenWidths) {
            const std::string m = "width/mip/scanline/w=" + widthName(w);
            std::printf("%6s | %10s %5.0f%% %9.1f %8.2f\n", widthName(w).c_str(), perLookup(per(m)).c_str(), spread(m),
                        counter(m, "px_per_lookup"), per(m) / per(m1));
        }

        std::printf(
            "\n3. Cold cache (cache cleared and a new LookupContext before every repetition; the file stays in "
            "the OS page cache)\n");
        std::printf("%8s | %10s %6s %10s | %10s %11s %12s | %12s %12s\n", "batch", "cold", "spread", "per lookup",
                    "tiles read", "bytes read", "warm/lookup", "extra/tile", "stored MB/s");
        for (std::size_t n : coldBatches) {
            const std::string c = "cold/bilinear/random/batch=" + std::to_string(n);
            const double tiles = counter(c, "tiles_read");
            const double extra = med(c) - double(n) * tWarm;
            std::printf("%8zu | %10s %5.0f%% %10s | %10.1f %11s %12s | %12s %12.1f\n", n, perLookup(med(c)).c_str(),
                        spread(c), perLookup(med(c) / double(n)).c_str(), tiles,
                        bytesText(counter(c, "bytes_read")).c_str(), perLookup(tWarm).c_str(),
                        perLookup(extra / tiles).c_str(), counter(c, "bytes_read") / extra / 1e6);
        }
        {
            const std::string d = "decode/level0-tiles";
            const double t = med(d), tiles = counter(d, "tiles_read"), bytes = counter(d, "bytes_read");
            std::printf(
                "read + decode of all %zu non-empty level-0 tiles: %s (spread %.0f%%), %.0f tiles read, %s "
                "stored, %s decoded\n",
                level0Tiles.size(), perLookup(t).c_str(), spread(d), tiles, bytesText(bytes).c_str(),
                bytesText(double(level0Raw)).c_str());
            std::printf(
                "  per tile %.1f us; %.1f MB/s of stored bytes, %.1f MB/s of decoded bytes; mean tile %.1f kB "
                "stored, %.1f kB raw\n",
                t / tiles * 1e6, bytes / t / 1e6, double(level0Raw) / t / 1e6, bytes / tiles / 1e3,
                double(level0Raw) / tiles / 1e3);
        }

        std::printf(
            "\n4. Mip pyramid size / base level (tolerance auto = 0.25/sqrt(spp), halved per level; "
            "%s build filter of width %g)\n",
            filterName(cfg.buildFilter), cfg.buildWidth);
        const double lvInfinite = 1.0 / (1.0 - std::sqrt(2.0) / 4.0);
        std::printf("%5s %4s %9s %3s | %11s %11s %6s | %10s %10s %6s | %6s %6s | %6s %6s | %6s %6s\n", "size", "spp",
                    "tol", "lev", "L0 bytes", "all bytes", "ratio", "L0 verts", "all verts", "ratio", "LV", "4/3",
                    "LV*", "4/3*", "hair", "LV*h");
        for (const BuiltMap& m : pyramids) {
            const auto& L = m.info.levels;
            double bytes = 0, verts = 0, lv = 0, ord = 0, lvNE = 0, ordNE = 0, hairVerts = 0, lvHair = 0;
            for (std::size_t l = 0; l < L.size(); ++l) {
                bytes += double(L[l].storedBytes);
                verts += double(L[l].vertexCount);
                hairVerts += double(m.hairVertices[l]);
                lv += std::pow(std::sqrt(2.0) / 4.0, double(l));
                ord += std::pow(0.25, double(l));
                const double ne = double(L[l].nonEmptyPixels) / double(L[0].nonEmptyPixels);
                lvNE += ne * std::pow(std::sqrt(2.0), double(l));
                ordNE += ne;
                lvHair += double(m.hairPixels[l]) / double(m.hairPixels[0]) * std::pow(std::sqrt(2.0), double(l));
            }
            std::printf(
                "%5u %4u %9.6f %3zu | %11.0f %11.0f %6.3f | %10llu %10.0f %6.3f | %6.3f %6.3f | %6.3f %6.3f | "
                "%6.3f %6.3f\n",
                m.size, m.spp, L[0].tolerance, L.size(), double(L[0].storedBytes), bytes,
                bytes / double(L[0].storedBytes), static_cast<unsigned long long>(L[0].vertexCount), verts,
                verts / double(L[0].vertexCount), lv, ord, lvNE, ordNE, hairVerts / double(m.hairVertices[0]), lvHair);
        }
        std::printf(
            "(LV = sum over the levels of (sqrt(2)/4)^l, -> %.3f for infinitely many; 4/3 = sum of (1/4)^l;\n"
            " LV* and 4/3* use the map's actual non-empty pixel counts n_l per level: sum n_l/n_0 * sqrt(2)^l and "
            "sum n_l/n_0;\n hair = the vertex ratio over the pixels over the hair only, LV*h its LV* "
            "prediction)\n",
            lvInfinite);
        std::size_t maxLevels = 0;
        for (const BuiltMap& m : pyramids) maxLevels = std::max(maxLevels, m.info.levels.size());
        // Mean vertices per pixel and level, given per-level pixel and vertex counts.
        auto meanTable = [&](auto pixelsOf, auto verticesOf) {
            std::printf("%5s", "level");
            for (const BuiltMap& m : pyramids) std::printf(" | %4u/%-3u %8s", m.size, m.spp, "");
            std::printf("\n");
            for (std::size_t l = 0; l < maxLevels; ++l) {
                std::printf("%5zu", l);
                for (const BuiltMap& m : pyramids) {
                    if (l >= m.info.levels.size() || pixelsOf(m, l) == 0) {
                        std::printf(" | %17s", "");
                        continue;
                    }
                    const double mean = double(verticesOf(m, l)) / double(pixelsOf(m, l));
                    if (l == 0 || pixelsOf(m, l - 1) == 0)
                        std::printf(" | %7.2f %9s", mean, "");
                    else
                        std::printf(" | %7.2f (x%5.2f)", mean,
                                    mean / (double(verticesOf(m, l - 1)) / double(pixelsOf(m, l - 1))));
                }
                std::printf("\n");
            }
        };
        std::printf(
            "\nMean vertices per non-empty pixel, per level (ratio to the level above in brackets; LV: x1.41 "
            "per level)\n");
        meanTable([](const BuiltMap& m, std::size_t l) { return m.info.levels[l].nonEmptyPixels; },
                  [](const BuiltMap& m, std::size_t l) { return m.info.levels[l].vertexCount; });
        std::printf("\nThe same over the pixels over the hair only\n");
        meanTable([](const BuiltMap& m, std::size_t l) { return m.hairPixels[l]; },
                  [](const BuiltMap& m, std::size_t l) { return m.hairVertices[l]; });
        std::printf("\nStored bytes per vertex, per level (zlib level 6; ratio to the level above in brackets)\n");
        meanTable([](const BuiltMap& m, std::size_t l) { return m.info.levels[l].vertexCount; },
                  [](const BuiltMap& m, std::size_t l) { return m.info.levels[l].storedBytes; });
        std::printf("\nNon-empty pixels per level (over the hair in brackets):\n%5s", "level");
        for (const BuiltMap& m : pyramids) std::printf(" | %4u/%-3u %8s", m.size, m.spp, "");
        std::printf("\n");
        for (std::size_t l = 0; l < maxLevels; ++l) {
            std::printf("%5zu", l);
            for (const BuiltMap& m : pyramids) {
                const auto& L = m.info.levels;
                if (l < L.size())
                    std::printf(" | %7llu (%7llu)", static_cast<unsigned long long>(L[l].nonEmptyPixels),
                                static_cast<unsigned long long>(m.hairPixels[l]));
                else
                    std::printf(" | %17s", "");
            }
            std::printf("\n");
        }

        std::printf(
            "\nHeadline: warm bilinear %.2f M lookups/s (%s each), lookup/direct %.2f; width 256/1 (scanline): "
            "mip %.2f, level 0 %.0f; tile read+decode %.1f us/tile (%.1f MB/s stored)\n",
            1e-6 / tWarm, perLookup(tWarm).c_str(), tWarm / tDirect, per("width/mip/scanline/w=256") / per(m1),
            per("width/level0/scanline/w=256") / per(l1),
            med("decode/level0-tiles") / counter("decode/level0-tiles", "tiles_read") * 1e6,
            counter("decode/level0-tiles", "bytes_read") / med("decode/level0-tiles") / 1e6);
        if (args.smoke) std::printf("(smoke run: the numbers above are not measurements)\n");
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_lookup: %s\n", e.what());
        return 1;
    }
}
