// bench_soft_shadows: area-light soft shadows on the receivers a viewing
// camera sees, rendered three ways with the same light samples per receiver:
//   (a) ray tracing the deep shadow map as an MTSM (dsm/soft_shadow.h),
//   (b) the classic PCF-based soft shadow from the same map (Xie et al. §3),
//   (c) the reference: stochastic ray tracing of the real scene (Embree).
// Reports, as Xie et al. Tables 1-2, the mean and standard deviation of the
// per-pixel difference to (c) and the shadow time per frame, for each example
// scene, light radius (small, medium, large) and light sample count; then a
// sweep of the knobs (layers K, bias, samples N) on the first two scenes. Writes
// JSON for bench/trade_report.py and one contact sheet per scene (PNG).
//
//   bench_soft_shadows --out FILE.json --images DIR [--smoke] [--bias-study] [--speed] [--error-budget] [--scenes A,B]
//                      [--threads T]
//
// --bias-study runs only the automatic bias against constant biases; --speed
// only the cost of a ray against Embree's and the cost of the first query;
// --error-budget only the MTSM error's sources (build filter, tolerance,
// resolution, samples per pixel, layers, light samples), one at a time, and
// candidate defaults for area-light maps; --budget-rows 'KNOB: VALUE;...'
// runs only the rows named so ("default", "filter: box 1", ...).
// --shadows-only runs only the table of lights and sample counts (--samples
// N,M: its light sample counts). The scene's map is built as dsm-build builds
// a scene with an area light (box filter of width 1, 2 layers, 0.125 /
// sqrt(spp)); --plain-maps builds it with the plain deep shadow map's filter
// and tolerance (Gaussian of width 2, 0.25 / sqrt(spp)) and 4 layers.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include <dsm/area_light.h>
#include <dsm/compressor.h>
#include "image_io.h"
#include <dsm/map_images.h>
#include <dsm/names.h>
#include <dsm/reference_tracer.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>
#include <dsm/soft_shadow.h>

#ifndef DSM_SOFT_EXAMPLES_DIR
#define DSM_SOFT_EXAMPLES_DIR "examples"
#endif

namespace {

using Json = nlohmann::ordered_json;
using dsm::Vec3;

struct Config {
    bool smoke = false;
    bool biasStudyOnly = false;  // --bias-study: only the automatic bias against constants
    bool speedOnly = false;      // --speed: only the cost of a ray and of the first query
    bool errorBudgetOnly = false;  // --error-budget: only the error's sources, one knob at a time
    bool shadowsOnly = false;      // --shadows-only: only the table of lights and sample counts
    bool areaDefaults = true;      // the map as dsm-build builds an area-light scene; --plain-maps: the plain defaults
    std::vector<std::string> scenes;
    std::vector<std::string> budgetRows;  // --budget-rows: the error budget's rows to run ("knob: value"), empty = all
    std::uint32_t mapResolution = 256, mapSpp = 16;
    int mapLayers = 4;
    std::uint32_t imageWidth = 160, imageHeight = 120;
    std::vector<int> samples{64, 256};
    unsigned threads = 0;
    std::filesystem::path images, workDir;
};

Vec3 add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 mul(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 normalize(const Vec3& a) { return mul(a, 1.0 / std::sqrt(dot(a, a))); }

/// Runs body(row) for every row on `threads` threads (rows handed out in turn).
template <class Body>
void parallelRows(std::uint32_t rows, unsigned threads, Body&& body) {
    std::atomic<std::uint32_t> next{0};
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < threads; ++t)
        pool.emplace_back([&] {
            for (std::uint32_t row; (row = next++) < rows;) body(row);
        });
    for (auto& t : pool) t.join();
}

double seconds(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// What the viewing camera sees: per pixel a receiver point (offset off its
/// surface) or none.
struct Receivers {
    std::uint32_t width = 0, height = 0;
    std::vector<Vec3> points;
    std::vector<Vec3> normals;  // of the surface each point lies on (facing the camera)
    std::vector<char> valid;
    std::vector<std::uint32_t> objects;  // the scene object each point lies on
    std::vector<std::string> objectNames;
};

/// A camera that looks at the point the light's axis meets, from the light's
/// position turned 40 degrees about the world y axis around that point and
/// raised a little, so shadows fall visibly on the receivers.
Receivers viewReceivers(const dsm::Scene& scene, const dsm::ReferenceTracer& tracer, const Config& config,
                        double& sceneScale) {
    const Vec3 lightPos = scene.light.position, axis = normalize(scene.light.direction);
    const auto hit = tracer.closestHit(lightPos, axis, 1e30);
    const double distance = hit ? hit->distance : 10.0;
    sceneScale = distance;
    const Vec3 target = add(lightPos, mul(axis, distance));
    const Vec3 back = sub(lightPos, target);
    const double angle = 40.0 * 3.14159265358979 / 180.0;
    Vec3 eyeOffset{std::cos(angle) * back[0] + std::sin(angle) * back[2], back[1] * 0.8,
                   -std::sin(angle) * back[0] + std::cos(angle) * back[2]};
    const Vec3 eye = add(target, mul(eyeOffset, 1.1));
    const Vec3 forward = normalize(sub(target, eye));
    const Vec3 right = normalize(cross(forward, {0.0, 1.0, 0.0}));
    const Vec3 up = cross(right, forward);
    const double tanHalf = std::tan(0.5 * 45.0 * 3.14159265358979 / 180.0);
    Receivers r;
    r.width = config.imageWidth;
    r.height = config.imageHeight;
    r.points.resize(std::size_t(r.width) * r.height);
    r.normals.resize(r.points.size());
    r.objects.assign(r.points.size(), 0);
    for (std::size_t k = 0; k < scene.objects.size(); ++k)
        r.objectNames.push_back(scene.objects[k].name.empty() ? "object " + std::to_string(k) : scene.objects[k].name);
    r.valid.assign(r.points.size(), 0);
    const double aspect = double(r.width) / r.height;
    for (std::uint32_t y = 0; y < r.height; ++y)
        for (std::uint32_t x = 0; x < r.width; ++x) {
            const double sx = (2.0 * (x + 0.5) / r.width - 1.0) * tanHalf * aspect;
            const double sy = (1.0 - 2.0 * (y + 0.5) / r.height) * tanHalf;
            const Vec3 d = normalize(add(forward, add(mul(right, sx), mul(up, sy))));
            const auto h = tracer.closestHit(eye, d, 1e30);
            if (!h) continue;
            // Off the surface, towards the camera, so neither tracer sees the
            // receiver's own surface.
            r.points[std::size_t(y) * r.width + x] = add(h->position, mul(h->normal, 1e-4 * distance));
            r.normals[std::size_t(y) * r.width + x] = h->normal;
            r.valid[std::size_t(y) * r.width + x] = 1;
            r.objects[std::size_t(y) * r.width + x] = h->object;
        }
    return r;
}

struct Frame {
    std::vector<float> v;  // channel 0 visibility per pixel (-1 where no receiver)
    double seconds = 0.0;
};

enum class Method { Mtsm, Pcf, Reference };

/// With `withNormals`, each MTSM query passes its receiver's normal to the
/// automatic bias.
Frame render(Method method, const Receivers& r, const std::shared_ptr<const dsm::SoftShadowTracer>& tracer,
             const dsm::ReferenceTracer& reference, const dsm::AreaLight& light, const dsm::SoftShadowOptions& o,
             unsigned threads, bool withNormals = false) {
    Frame f;
    f.v.assign(r.points.size(), -1.0f);
    const auto start = std::chrono::steady_clock::now();
    parallelRows(r.height, threads, [&](std::uint32_t y) {
        dsm::SoftShadowContext context(tracer);
        dsm::SoftShadowOptions own = o;
        std::vector<Vec3> samples;
        for (std::uint32_t x = 0; x < r.width; ++x) {
            const std::size_t i = std::size_t(y) * r.width + x;
            if (!r.valid[i]) continue;
            const Vec3& p = r.points[i];
            double v = 1.0;
            if (method == Method::Mtsm) {
                if (withNormals) own.normal = r.normals[i];
                v = context.visibility(p, own).v[0];
            } else if (method == Method::Pcf) {
                v = context.pcfVisibility(p, o).v[0];
            } else {
                // The map holds visibility averaged over the shutter: so does
                // the reference, one stratified shutter time per light sample.
                samples = light.samples(p, o.samples, o.seed);
                double sum = 0.0;
                for (std::size_t k = 0; k < samples.size(); ++k)
                    sum += reference.transmittance(p, samples[k], (k + 0.5) / samples.size())[0];
                v = sum / samples.size();
            }
            f.v[i] = static_cast<float>(v);
        }
    });
    f.seconds = seconds(start);
    return f;
}

struct Difference {
    double mean = 0.0, stddev = 0.0, max = 0.0;
};

/// Mean and standard deviation of |a - b| over receivers.
Difference difference(const Frame& a, const Frame& b) {
    double sum = 0.0, sumSquares = 0.0, worst = 0.0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < a.v.size(); ++i) {
        if (a.v[i] < 0.0f) continue;
        const double d = std::abs(double(a.v[i]) - b.v[i]);
        sum += d;
        sumSquares += d * d;
        worst = std::max(worst, d);
        ++n;
    }
    Difference d;
    if (n) {
        d.mean = sum / n;
        d.stddev = std::sqrt(std::max(0.0, sumSquares / n - d.mean * d.mean));
        d.max = worst;
    }
    return d;
}

Json toJson(const Difference& d) { return Json{{"mean", d.mean}, {"stddev", d.stddev}, {"max", d.max}}; }

/// Where a method's mean error comes from: the sums of |method - reference|
/// over the receivers the reference sees lit (1), in the umbra (0) and in
/// the penumbra (between), each divided by all the receivers, so the three
/// add up to the mean error; and how many receivers each class holds.
Json errorByClass(const Frame& method, const Frame& reference) {
    double sum[3] = {0.0, 0.0, 0.0};
    std::size_t count[3] = {0, 0, 0}, n = 0;
    for (std::size_t i = 0; i < method.v.size(); ++i) {
        if (method.v[i] < 0.0f) continue;
        const int c = reference.v[i] >= 1.0f ? 0 : reference.v[i] <= 0.0f ? 1 : 2;
        sum[c] += std::abs(double(method.v[i]) - reference.v[i]);
        ++count[c];
        ++n;
    }
    Json out;
    const char* names[] = {"lit", "umbra", "penumbra"};
    for (int c = 0; c < 3; ++c)
        out[names[c]] = {{"receivers", count[c]}, {"error_share", n ? sum[c] / double(n) : 0.0}};
    return out;
}

/// Copies a frame into a cell of a contact sheet: visibility as grey
/// (background dark blue), or with `reference` the signed difference x4 as
/// red (too bright) and blue (too dark).
void blit(dsm::FloatImage& sheet, std::uint32_t cellX, std::uint32_t cellY, std::uint32_t w, std::uint32_t h,
          const Frame& f, const Frame* reference) {
    for (std::uint32_t y = 0; y < h; ++y)
        for (std::uint32_t x = 0; x < w; ++x) {
            const std::size_t i = std::size_t(y) * w + x;
            float rgb[3] = {0.05f, 0.05f, 0.15f};
            if (f.v[i] >= 0.0f) {
                if (reference) {
                    const float d = 4.0f * (f.v[i] - reference->v[i]);
                    rgb[0] = std::clamp(d, 0.0f, 1.0f);
                    rgb[1] = 0.0f;
                    rgb[2] = std::clamp(-d, 0.0f, 1.0f);
                } else {
                    rgb[0] = rgb[1] = rgb[2] = f.v[i];
                }
            }
            for (int c = 0; c < 3; ++c) sheet.at(cellX * (w + 4) + x, cellY * (h + 4) + y, c) = rgb[c];
        }
}

std::string stem(const std::string& path) {
    std::string name = std::filesystem::path(path).filename().string();
    return name.substr(0, name.find('.'));
}

/// Time to the first soft query on a map nobody has read yet: opening it,
/// making the tracer and a context, and answering one query (defaults, 64
/// rays), for receivers spread over the view, each with a fresh open; the
/// median, the maximum and the depth pyramids built.
Json firstQuery(const std::filesystem::path& path, const std::vector<Vec3>& points, double radius,
                const dsm::Scene& scene, const dsm::SoftShadowOptions& base) {
    const std::size_t runs = std::min<std::size_t>(15, points.size());
    std::vector<double> times;
    double tilesBuilt = 0.0;
    unsigned tiles = 0;
    for (std::size_t k = 0; k < runs; ++k) {
        const Vec3& p = points[k * points.size() / runs];
        const auto start = std::chrono::steady_clock::now();
        const auto map = dsm::DeepShadowMap::open(path.string());
        const double plane = dsm::AreaLight::disk(map->info().camera, scene.light.areaLightRadius).planeDepth();
        const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(
            map, dsm::AreaLight::disk(map->info().camera, radius, plane));
        dsm::SoftShadowContext context(tracer);
        dsm::SoftShadowOptions o = base;
        o.samples = 64;
        context.visibility(p, o);
        times.push_back(seconds(start));
        tilesBuilt += double(tracer->hierarchyTilesBuilt()) / double(runs);
        tiles = map->info().levels[0].tilesX * map->info().levels[0].tilesY;
    }
    std::sort(times.begin(), times.end());
    return Json{{"runs", runs},
                {"median_seconds", times.empty() ? 0.0 : times[times.size() / 2]},
                {"max_seconds", times.empty() ? 0.0 : times.back()},
                {"mean_tiles_built", tilesBuilt},
                {"tiles", tiles}};
}

/// Rays per second on one core through the map (MTSM with the hierarchy,
/// classification off, so every ray is traced) and through the real scene
/// (the Embree reference's transmittance), for the same receivers, light
/// samples and light (medium), both including the drawing of the light
/// samples; measured in one run, alternating slice by slice of the receivers.
Json raySpeed(const std::shared_ptr<const dsm::DeepShadowMap>& map, const Receivers& receivers,
              const dsm::ReferenceTracer& reference, double radius, double planeDepth,
              const dsm::SoftShadowOptions& base, const std::string& name) {
    std::vector<Vec3> points;
    for (std::size_t i = 0; i < receivers.points.size(); i += 3)
        if (receivers.valid[i]) points.push_back(receivers.points[i]);
    const dsm::AreaLight light = dsm::AreaLight::disk(map->info().camera, radius, planeDepth);
    const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(map, light);
    dsm::SoftShadowOptions o = base;
    o.samples = 64;
    o.classification = false;
    dsm::SoftShadowContext context(tracer);
    for (const Vec3& p : points) context.visibility(p, o);  // warm: tiles decoded, pyramids built
    context.resetStats();
    // The receivers in slices, each traced through the map and then through
    // the scene, so that both see the machine as it is at that moment (on a
    // shared machine the speed moves between one phase and the next).
    constexpr std::size_t kSlices = 16;
    double mapSeconds = 0.0, sceneSeconds = 0.0, sceneRays = 0.0, sink = 0.0;
    for (std::size_t slice = 0; slice < kSlices; ++slice) {
        const std::size_t begin = points.size() * slice / kSlices, end = points.size() * (slice + 1) / kSlices;
        auto start = std::chrono::steady_clock::now();
        for (std::size_t i = begin; i < end; ++i) context.visibility(points[i], o);
        mapSeconds += seconds(start);
        start = std::chrono::steady_clock::now();
        for (std::size_t i = begin; i < end; ++i) {
            const Vec3& p = points[i];
            const std::vector<Vec3> samples = light.samples(p, o.samples, o.seed);
            for (std::size_t k = 0; k < samples.size(); ++k)
                sink += reference.transmittance(p, samples[k], (k + 0.5) / samples.size())[0];
            sceneRays += double(samples.size());
        }
        sceneSeconds += seconds(start);
    }
    const double mapRays = double(context.stats().rays);
    const double opaque = double(context.stats().raysProvenOpaque);
    const double mapRate = mapRays / std::max(1e-9, mapSeconds), sceneRate = sceneRays / std::max(1e-9, sceneSeconds);
    std::printf("  %s rays, one core, classification off: map %.3g/s, scene (Embree) %.3g/s: map / scene %.2f "
                "(%.0f rays each; %.1f %% of map rays proven opaque; checksum %.3g)\n",
                name.c_str(), mapRate, sceneRate, mapRate / sceneRate, mapRays, 100.0 * opaque / std::max(1.0, mapRays),
                sink);
    std::fflush(stdout);
    return Json{{"receivers", points.size()},
                {"rays", mapRays},
                {"map_rays_per_second", mapRate},
                {"scene_rays_per_second", sceneRate},
                {"map_over_scene", mapRate / sceneRate},
                {"rays_proven_opaque", opaque},
                {"nodes_per_ray", double(context.stats().nodesVisited) / std::max(1.0, mapRays)},
                {"pixels_per_ray", double(context.stats().pixelsVisited) / std::max(1.0, mapRays)}};
}

/// A map with the plain deep shadow map's filter (Gaussian, width 2) and
/// automatic tolerance 0.25 / sqrt(spp) and the configured MTSM layers, all
/// set here: the error budget's baseline, the resolution scaling's maps and,
/// with --plain-maps, the scene's map (otherwise built with dsm-build's
/// defaults for an area-light scene).
dsm::BuildOptions benchBuild(const Config& config, std::uint32_t size, std::uint32_t spp) {
    dsm::BuildOptions build;
    build.width = build.height = size;
    build.samplesPerPixel = spp;
    build.tolerance = dsm::autoTolerance(spp);
    build.filter = dsm::PixelFilter::Gaussian;
    build.filterWidth = 2.0;
    build.mtsmLayers = config.mapLayers;
    build.threads = config.threads;
    return build;
}

/// Cost of a ray through the map against the map's resolution (Xie §4.3):
/// the same receivers and light at 128² .. 1024², every ray walked pixel by
/// pixel or through the min/max depth hierarchy (classification off, so
/// every ray is traced), one thread. Counts come from SoftShadowStats.
Json hierarchyScaling(const Config& config, const dsm::Scene& sceneIn, const Receivers& receivers, double radius,
                      const dsm::SoftShadowOptions& base, const std::string& name) {
    dsm::Scene scene = sceneIn;  // areaLightRadius already set for the largest light
    const std::vector<std::uint32_t> sizes =
        config.smoke ? std::vector<std::uint32_t>{16, 32} : std::vector<std::uint32_t>{128, 256, 512, 1024};
    std::vector<Vec3> points;
    for (std::size_t i = 0; i < receivers.points.size(); i += 7)
        if (receivers.valid[i]) points.push_back(receivers.points[i]);
    Json rows = Json::array();
    for (const std::uint32_t size : sizes) {
        const dsm::BuildOptions build = benchBuild(config, size, 4);
        const auto path = config.workDir / (name + "-scaling.dsm");
        dsm::buildMap(scene, build, path.string());
        Json row{{"resolution", size}, {"receivers", points.size()}, {"first_query", firstQuery(path, points, radius, scene, base)}};
        const auto map = dsm::DeepShadowMap::open(path.string());
        const double plane = dsm::AreaLight::disk(map->info().camera, scene.light.areaLightRadius).planeDepth();
        const dsm::AreaLight light = dsm::AreaLight::disk(map->info().camera, radius, plane);
        const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(map, light);
        for (const bool hierarchy : {false, true}) {
            dsm::SoftShadowContext context(tracer);
            dsm::SoftShadowOptions o = base;
            o.samples = 64;
            o.hierarchy = hierarchy;
            o.classification = false;
            const auto start = std::chrono::steady_clock::now();
            for (const Vec3& p : points) context.visibility(p, o);
            const double wall = seconds(start);
            const dsm::SoftShadowStats& st = context.stats();
            const double rays = std::max<double>(1.0, double(st.rays));
            row[hierarchy ? "hierarchy" : "walk"] = {{"rays", st.rays},
                                                     {"pixels_per_ray", st.pixelsVisited / rays},
                                                     {"nodes_per_ray", st.nodesVisited / rays},
                                                     {"microseconds_per_ray", 1e6 * wall / rays}};
        }
        std::printf("  %s scaling %4u^2: first query %.2f ms (median of %d, max %.2f ms, %.1f of %u tiles' depth "
                    "pyramids)\n",
                    name.c_str(), size, 1e3 * row["first_query"]["median_seconds"].get<double>(),
                    row["first_query"]["runs"].get<int>(), 1e3 * row["first_query"]["max_seconds"].get<double>(),
                    row["first_query"]["mean_tiles_built"].get<double>(), row["first_query"]["tiles"].get<unsigned>());
        std::printf("  %s scaling %4u^2: walk %.1f px/ray %.2f us/ray | hierarchy %.1f px + %.1f nodes/ray %.2f us/ray\n",
                    name.c_str(), size, row["walk"]["pixels_per_ray"].get<double>(),
                    row["walk"]["microseconds_per_ray"].get<double>(), row["hierarchy"]["pixels_per_ray"].get<double>(),
                    row["hierarchy"]["nodes_per_ray"].get<double>(),
                    row["hierarchy"]["microseconds_per_ray"].get<double>());
        std::fflush(stdout);
        rows.push_back(std::move(row));
    }
    return rows;
}

/// The automatic bias against hand-tuned constants (medium light, 64 rays):
/// the mean error of constant biases from 0.0005 to 0.5 times the scene's
/// scale, and of the automatic bias with and without the receivers' normals;
/// and the receivers the reference sees fully lit that read below 0.9
/// (self-shadowing).
Json biasStudy(const Config& config, const std::shared_ptr<const dsm::DeepShadowMap>& map, const Receivers& receivers,
               const dsm::ReferenceTracer& reference, double radius, double planeDepth, double scale,
               const dsm::SoftShadowOptions& base, const std::string& name) {
    const dsm::AreaLight light = dsm::AreaLight::disk(map->info().camera, radius, planeDepth);
    const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(map, light);
    dsm::SoftShadowOptions o = base;
    o.samples = 64;
    const Frame ref = render(Method::Reference, receivers, tracer, reference, light, o, config.threads);
    auto litButDark = [&](const Frame& f) {
        std::size_t n = 0;
        for (std::size_t i = 0; i < f.v.size(); ++i) n += ref.v[i] >= 1.0f && f.v[i] >= 0.0f && f.v[i] < 0.9f;
        return n;
    };
    std::size_t lit = 0;
    for (const float v : ref.v) lit += v >= 1.0f;
    Json constants = Json::array();
    double best = 1e300, bestBias = 0.0;
    for (const double f : {0.0005, 0.001, 0.002, 0.004, 0.008, 0.015, 0.03, 0.06, 0.125, 0.25, 0.5}) {
        o.bias = f * scale;
        const Frame mtsm = render(Method::Mtsm, receivers, tracer, reference, light, o, config.threads);
        const Difference d = difference(mtsm, ref);
        constants.push_back({{"bias", *o.bias}, {"error", toJson(d)}, {"lit_but_dark", litButDark(mtsm)}});
        if (d.mean < best) {
            best = d.mean;
            bestBias = *o.bias;
        }
    }
    Json out{{"constants", constants}, {"best_bias", bestBias}, {"best_error", best}, {"lit_receivers", lit}};
    // Where the automatic bias's error and the best constant's come from:
    // each object's receivers' share of the mean error.
    auto byObject = [&](const Frame& f) {
        std::vector<double> share(receivers.objectNames.size(), 0.0);
        std::vector<std::size_t> dark(receivers.objectNames.size(), 0);
        std::size_t n = 0;
        for (std::size_t i = 0; i < f.v.size(); ++i)
            if (f.v[i] >= 0.0f) {
                share[receivers.objects[i]] += std::abs(double(f.v[i]) - ref.v[i]);
                dark[receivers.objects[i]] += ref.v[i] >= 1.0f && f.v[i] < 0.9f;
                ++n;
            }
        Json objects;
        for (std::size_t k = 0; k < share.size(); ++k)
            objects[receivers.objectNames[k]] = {{"error_share", share[k] / double(std::max<std::size_t>(1, n))},
                                                 {"lit_but_dark", dark[k]}};
        return objects;
    };
    {
        dsm::SoftShadowOptions atBest = o;
        atBest.bias = bestBias;
        out["best_by_object"] =
            byObject(render(Method::Mtsm, receivers, tracer, reference, light, atBest, config.threads));
    }
    o.bias.reset();
    out["auto_by_object"] = byObject(render(Method::Mtsm, receivers, tracer, reference, light, o, config.threads));
    std::printf("  %s bias by object (error share, lit receivers below 0.9): best constant %s | auto %s\n",
                name.c_str(), out["best_by_object"].dump().c_str(), out["auto_by_object"].dump().c_str());
    for (const bool normals : {false, true}) {
        const Frame mtsm = render(Method::Mtsm, receivers, tracer, reference, light, o, config.threads, normals);
        const Difference d = difference(mtsm, ref);
        out[normals ? "auto_normals" : "auto"] = {
            {"error", toJson(d)}, {"ratio_to_best", d.mean / best}, {"lit_but_dark", litButDark(mtsm)}};
        std::printf("  %s bias: best constant %.4g err %.4f | auto%s err %.4f (x%.3f of best), %zu of %zu lit "
                    "receivers below 0.9\n",
                    name.c_str(), bestBias, best, normals ? "+normals" : "", d.mean, d.mean / best, litButDark(mtsm),
                    lit);
    }
    std::fflush(stdout);
    return out;
}

/// Where the MTSM error comes from (medium light): the default map and
/// light samples against one change at a time (build filter, tolerance,
/// resolution, samples per pixel, layers used, light samples) and all the
/// build changes together. Per row the mean |MTSM - reference| over all
/// receivers and the mean signed error over the penumbra's (the reference
/// strictly between 0.02 and 0.98).
Json errorBudget(const Config& config, const dsm::Scene& sceneIn, const Receivers& receivers,
                 const dsm::ReferenceTracer& reference, double radius, double largestRadius,
                 const dsm::SoftShadowOptions& base, const dsm::BuildOptions& defaults, const std::string& name) {
    dsm::Scene scene = sceneIn;
    scene.light.areaLightRadius = largestRadius;
    struct Row {
        std::string knob, value;
        dsm::BuildOptions build;
        int samples = 64;
        std::optional<int> layers;
    };
    auto with = [&](auto change) {
        dsm::BuildOptions b = defaults;
        change(b);
        return b;
    };
    const auto boxOne = [](dsm::BuildOptions& b) {
        b.filter = dsm::PixelFilter::Box;
        b.filterWidth = 1.0;
    };
    std::vector<Row> rows{
        {"default", "", defaults, 64, std::nullopt},
        {"filter", "box 1", with(boxOne), 64, std::nullopt},
        {"tolerance", "0.005", with([](auto& b) { b.tolerance = 0.005; }), 64, std::nullopt},
        {"tolerance", "0.02", with([](auto& b) { b.tolerance = 0.02; }), 64, std::nullopt},
        {"resolution", "512", with([](auto& b) { b.width = b.height = 512u; }), 64, std::nullopt},
        {"resolution", "1024", with([](auto& b) { b.width = b.height = 1024u; }), 64, std::nullopt},
        {"spp", "64", with([](auto& b) { b.samplesPerPixel = 64; }), 64, std::nullopt},
        {"layers", "1", defaults, 64, 1},
        {"layers", "2", defaults, 64, 2},
        {"light samples", "16", defaults, 16, std::nullopt},
        {"light samples", "256", defaults, 256, std::nullopt},
        {"all builds", "box 1, 0.005, 1024", with([&](auto& b) {
             boxOne(b);
             b.tolerance = 0.005;
             b.width = b.height = 1024u;
         }),
         64, std::nullopt},
        {"dsm-build defaults", "area light", [&] {
             dsm::BuildOptions b;  // what buildMap resolves for a scene with an area light
             b.width = defaults.width;
             b.height = defaults.height;
             b.samplesPerPixel = defaults.samplesPerPixel;
             b.threads = defaults.threads;
             return b;
         }(),
         64, std::nullopt},
        // Candidates for the defaults of a map built for an area light.
        {"built layers", "1, no counts", with([](auto& b) { b.mtsmLayers = 1; }), 64, std::nullopt},
        {"built layers", "2", with([](auto& b) { b.mtsmLayers = 2; }), 64, std::nullopt},
        {"box 1, 2 layers", "", with([&](auto& b) {
             boxOne(b);
             b.mtsmLayers = 2;
         }),
         64, std::nullopt},
        {"box 1, 2 layers", "tolerance 0.031", with([&](auto& b) {
             boxOne(b);
             b.mtsmLayers = 2;
             b.tolerance = 0.03125;
         }),
         64, std::nullopt},
        {"box 1, 1 layer", "tolerance 0.031", with([&](auto& b) {
             boxOne(b);
             b.mtsmLayers = 1;
             b.tolerance = 0.03125;
         }),
         64, std::nullopt},
        {"box 1, 1 layer, counts", "tolerance 0.031", with([&](auto& b) {
             boxOne(b);
             b.mtsmLayers = 1;
             b.counts = true;
             b.tolerance = 0.03125;
         }),
         64, std::nullopt},
        {"box 1, 2 layers", "tolerance 0.02", with([&](auto& b) {
             boxOne(b);
             b.mtsmLayers = 2;
             b.tolerance = 0.02;
         }),
         64, std::nullopt},
    };
    if (!config.budgetRows.empty())
        std::erase_if(rows, [&](const Row& row) {
            const std::string id = row.value.empty() ? row.knob : row.knob + ": " + row.value;
            return std::find(config.budgetRows.begin(), config.budgetRows.end(), id) == config.budgetRows.end();
        });
    std::map<int, Frame> references;
    Json out = Json::array();
    for (const Row& row : rows) {
        const auto path = config.workDir / (name + "-budget.dsm");
        const dsm::BuildStats built = dsm::buildMap(scene, row.build, path.string());
        const auto map = dsm::DeepShadowMap::open(path.string());
        const double plane = dsm::AreaLight::disk(map->info().camera, largestRadius).planeDepth();
        const dsm::AreaLight light = dsm::AreaLight::disk(map->info().camera, radius, plane);
        const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(map, light);
        dsm::SoftShadowOptions o = base;
        o.samples = row.samples;
        o.layers = row.layers;
        if (!references.count(row.samples))
            references[row.samples] = render(Method::Reference, receivers, tracer, reference, light, o, config.threads);
        const Frame& ref = references[row.samples];
        const Frame mtsm = render(Method::Mtsm, receivers, tracer, reference, light, o, config.threads);
        double signedSum = 0.0;
        std::size_t penumbra = 0;
        for (std::size_t i = 0; i < ref.v.size(); ++i)
            if (ref.v[i] > 0.02f && ref.v[i] < 0.98f) {
                signedSum += double(mtsm.v[i]) - ref.v[i];
                ++penumbra;
            }
        const Difference d = difference(mtsm, ref);
        const double penumbraSigned = penumbra ? signedSum / double(penumbra) : 0.0;
        out.push_back({{"knob", row.knob},
                       {"value", row.value},
                       {"samples", row.samples},
                       {"file_bytes", map->info().fileBytes},
                       {"tolerance", built.tolerance},
                       {"error", toJson(d)},
                       {"penumbra_receivers", penumbra},
                       {"penumbra_signed_error", penumbraSigned}});
        std::printf("  %s budget %-13s %-18s err %.4f  penumbra signed %+.4f (%zu)  %.0f KiB\n", name.c_str(),
                    row.knob.c_str(), row.value.c_str(), d.mean, penumbraSigned, penumbra,
                    double(map->info().fileBytes) / 1024.0);
        std::fflush(stdout);
    }
    return out;
}

Json runScene(const Config& config, const std::string& file, bool sweepKnobs, bool scaling) {
    const std::string name = stem(file);
    dsm::Scene scene = dsm::loadScene(file);
    const dsm::ReferenceTracer reference(scene);
    double scale = 1.0;
    const Receivers receivers = viewReceivers(scene, reference, config, scale);
    const double radii[] = {0.02 * scale, 0.05 * scale, 0.12 * scale};
    const char* radiusNames[] = {"small", "medium", "large"};

    // One map serves every radius: built for the largest light, so its
    // push-back lets it see whatever any point of that light sees.
    scene.light.areaLightRadius = radii[2];
    dsm::BuildOptions build = benchBuild(config, config.mapResolution, config.mapSpp);
    if (config.areaDefaults) {
        // Only what the bench fixes; the rest as dsm-build gives a scene with an area light.
        build.tolerance.reset();
        build.filter.reset();
        build.filterWidth.reset();
        build.mtsmLayers.reset();
    }
    const auto mapPath = config.workDir / (name + "-soft.dsm");
    const dsm::BuildStats built = dsm::buildMap(scene, build, mapPath.string());
    const auto map = dsm::DeepShadowMap::open(mapPath.string());
    const double planeDepth = dsm::AreaLight::disk(map->info().camera, radii[2]).planeDepth();

    Json out;
    out["scene"] = name;
    out["scale"] = scale;
    out["map"] = {{"resolution", config.mapResolution},
                  {"spp", config.mapSpp},
                  {"layers", map->info().maxLayers},
                  {"filter", dsm::filterName(map->info().filter)},
                  {"filter_width", map->info().filterWidth},
                  {"tolerance", built.tolerance},
                  {"file_bytes", map->info().fileBytes},
                  {"build_seconds", built.wallSeconds}};
    out["image"] = {{"width", receivers.width}, {"height", receivers.height}};
    dsm::SoftShadowOptions base;
    // The bias is automatic (dsm/auto_bias.h): see the bias study below.
    base.zThreshold = 0.003 * scale;
    out["bias"] = "auto";
    out["z_threshold"] = base.zThreshold;

    if (config.errorBudgetOnly) {
        out["error_budget"] = errorBudget(config, scene, receivers, reference, radii[1], radii[2], base, build, name);
        return out;
    }
    if (!config.shadowsOnly && !config.biasStudyOnly) out["ray_speed"] = raySpeed(map, receivers, reference, radii[1], planeDepth, base, name);
    if (config.speedOnly) {
        if (scaling) out["scaling"] = hierarchyScaling(config, scene, receivers, radii[1], base, name);
        return out;
    }
    if (config.biasStudyOnly) {
        out["bias_study"] = biasStudy(config, map, receivers, reference, radii[1], planeDepth, scale, base, name);
        return out;
    }
    const std::uint32_t w = receivers.width, h = receivers.height;
    dsm::FloatImage sheet((w + 4) * 5, (h + 4) * 3, 3, 0.0f);
    Json rows = Json::array();
    for (int ri = 0; ri < 3; ++ri) {
        const dsm::AreaLight light = dsm::AreaLight::disk(map->info().camera, radii[ri], planeDepth);
        const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(map, light);
        for (const int n : config.samples) {
            dsm::SoftShadowOptions o = base;
            o.samples = n;
            const Frame ref = render(Method::Reference, receivers, tracer, reference, light, o, config.threads);
            const Frame mtsm = render(Method::Mtsm, receivers, tracer, reference, light, o, config.threads);
            const Frame pcf = render(Method::Pcf, receivers, tracer, reference, light, o, config.threads);
            const Difference dm = difference(mtsm, ref), dp = difference(pcf, ref);
            rows.push_back({{"radius", radiusNames[ri]},
                            {"radius_world", radii[ri]},
                            {"samples", n},
                            {"reference_seconds", ref.seconds},
                            {"mtsm_seconds", mtsm.seconds},
                            {"pcf_seconds", pcf.seconds},
                            {"mtsm_error", toJson(dm)},
                            {"pcf_error", toJson(dp)},
                            {"mtsm_error_by_class", errorByClass(mtsm, ref)},
                            {"pcf_error_by_class", errorByClass(pcf, ref)}});
            const Json em = errorByClass(mtsm, ref), ep = errorByClass(pcf, ref);
            std::printf("  %s %-6s N=%3d  error shares lit/umbra/penumbra (%zu/%zu/%zu receivers): MTSM "
                        "%.4f/%.4f/%.4f | PCF %.4f/%.4f/%.4f\n",
                        name.c_str(), radiusNames[ri], n, em["lit"]["receivers"].get<std::size_t>(),
                        em["umbra"]["receivers"].get<std::size_t>(), em["penumbra"]["receivers"].get<std::size_t>(),
                        em["lit"]["error_share"].get<double>(), em["umbra"]["error_share"].get<double>(),
                        em["penumbra"]["error_share"].get<double>(), ep["lit"]["error_share"].get<double>(),
                        ep["umbra"]["error_share"].get<double>(), ep["penumbra"]["error_share"].get<double>());
            std::printf("  %s %-6s N=%3d  reference %6.2f s | MTSM %6.2f s err %.4f±%.4f | PCF %6.2f s err %.4f±%.4f\n",
                        name.c_str(), radiusNames[ri], n, ref.seconds, mtsm.seconds, dm.mean, dm.stddev, pcf.seconds,
                        dp.mean, dp.stddev);
            std::fflush(stdout);
            if (n == config.samples.back()) {
                blit(sheet, 0, ri, w, h, ref, nullptr);
                blit(sheet, 1, ri, w, h, mtsm, nullptr);
                blit(sheet, 2, ri, w, h, pcf, nullptr);
                blit(sheet, 3, ri, w, h, mtsm, &ref);
                blit(sheet, 4, ri, w, h, pcf, &ref);
            }
        }
    }
    out["rows"] = std::move(rows);
    if (config.shadowsOnly) return out;
    const std::string sheetName = "soft-" + name + ".png";
    dsm::writeImage((config.images / sheetName).string(), sheet);
    out["sheet"] = sheetName;

    if (sweepKnobs) {
        // The knobs of the trade at the medium radius: layers K, bias, samples N.
        const dsm::AreaLight light = dsm::AreaLight::disk(map->info().camera, radii[1], planeDepth);
        const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(map, light);
        Json knobs = Json::array();
        auto measure = [&](const char* knob, double value, const dsm::SoftShadowOptions& o) {
            const Frame ref = render(Method::Reference, receivers, tracer, reference, light, o, config.threads);
            const Frame mtsm = render(Method::Mtsm, receivers, tracer, reference, light, o, config.threads);
            const Difference d = difference(mtsm, ref);
            knobs.push_back({{"knob", knob},
                             {"value", value},
                             {"samples", o.samples},
                             {"layers", o.layers.value_or(0)},  // 0: all of the map's layers
                             {"bias", o.bias.value_or(-1.0)},  // -1: automatic
                             {"mtsm_seconds", mtsm.seconds},
                             {"reference_seconds", ref.seconds},
                             {"error", toJson(d)}});
            std::printf("  %s knob %-7s %8.4g  MTSM %6.2f s  err %.4f±%.4f  (reference %.2f s)\n", name.c_str(), knob,
                        value, mtsm.seconds, d.mean, d.stddev, ref.seconds);
            std::fflush(stdout);
        };
        for (const int k : {1, 2, 4}) {
            dsm::SoftShadowOptions o = base;
            o.layers = k;
            measure("layers", k, o);
        }
        for (const double f : {0.25, 1.0, 4.0}) {
            dsm::SoftShadowOptions o = base;
            o.bias = 0.015 * scale * f;
            measure("bias", *o.bias, o);
        }
        for (const int n : {16, 64, 256}) {
            dsm::SoftShadowOptions o = base;
            o.samples = n;
            measure("samples", n, o);
        }
        out["knobs"] = std::move(knobs);
    }
    out["bias_study"] = biasStudy(config, map, receivers, reference, radii[1], planeDepth, scale, base, name);
    if (scaling) out["scaling"] = hierarchyScaling(config, scene, receivers, radii[1], base, name);
    return out;
}

std::vector<std::string> splitList(const std::string& text, char separator = ',') {
    std::vector<std::string> out;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, separator);)
        if (!item.empty()) out.push_back(item);
    return out;
}

}  // namespace

int main(int argc, char** argv) {
    Config config;
    std::string outPath, budgetRows, samples, scenes = std::string(DSM_SOFT_EXAMPLES_DIR) + "/hairball.json," + DSM_SOFT_EXAMPLES_DIR +
                                  "/cloud-and-pipes.json," + DSM_SOFT_EXAMPLES_DIR + "/leaves.json," +
                                  DSM_SOFT_EXAMPLES_DIR + "/motion.json";
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const bool hasValue = i + 1 < argc;
        if (a == "--smoke") config.smoke = true;
        else if (a == "--bias-study") config.biasStudyOnly = true;
        else if (a == "--speed") config.speedOnly = true;
        else if (a == "--error-budget") config.errorBudgetOnly = true;
        else if (a == "--out" && hasValue) outPath = argv[++i];
        else if (a == "--images" && hasValue) config.images = argv[++i];
        else if (a == "--scenes" && hasValue) scenes = argv[++i];
        else if (a == "--budget-rows" && hasValue) budgetRows = argv[++i];
        else if (a == "--shadows-only") config.shadowsOnly = true;
        else if (a == "--plain-maps") config.areaDefaults = false;
        else if (a == "--samples" && hasValue) samples = argv[++i];
        else if (a == "--threads" && hasValue) config.threads = static_cast<unsigned>(std::stoul(argv[++i]));
        else {
            std::fprintf(stderr, "usage: bench_soft_shadows --out FILE.json --images DIR [--smoke] [--bias-study] "
                                 "[--speed] [--error-budget [--budget-rows 'KNOB: VALUE;...']] [--shadows-only] "
                                 "[--plain-maps] [--samples N,M] [--scenes A,B] [--threads T]\n");
            return 2;
        }
    }
    if (outPath.empty() || config.images.empty()) {
        std::fprintf(stderr, "bench_soft_shadows: --out and --images are required\n");
        return 2;
    }
    if (config.smoke) {
        config.mapResolution = 32;
        config.mapSpp = 4;
        config.imageWidth = 24;
        config.imageHeight = 18;
        config.samples = {4, 16};
    }
    if (config.threads == 0) config.threads = std::max(1u, std::thread::hardware_concurrency());
    config.scenes = splitList(scenes);
    config.budgetRows = splitList(budgetRows, ';');
    if (!samples.empty()) {
        config.samples.clear();
        for (const std::string& n : splitList(samples)) config.samples.push_back(std::stoi(n));
    }
    config.workDir = std::filesystem::temp_directory_path() / ("dsm-soft-" + std::to_string(::getpid()));
    std::filesystem::create_directories(config.workDir);
    std::filesystem::create_directories(config.images);
    Json report;
    int status = 0;
    try {
        report["smoke"] = config.smoke;
        report["threads"] = config.threads;
        report["scenes"] = Json::array();
        for (std::size_t s = 0; s < config.scenes.size(); ++s) {
            std::printf("soft shadows: %s\n", config.scenes[s].c_str());
            report["scenes"].push_back(runScene(config, config.scenes[s], s < 2, s == 0));
        }
        std::ofstream out(outPath);
        out << report.dump(2) << "\n";
        if (!out) throw std::runtime_error("cannot write " + outPath);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_soft_shadows: ERROR %s\n", e.what());
        status = 1;
    }
    std::filesystem::remove_all(config.workDir);
    return status;
}
