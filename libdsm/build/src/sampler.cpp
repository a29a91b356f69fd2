#include "dsm/sampler.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/task_arena.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_pipeline.h>

#include "dsm/build_visibility.h"
#include "dsm/compressor.h"
#include "dsm/error.h"
#include "dsm/names.h"
#include "dsm/output_file.h"
#include "dsm/reader.h"
#include "dsm/sweep.h"
#include "dsm/threads.h"
#include "dsm/value_step.h"
#include "dsm/writer.h"
#include "light_rays.h"
#include "pixel_filter.h"
#include "ray_caster.h"
#include "scanline_hider.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

using Clock = std::chrono::steady_clock;
// Samples a worker holds at once for one tile (see computeTile).
constexpr std::size_t kBandSamples = std::size_t(1) << 20;

// Level-0 tiles a build holds at once (built, or waiting for the writer):
// about one row of them, and two for each worker so that none waits for a
// tile to start while the writer catches up.
std::size_t tilesInFlight(std::uint32_t tilesX, unsigned threads) { return std::size_t(tilesX) + 2 * std::size_t(threads); }

double since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// Weight of a sample at offset (dx, dy) pixels from a pixel centre, for
// filter F (a constant, so that the loop over a pixel's samples has no
// switch in it).
template <PixelFilter F>
double filterWeight(double radius, double dx, double dy) {
    const double ax = std::abs(dx), ay = std::abs(dy);
    if (ax >= radius || ay >= radius) return 0.0;
    if constexpr (F == PixelFilter::Box) return 1.0;
    if constexpr (F == PixelFilter::Triangle)
        return detail::triangleWeight(ax, radius) * detail::triangleWeight(ay, radius);
    if constexpr (F == PixelFilter::Gaussian) return detail::gaussianWeight(dx * dx + dy * dy, radius);
    return 0.0;
}

// Calls body(weightOf) with weightOf(dx, dy) the weight of `filter` of
// half-width `radius`.
template <class Body>
void withFilter(PixelFilter filter, double radius, Body&& body) {
    switch (filter) {
        case PixelFilter::Box:
            return body([radius](double dx, double dy) { return filterWeight<PixelFilter::Box>(radius, dx, dy); });
        case PixelFilter::Triangle:
            return body(
                [radius](double dx, double dy) { return filterWeight<PixelFilter::Triangle>(radius, dx, dy); });
        case PixelFilter::Gaussian:
            return body(
                [radius](double dx, double dy) { return filterWeight<PixelFilter::Gaussian>(radius, dx, dy); });
    }
}

// Everything one sample ray met: its surface hits are
// TileWorkspace::surfaceHits[firstHit, firstHit + hitCount).
struct SampleData {
    std::size_t firstHit = 0, hitCount = 0;
    std::vector<VolumeSample> volume;
    double x = 0.0, y = 0.0;  // raster position
    double time = 0.0;        // in the shutter, [0, 1)
};

// Working memory of one worker thread, kept from tile to tile: once it has
// grown to the largest tile, a tile allocates nothing per sample or per pixel
// but its pixels' results. Vectors of vectors are only ever grown, so that
// each inner vector keeps its storage.
struct TileWorkspace {
    explicit TileWorkspace(const CompressorOptions& compression) : pixel(compression) {}

    detail::LargeVector<SampleData> samples;  // of the tile's sample pixels, spp each
    // The samples' surface hits, one after the other in the samples' order:
    // a pass over the samples (building their transmittances) reads them in
    // turn instead of from a block of its own each.
    detail::LargeVector<SurfaceHit> surfaceHits;
    Span<const SurfaceHit> hitsOf(const SampleData& s) const {
        return Span<const SurfaceHit>(surfaceHits.data() + s.firstHit, s.hitCount);
    }
    detail::LargeVector<std::uint32_t> timeSlot, cell;
    detail::LargeVector<HiderSample> points;
    ScanlineHider::TileHits hits;
    RaySurfaceHits rayHits;
    std::vector<RayVolumeSample> volume;
    // Per sample: its transmittance, prepared for the sweep when a pixel
    // first uses it, then shared by every pixel whose filter reaches the
    // sample.
    detail::LargeVector<SweepInput> transmittances;
    detail::LargeVector<unsigned char> built;
    // A pixel's own rays, for BuildOptions::sampleRays.
    std::vector<SampleRay> ownRays;
    // One pixel's inputs, the first of each in use (sized for the largest).
    std::vector<SampleRay> rays;
    std::vector<const SweepInput*> inputs;
    std::vector<double> weights;
    TransmittanceBuilder transmittance;
    PixelBuilder pixel;
};

struct TileStats {
    PixelTimings timings;
    double castSeconds = 0.0;
    std::uint64_t samples = 0;
    std::uint64_t rawVertices = 0;
    std::uint64_t vertices = 0;
    std::uint32_t maxVertices = 0;
    double preparingSeconds = 0.0;  // the tile made ready for the file (writing)
};

// Defaults of a map built for an area light, chosen from the error budget
// of soft shadows traced through the map on the examples (docs/dsm-lookup.md):
// two layers with sample counts, so a ray sees what lies behind the first
// opaque surface (one layer without counts: 1.7 times the hair ball's error);
// a box filter of one pixel, whose samples are the pixel's own (a wider
// filter lends a pixel its neighbours' occluders and darkens the penumbra;
// the light's rays do the filtering); half the automatic tolerance (3-45 %
// less error for about twice the file; a smaller one gained nothing more).
constexpr int kAreaLightLayers = 2;
constexpr double kAreaLightToleranceScale = 0.5;

}  // namespace

BuildOptions resolvedBuildOptions(const Scene& scene, const BuildOptions& options) {
    BuildOptions o = options;
    const bool areaLight = scene.light.areaLightRadius > 0.0;
    if (!o.width) o.width = scene.light.width;
    if (!o.height) o.height = scene.light.height;
    if (!o.tolerance)
        o.tolerance = autoTolerance(o.samplesPerPixel) * (areaLight ? kAreaLightToleranceScale : 1.0);
    if (!o.filter) o.filter = areaLight ? PixelFilter::Box : PixelFilter::Gaussian;
    if (!o.filterWidth) o.filterWidth = areaLight && *o.filter == PixelFilter::Box ? 1.0 : 2.0;
    if (!o.mtsmLayers) o.mtsmLayers = areaLight ? kAreaLightLayers : 1;
    return o;
}

BuildEstimate estimateBuild(const Scene& scene, const BuildOptions& given) {
    const BuildOptions options = resolvedBuildOptions(scene, given);
    BuildEstimate e;
    e.width = *options.width;
    e.height = *options.height;
    const auto& r = options.region;
    const bool whole = r == std::array<std::uint32_t, 4>{0, 0, 0, 0} || r[0] >= r[2] || r[1] >= r[3];
    e.pixels = whole ? std::uint64_t(e.width) * e.height : std::uint64_t(r[2] - r[0]) * (r[3] - r[1]);
    e.sampleRays = e.pixels * options.samplesPerPixel;
    // A few vertices per pixel: an assumption, real scenes vary widely.
    const int channels = scene.isColoured() ? 3 : 1;
    constexpr std::uint64_t kTypicalVertices = 4;
    const std::uint64_t perPixel = sizeof(VisibilityFunction) + kTypicalVertices * (4 + 4 * std::uint64_t(channels));
    const std::uint64_t tile = std::max<std::uint32_t>(1, options.tileSize);
    std::uint64_t directory = 0;
    for (std::uint64_t w = e.width, h = e.height;; w = (w + 1) / 2, h = (h + 1) / 2) {
        directory += ((w + tile - 1) / tile) * ((h + tile - 1) / tile) * (sizeof(TileSummary) + 1);
        if (w == 1 && h == 1) break;
    }
    const std::uint64_t row = std::uint64_t(e.width) * tile * perPixel;
    const std::uint64_t reach = static_cast<std::uint64_t>(std::ceil(std::max(0.0, 0.5 * *options.filterWidth - 0.5)));
    const std::uint64_t samplePixels = (tile + 2 * reach) * (tile + 2 * reach);
    // Per sample: its data, two hits, and their transmittance prepared for the
    // sweep (four depths).
    const std::uint64_t perSample = sizeof(SampleData) + 2 * sizeof(SurfaceHit) + sizeof(SweepInput) +
                                    4 * (sizeof(SweepInput::Step) + 2 * sizeof(double) * std::uint64_t(channels));
    const unsigned threads = usableThreads(options.threads.value_or(0));
    const std::uint64_t samples = std::uint64_t(threads) * samplePixels * options.samplesPerPixel * perSample;
    // The tiles in flight (tilesInFlight()) and the pending mip tiles, about a row of them.
    const std::uint64_t held = tilesInFlight(static_cast<std::uint32_t>((e.width + tile - 1) / tile), threads);
    e.memoryBytes = directory + held * tile * tile * perPixel + row + samples;
    return e;
}

// Errors about the output (its checks, its writing) leave carrying its path.
BuildStats buildMap(const Scene& scene, const BuildOptions& given, const std::string& path) try {
    const auto wallStart = Clock::now();
    const BuildOptions options = resolvedBuildOptions(scene, given);
    const double filterWidth = *options.filterWidth;
    const int layers = *options.mtsmLayers;
    const PixelFilter filter = *options.filter;
    LightDescription light = scene.light;
    light.width = *options.width;
    light.height = *options.height;
    const std::uint32_t W = light.width, H = light.height;
    const std::string where = concat("build '", path, "'");
    checkOutputPath(path);  // before the work, not after it
    if (W == 0 || H == 0) throw Error(ErrorCode::argument, concat(where, ": resolution ", W, "x", H, " is empty"));
    if (options.threads && *options.threads < 1)
        throw Error(ErrorCode::argument, concat(where, ": worker thread count 0 is not >= 1"));
    if (options.samplesPerPixel < 1 || options.samplesPerPixel > 65536)
        throw Error(ErrorCode::argument,
                    concat(where, ": samples per pixel ", options.samplesPerPixel, " is not in [1, 65536]"));
    if (!std::isfinite(filterWidth) || filterWidth <= 0.0 || filterWidth > 64.0)
        throw Error(ErrorCode::argument, concat(where, ": filter width ", filterWidth, " is not in (0, 64]"));
    if (layers < 1 || layers > 255)
        throw Error(ErrorCode::argument, concat(where, ": MTSM layer count ", layers, " is not in [1, 255]"));
    std::array<std::uint32_t, 4> region = options.region;
    if (region == std::array<std::uint32_t, 4>{0, 0, 0, 0}) region = {0, 0, W, H};
    if (region[0] >= region[2] || region[1] >= region[3] || region[2] > W || region[3] > H)
        throw Error(ErrorCode::argument, concat(where, ": region ", region[0], ",", region[1], ",", region[2], ",",
                                                region[3], " is empty or outside the ", W, "x", H, " image"));

    const LightCamera camera = lightCamera(light);
    const detail::LightRayFrame frame = detail::lightRayFrame(camera, W, H);
    const int channels = scene.isColoured() ? 3 : 1;
    const bool counts = options.counts || layers > 1;
    const std::uint32_t spp = options.samplesPerPixel;
    const double tolerance = *options.tolerance;
    if (!std::isfinite(tolerance) || tolerance < 0.0)
        throw Error(ErrorCode::argument, concat(where, ": tolerance ", tolerance, " is not a finite value >= 0"));
    const double radius = 0.5 * filterWidth;
    const int reach = std::max(0, static_cast<int>(std::ceil(radius - 0.5)));  // neighbour pixels with samples in range
    const std::uint32_t gridY = std::max(1u, static_cast<std::uint32_t>(std::floor(std::sqrt(double(spp)))));
    const std::uint32_t gridX = (spp + gridY - 1) / gridY;

    const bool scanline = options.sampler == SamplerMethod::scanline;
    const RayCaster caster(scene, scanline ? RayCaster::Surfaces::none : RayCaster::Surfaces::hierarchy);

    WriterOptions w;
    w.width = W;
    w.height = H;
    w.tileSize = options.tileSize;
    w.channels = channels;
    w.counts = counts;
    w.maxLayers = layers;
    w.camera = camera;
    w.filter = filter;
    w.filterWidth = filterWidth;
    w.tolerance = tolerance;
    w.mipLevels = options.mipLevels;
    w.levelToleranceFactor = options.levelToleranceFactor;
    w.centredCompression = options.centredCompression;
    w.zlibLevel = options.zlibLevel;
    w.codec = options.codec;
    w.zstdLevel = options.zstdLevel;
    w.quantiseValues = true;
    if (light.areaLightRadius > 0.0 && camera.projection == Projection::Perspective) {
        // The push-back lightCamera applied: the light's plane lies at this
        // light-space depth (AreaLight, Xie et al. 2007 eq. 4).
        const auto& window = camera.screenWindow;
        w.areaLightRadius = light.areaLightRadius;
        w.areaLightPlaneDepth =
            light.areaLightRadius / std::min({window[1], -window[0], window[3], -window[2]});
    }
    {
        nlohmann::json m = {
            {"software", "libdsm"},
            {"scene", scene.path},
            {"settings",
             {{"resolution", {W, H}},
              {"spp", spp},
              {"tolerance", tolerance},
              {"filter", filterName(filter)},
              {"filter_width", filterWidth},
              {"tile_size", options.tileSize},
              {"mtsm_layers", layers},
              {"area_light_radius", light.areaLightRadius},
              {"seed", options.seed},
              {"sampler", scanline ? "scanline" : "raytrace"},
              {"region", region}}}};
        if (options.centredCompression) m["settings"]["compression"] = "centred";
        if (scene.source.size() <= 65536) m["scene_json"] = scene.source;
        w.metadata = m.dump();
    }
    MapWriter writer(path, w);

    CompressorOptions compression;
    // Values are stored rounded to the level's value step: the compressor
    // leaves room for it so the stated tolerance holds as stored.
    compression.tolerance = compressorTolerance(tolerance);
    compression.channels = channels;
    compression.keepCounts = counts;
    compression.maxLayers = layers;
    compression.centred = options.centredCompression;

    tbb::task_arena arena(static_cast<int>(usableThreads(options.threads.value_or(0))));  // 0: all cores
    std::optional<ScanlineHider> hider;
    std::vector<Rgb> objectOpacity;
    for (const SceneObject& object : scene.objects) objectOpacity.push_back(object.opacity);
    if (scanline)  // bucketing the primitives uses the build's threads
        arena.execute([&] { hider.emplace(caster.surfaces(), camera, W, H, w.tileSize, static_cast<std::uint32_t>(reach)); });

    tbb::enumerable_thread_specific<TileWorkspace> workspaces([&] { return TileWorkspace(compression); });

    // The spp samples of one sample pixel into out[0, spp): positions and
    // times, from the pixel's own seed (so a pixel's samples do not depend on
    // the tile or region).
    auto placeSamples = [&](std::uint32_t px, std::uint32_t py, SampleData* out, TileWorkspace& ws) {
        detail::SplitMix64 rng(detail::pixelSeed(options.seed, px, py));
        auto& timeSlot = ws.timeSlot;
        timeSlot.resize(spp);
        for (std::uint32_t k = 0; k < spp; ++k) timeSlot[k] = k;
        for (std::uint32_t k = spp; k > 1; --k) std::swap(timeSlot[k - 1], timeSlot[rng.next() % k]);
        // Strata: cell k of the gridX x gridY grid. When the grid has more
        // cells than samples, spp of them are chosen at random per pixel, so
        // that no part of the pixel is left out every time (unbiased).
        auto& cell = ws.cell;
        cell.resize(gridX * gridY);
        for (std::uint32_t k = 0; k < cell.size(); ++k) cell[k] = k;
        if (cell.size() > spp)
            for (std::uint32_t k = 0; k < spp; ++k)
                std::swap(cell[k], cell[k + rng.next() % (cell.size() - k)]);
        for (std::uint32_t k = 0; k < spp; ++k) {
            SampleData& s = out[k];
            s.hitCount = 0;
            s.volume.clear();
            const std::uint32_t cx = cell[k] % gridX, cy = cell[k] / gridX;
            s.x = px + (cx + rng.uniform()) / gridX;
            s.y = py + (cy + rng.uniform()) / gridY;
            s.time = (timeSlot[k] + rng.uniform()) / spp;
        }
    };
    // Called for the samples in their order: each one's hits follow the
    // previous one's.
    auto addSurfaceHits = [&](std::span<const RaySurfaceHit> hits, SampleData& s, TileWorkspace& ws) {
        s.firstHit = ws.surfaceHits.size();
        s.hitCount = hits.size();
        for (const RaySurfaceHit& h : hits) ws.surfaceHits.push_back(samplerHit(h, objectOpacity));
    };
    auto addVolumeSamples = [&](SampleData& s, std::vector<RayVolumeSample>& volume) {
        if (!caster.hasVolumes()) return;
        Vec3 o, d;
        frame.ray(s.x, s.y, o, d);
        volume.clear();
        caster.volumeSamples(o, d, s.time, camera.nearPlane, volume);
        for (const RayVolumeSample& v : volume) s.volume.push_back({static_cast<float>(v.t), static_cast<float>(v.extinction)});
    };

    // The samples of the sample pixels [x0, x1) x [y0, y1) of tile (tx, ty),
    // placed and given what they cross: ws.samples[((y - y0) * (x1 - x0) +
    // (x - x0)) * spp + k] is pixel (x, y)'s k-th. Returns how many.
    auto sampleTile = [&](std::uint32_t tx, std::uint32_t ty, const std::array<std::uint32_t, 4>& pixels,
                          TileWorkspace& ws, TileStats& stats) {
        const auto start = Clock::now();
        const std::uint32_t sw = pixels[2] - pixels[0];
        const std::size_t count = std::size_t(sw) * (pixels[3] - pixels[1]) * spp;
        if (ws.samples.size() < count) ws.samples.resize(count);
        const std::span<SampleData> samples(ws.samples.data(), count);
        for (std::uint32_t y = pixels[1]; y < pixels[3]; ++y)
            for (std::uint32_t x = pixels[0]; x < pixels[2]; ++x)
                placeSamples(x, y, &samples[(std::size_t(y - pixels[1]) * sw + (x - pixels[0])) * spp], ws);
        if (hider) {
            ws.points.resize(count);
            for (std::size_t i = 0; i < count; ++i) {
                const SampleData& s = samples[i];
                ws.points[i] = HiderSample{s.x, s.y, s.time};
            }
            // The hider fills the tile's own hit array, lent to it: one array
            // of the largest tile's crossings per thread, not two. It keeps
            // its size from tile to tile, so the hider sets only the slots it
            // adds.
            ws.hits.hits.swap(ws.surfaceHits);
            hider->tileHits(tx, ty, pixels, spp, ws.points, camera.nearPlane, objectOpacity, ws.hits);
            ws.hits.hits.swap(ws.surfaceHits);
            for (std::size_t i = 0; i < count; ++i) {
                samples[i].firstHit = ws.hits.start[i];
                samples[i].hitCount = ws.hits.start[i + 1] - ws.hits.start[i];
                addVolumeSamples(samples[i], ws.volume);
            }
        } else {
            ws.surfaceHits.clear();
            for (SampleData& s : samples) {
                Vec3 o, d;
                frame.ray(s.x, s.y, o, d);
                ws.rayHits.clear();
                caster.surfaceHits(o, d, s.time, camera.nearPlane, ws.rayHits);
                addSurfaceHits(ws.rayHits, s, ws);
                addVolumeSamples(s, ws.volume);
            }
        }
        stats.samples += count;
        stats.castSeconds += since(start);
        return count;
    };

    auto computeTile = [&](std::uint32_t tx, std::uint32_t ty, std::vector<VisibilityFunction>& pixels,
                           TileStats& stats) {
        const std::uint32_t x0 = tx * w.tileSize, y0 = ty * w.tileSize;
        const std::uint32_t x1 = std::min(x0 + w.tileSize, W), y1 = std::min(y0 + w.tileSize, H);
        pixels.assign(std::size_t(x1 - x0) * (y1 - y0), VisibilityFunction(channels, counts));
        // Pixels of this tile inside the region.
        const std::uint32_t rx0 = std::max(x0, region[0]), rx1 = std::min(x1, region[2]);
        const std::uint32_t ry0 = std::max(y0, region[1]), ry1 = std::min(y1, region[3]);
        if (rx0 >= rx1 || ry0 >= ry1) return;
        // Sample pixels whose samples can reach them. A tile's samples are all
        // held at once (crossings, transmittances, sweep inputs), so a tile with
        // more than kBandSamples of them is built in bands of rows, each
        // sampling its own border rows again: memory stays bounded at high
        // samples per pixel, and since a pixel's samples and the order of its
        // inputs do not depend on the band, the map is the same.
        const std::uint32_t sx0 = rx0 >= std::uint32_t(reach) ? rx0 - reach : 0, sx1 = std::min(rx1 + reach, W);
        const std::uint32_t sw = sx1 - sx0;
        const std::size_t rowSamples = std::size_t(sw) * spp;
        const std::size_t bandLimit = kBandSamples / rowSamples;
        const std::uint32_t bandRows = bandLimit > std::size_t(2 * reach + 1)
                                           ? static_cast<std::uint32_t>(std::min<std::size_t>(bandLimit - 2 * reach, ry1 - ry0))
                                           : 1u;
        for (std::uint32_t by0 = ry0; by0 < ry1; by0 += bandRows) {
            const std::uint32_t by1 = std::min(by0 + bandRows, ry1);
            const std::uint32_t sy0 = by0 >= std::uint32_t(reach) ? by0 - reach : 0, sy1 = std::min(by1 + reach, H);
            TileWorkspace& ws = workspaces.local();
            const std::size_t sampleCount = sampleTile(tx, ty, {sx0, sy0, sx1, sy1}, ws, stats);
            const std::span<const SampleData> samples(ws.samples.data(), sampleCount);
            // The index of sample pixel (sx, sy)'s first sample in the band's samples and slots.
            const auto firstSampleOf = [&](std::uint32_t sx, std::uint32_t sy) {
                return (std::size_t(sy - sy0) * sw + (sx - sx0)) * spp;
            };
            for (std::uint32_t y = by0; y < by1; ++y)
                for (std::uint32_t x = rx0; x < rx1; ++x) {
                    const auto s = samples.subspan(firstSampleOf(x, y), spp);
                    for (const SampleData& d : s) stats.rawVertices += 2 * d.hitCount + d.volume.size();
                    if (options.sampleRays) {
                        ws.ownRays.clear();
                        for (const SampleData& d : s) ws.ownRays.push_back({ws.hitsOf(d), d.volume});
                        options.sampleRays(x, y, ws.ownRays);
                    }
                }
            if (ws.transmittances.size() < sampleCount) ws.transmittances.resize(sampleCount);
            ws.built.assign(sampleCount, 0);
            // Room for a pixel's inputs: every sample its filter's square reaches.
            const std::size_t footprint = std::size_t(2 * reach + 1) * (2 * reach + 1) * spp;
            if (ws.rays.size() < footprint) {
                ws.rays.resize(footprint);
                ws.inputs.resize(footprint);
                ws.weights.resize(footprint);
            }
            constexpr float kFromTheStart = -std::numeric_limits<float>::infinity();
            // Gathering is timed as the band's pixels' time less what the
            // pixel builder timed: two clock readings a band instead of two
            // a pixel (each reading is about a percent of a build).
            const auto timed = [&] {
                return stats.timings.transmittanceSeconds + stats.timings.sweepSeconds +
                       stats.timings.compressionSeconds;
            };
            const auto pixelsStart = Clock::now();
            const double timedBefore = timed();
            // The workspace's arrays through pointers read once: none is resized
            // in the loop, and stores of pointers into `inputs` would otherwise
            // make the compiler read the vectors' own pointers again.
            SampleRay* const rays = ws.rays.data();
            const SweepInput** const inputs = ws.inputs.data();
            double* const weights = ws.weights.data();
            unsigned char* const built = ws.built.data();
            SweepInput* const transmittances = ws.transmittances.data();
            withFilter(filter, radius, [&](auto weightOf) {
                for (std::uint32_t y = by0; y < by1; ++y)
                    for (std::uint32_t x = rx0; x < rx1; ++x) {
                        std::size_t used = 0;  // the pixel's inputs so far
                        const double cx = x + 0.5, cy = y + 0.5;
                        // The sample pixels [nx0, nx1) x [ny0, ny1) whose samples can reach it.
                        const std::uint32_t nx0 = x >= std::uint32_t(reach) ? x - reach : 0;
                        const std::uint32_t ny0 = y >= std::uint32_t(reach) ? y - reach : 0;
                        const std::uint32_t nx1 = std::min(x + reach + 1, W), ny1 = std::min(y + reach + 1, H);
                        // The next pixel first uses the samples of sample pixel (x + reach + 1,
                        // y + reach): their transmittance slots, cold since their band began (a
                        // slot's first read, of its capacity, stalled on memory), are fetched
                        // ahead, for writing.
                        if (x + reach + 1 < sx1 && y + reach < sy1) {
                            const std::size_t next = firstSampleOf(x + reach + 1, y + reach);
                            const auto* from = reinterpret_cast<const char*>(transmittances + next);
                            const auto* to = reinterpret_cast<const char*>(transmittances + next + spp);
                            for (; from < to; from += 64) __builtin_prefetch(from, 1);
                        }
                        for (std::uint32_t ny = ny0; ny < ny1; ++ny)
                            for (std::uint32_t nx = nx0; nx < nx1; ++nx) {
                                const std::size_t first = firstSampleOf(nx, ny);
                                for (std::size_t i = first; i < first + spp; ++i) {
                                    const SampleData& s = samples[i];
                                    const double wgt = weightOf(s.x - cx, s.y - cy);
                                    if (wgt <= 0.0) continue;
                                    // The ray's fields stored where they go: a copy of a
                                    // ray assembled on the stack read it back whole before
                                    // its halves had been written (a stalled store).
                                    SampleRay& ray = rays[used];
                                    ray.hits = ws.hitsOf(s);
                                    ray.volume = s.volume;
                                    if (!built[i]) {
                                        try {
                                            ws.transmittance.build(ray, channels, counts, kFromTheStart,
                                                                   transmittances[i]);
                                        } catch (const Error& e) {
                                            throw Error(e.code(), concat(where, ": pixel ", x, ",", y, ": ray ", used,
                                                                         ": ", e.what()));
                                        }
                                        built[i] = 1;
                                    }
                                    inputs[used] = &transmittances[i];
                                    weights[used] = wgt;
                                    ++used;
                                }
                            }
                        VisibilityFunction& f = pixels[std::size_t(y - y0) * (x1 - x0) + (x - x0)];
                        if (used == 0) continue;  // a filter too narrow to catch a sample
                        try {
                            ws.pixel.build(Span<const SweepInput* const>(inputs, used), Span<const SampleRay>(rays, used),
                                           Span<const double>(weights, used), f, &stats.timings);
                        } catch (const Error& e) {
                            throw Error(e.code(), concat(where, ": pixel ", x, ",", y, ": ", e.what()));
                        }
                        stats.vertices += f.size();
                        stats.maxVertices = std::max(stats.maxVertices, static_cast<std::uint32_t>(f.size()));
                    }
            });
            stats.timings.transmittanceSeconds += since(pixelsStart) - (timed() - timedBefore);
        }
    };

    BuildStats result;
    result.tolerance = tolerance;
    const std::uint32_t tilesX = writer.tilesX(), tilesY = writer.tilesY();
    const std::uint64_t tileCount = std::uint64_t(tilesX) * tilesY;
    // A pipeline over the tiles in row order: workers build any tile whose
    // turn has come while one of them hands the finished ones to the writer
    // in order (the file is the same for any thread count), so no row waits
    // for its slowest tile. At most `inFlight` tiles are held at once; tile i
    // lives in slot i % inFlight, free again by then because the writer takes
    // tiles in order. The worker that built a tile also prepares it for the
    // file (encoding, compression, its level-1 pixels): only appending it and
    // the coarser levels are left to the writer's turn, which every tile
    // passes through one at a time.
    const std::size_t inFlight = tilesInFlight(tilesX, static_cast<unsigned>(arena.max_concurrency()));
    std::vector<std::vector<VisibilityFunction>> slotTiles(inFlight);
    std::vector<PreparedTile> slotPrepared(inFlight);
    std::vector<TileStats> slotStats(inFlight);
    std::uint64_t nextTile = 0;
    auto writeTile = [&](std::uint64_t i) {
        const auto start = Clock::now();
        const std::uint32_t tx = static_cast<std::uint32_t>(i % tilesX), ty = static_cast<std::uint32_t>(i / tilesX);
        writer.writePreparedTile(slotPrepared[i % inFlight]);
        const TileStats& s = slotStats[i % inFlight];
        result.writingSeconds += s.preparingSeconds;
        result.samplingSeconds += s.castSeconds + s.timings.transmittanceSeconds;
        result.crossingSeconds += s.castSeconds;
        result.sweepSeconds += s.timings.sweepSeconds;
        result.compressionSeconds += s.timings.compressionSeconds;
        result.samples += s.samples;
        result.sampleVertices += s.rawVertices;
        result.vertices += s.vertices;
        result.maxVerticesPerPixel = std::max(result.maxVerticesPerPixel, s.maxVertices);
        result.writingSeconds += since(start);
        if (options.progress && tx + 1 == tilesX && ty + 1 < tilesY) options.progress(double(ty + 1) / tilesY);
    };
    arena.execute([&] {
        tbb::parallel_pipeline(
            inFlight,
            tbb::make_filter<void, std::uint64_t>(tbb::filter_mode::serial_in_order,
                                                  [&](tbb::flow_control& control) -> std::uint64_t {
                                                      if (nextTile == tileCount) control.stop();
                                                      return nextTile++;
                                                  }) &
                tbb::make_filter<std::uint64_t, std::uint64_t>(tbb::filter_mode::parallel,
                                                               [&](std::uint64_t i) {
                                                                   TileStats& stats = slotStats[i % inFlight];
                                                                   stats = TileStats{};
                                                                   const std::uint32_t tx = static_cast<std::uint32_t>(i % tilesX);
                                                                   const std::uint32_t ty = static_cast<std::uint32_t>(i / tilesX);
                                                                   computeTile(tx, ty, slotTiles[i % inFlight], stats);
                                                                   const auto preparing = Clock::now();
                                                                   writer.prepareTile(tx, ty, slotTiles[i % inFlight],
                                                                                      slotPrepared[i % inFlight]);
                                                                   stats.preparingSeconds = since(preparing);
                                                                   return i;
                                                               }) &
                tbb::make_filter<std::uint64_t, void>(tbb::filter_mode::serial_in_order, writeTile));
    });
    if (options.progress) options.progress(1.0);
    // The writer's last levels and directory are written while the build's
    // other threads free what the tiles held: each thread's workspace and the
    // tiles in flight, megabytes of small blocks, whose freeing took one
    // thread about 14 ms after a 512² build.
    arena.execute([&] {
        tbb::parallel_invoke(
            [&] {
                const auto start = Clock::now();
                writer.finish();
                result.writingSeconds += since(start);
            },
            [&] { workspaces.clear(); },
            [&] {
                std::vector<std::vector<VisibilityFunction>>().swap(slotTiles);
                std::vector<PreparedTile>().swap(slotPrepared);
            });
    });
    result.pixels = std::uint64_t(region[2] - region[0]) * (region[3] - region[1]);
    result.rawBytes = result.sampleVertices * (4u + 4u * static_cast<unsigned>(channels));
    std::error_code ignored;
    result.fileBytes = std::filesystem::file_size(path, ignored);
    result.wallSeconds = since(wallStart);
    return result;
} catch (const Error& e) {
    throw e.withFile(path);
}

DSM_NAMESPACE_END
