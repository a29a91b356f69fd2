// The _dsm extension module: a thin layer over libdsm's public API. The
// Python package `dsm` (dsm/__init__.py) wraps it; everything a user calls is
// documented there and in dsm/__init__.pyi.
//
// Threads: lookups copy their input out of NumPy while holding the GIL, then
// release it and split the points into contiguous chunks, one ShadowThread
// per worker making one batched lookup of its chunk (thread states are
// per-thread by design; contiguous chunks keep the coherence a caller's point
// order has).
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "dsm/area_light.h"
#include "dsm/error.h"
#include "dsm/lookup.h"
#include "dsm/map_info.h"
#include "area_light_size.h"
#include "map_json.h"
#include "dsm/reader.h"
#include "dsm/sampler.h"
#include "dsm/scene.h"
#include "dsm/shadow_system.h"
#include "dsm/soft_shadow.h"
#include "dsm/threads.h"
#include "dsm/tile_cache.h"

namespace py = pybind11;

namespace {

dsm::LookupSpace parseSpace(const std::string& name) {
    if (name == "world") return dsm::LookupSpace::world;
    if (name == "light") return dsm::LookupSpace::light;
    if (name == "raster") return dsm::LookupSpace::raster;
    throw py::value_error("space must be 'world', 'light' or 'raster', not '" + name + "'");
}

dsm::PixelFilter parseFilter(const std::string& name) {
    if (const auto filter = dsm::pixelFilterFromName(name)) return *filter;
    throw py::value_error("filter must be 'box', 'triangle' or 'gaussian', not '" + name + "'");
}

/// "auto" -> nothing (automatic), an integer >= 0 -> itself.
std::optional<unsigned> parseLevel(const py::object& level) {
    if (py::isinstance<py::str>(level)) {
        if (level.cast<std::string>() == "auto") return std::nullopt;
        throw py::value_error("level must be 'auto' or an integer >= 0");
    }
    const long value = level.cast<long>();
    if (value < 0) throw py::value_error("level must be 'auto' or an integer >= 0");
    return static_cast<unsigned>(std::min<long>(value, 1 << 20));
}

using PointArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using Point = std::array<double, 3>;

/// The rows of an (N, 3) array, copied out while the GIL is held.
/// "auto" (unset: the automatic bias) or a number.
std::optional<double> parseBias(const py::object& bias) {
    if (py::isinstance<py::str>(bias)) {
        if (bias.cast<std::string>() == "auto") return std::nullopt;
        throw py::value_error("bias must be 'auto' or a number");
    }
    return bias.cast<double>();
}

std::vector<Point> pointRows(const PointArray& points) {
    if (points.ndim() != 2 || points.shape(1) != 3) throw py::value_error("points must be an array of shape (N, 3)");
    std::vector<Point> rows(static_cast<std::size_t>(points.shape(0)));
    const double* p = points.data();
    for (Point& row : rows) {
        row = {p[0], p[1], p[2]};
        p += 3;
    }
    return rows;
}

/// Per-point values as (N,) for one channel, (N, 3) for three.
py::array_t<double> valuesArray(const std::vector<double>& values, int channels) {
    const auto n = static_cast<py::ssize_t>(values.size() / static_cast<std::size_t>(channels));
    py::array_t<double> out = channels == 1 ? py::array_t<double>({n}) : py::array_t<double>({n, py::ssize_t{3}});
    std::copy(values.begin(), values.end(), out.mutable_data());
    return out;
}

/// Points per batched lookup. A batch visits its points tile by tile, which
/// pays more the more points share a tile, but its sort and scattered writes
/// slow down once they leave the processor's caches: two million random
/// points in one batch ran slower than point by point, in batches of 2^18
/// about 1.5x faster.
constexpr std::size_t kBatchPoints = std::size_t(1) << 18;

unsigned workerCount(int threads, std::size_t work) {
    const unsigned n = dsm::usableThreads(threads > 0 ? static_cast<unsigned>(threads) : 0u);
    // Below a few thousand points a thread costs more than it saves.
    const std::size_t useful = std::max<std::size_t>(1, work / 4096);
    return static_cast<unsigned>(std::min<std::size_t>(n, useful));
}

/// Runs body(begin, end) over [0, count) in contiguous chunks on `workers`
/// threads; rethrows the first exception.
template <class Body>
void parallelChunks(std::size_t count, unsigned workers, Body&& body) {
    if (workers <= 1) {
        body(std::size_t{0}, count);
        return;
    }
    std::vector<std::thread> pool;
    std::vector<std::exception_ptr> errors(workers);
    const std::size_t chunk = (count + workers - 1) / workers;
    for (unsigned w = 0; w < workers; ++w) {
        const std::size_t begin = std::min(count, w * chunk), end = std::min(count, begin + chunk);
        pool.emplace_back([&, w, begin, end] {
            try {
                body(begin, end);
            } catch (...) {
                errors[w] = std::current_exception();
            }
        });
    }
    for (auto& t : pool) t.join();
    for (auto& e : errors)
        if (e) std::rethrow_exception(e);
}

class Map {
public:
    /// A system of its own per map: the process-wide cache unless cache_mb
    /// asks for a private one, and the one file open for the map's lifetime.
    Map(const std::string& path, double cacheMb) {
        dsm::ShadowSystemOptions options;
        options.cache = cacheMb >= 0.0 ? dsm::TileCache::create(static_cast<std::size_t>(cacheMb * 1048576.0))
                                       : dsm::TileCache::defaultCache();
        options.maxOpenFiles = 1;
        system_ = dsm::ShadowSystem::create(options);
        handle_ = system_->open(path);
        map_ = system_->map(handle_);
    }

    const dsm::MapInfo& info() const { return map_->info(); }
    const std::string& path() const { return map_->path(); }

    py::dict camera() const {
        const dsm::LightCamera& c = info().camera;
        py::array_t<double> matrix({4, 4});
        std::copy(c.worldToLight.begin(), c.worldToLight.end(), matrix.mutable_data());
        py::dict d;
        d["projection"] = dsm::projectionName(c.projection);
        d["world_to_light"] = matrix;
        d["screen_window"] = py::make_tuple(c.screenWindow[0], c.screenWindow[1], c.screenWindow[2], c.screenWindow[3]);
        d["near_plane"] = c.nearPlane;
        return d;
    }

    py::list levels() const {
        py::list out;
        for (std::size_t l = 0; l < info().levels.size(); ++l) {
            const dsm::LevelInfo& level = info().levels[l];
            py::dict d;
            d["level"] = l;
            d["width"] = level.width;
            d["height"] = level.height;
            d["tolerance"] = level.tolerance;
            d["error_bound"] = level.errorBound;
            d["vertices"] = level.vertexCount;
            d["non_empty_pixels"] = level.nonEmptyPixels;
            d["stored_bytes"] = level.storedBytes;
            out.append(d);
        }
        return out;
    }

    std::string infoJson() const { return dsm::mapInfoJson(info(), path(), -1); }

    /// Vertices of one pixel as a structured array: z, v (mono) or r g b,
    /// count, layer.
    py::array pixel(std::uint32_t x, std::uint32_t y, unsigned level) const {
        const dsm::PixelFunction function = map_->pixel(level, x, y);
        const dsm::VisibilityView& f = function.view();
        const bool rgb = f.channels() == 3;
        py::list fields;
        fields.append(py::make_tuple("z", "<f4"));
        if (rgb) {
            for (const char* name : {"r", "g", "b"}) fields.append(py::make_tuple(name, "<f4"));
        } else {
            fields.append(py::make_tuple("v", "<f4"));
        }
        fields.append(py::make_tuple("count", "<u4"));
        fields.append(py::make_tuple("layer", "<u4"));
        const py::dtype dtype = py::dtype::from_args(fields);
        py::array out(dtype, std::vector<py::ssize_t>{static_cast<py::ssize_t>(f.size())});
        struct Mono { float z, v; std::uint32_t count, layer; };
        struct Colour { float z, r, g, b; std::uint32_t count, layer; };
        std::size_t layer = 0;
        for (std::size_t i = 0; i < f.size(); ++i) {
            while (layer + 1 < f.layerCount() && i >= f.layerEnd(layer)) ++layer;
            if (rgb) {
                auto* row = static_cast<Colour*>(out.mutable_data()) + i;
                *row = {f.z(i), f.value(i, 0), f.value(i, 1), f.value(i, 2), f.count(i), std::uint32_t(layer)};
            } else {
                auto* row = static_cast<Mono*>(out.mutable_data()) + i;
                *row = {f.z(i), f.value(i, 0), f.count(i), std::uint32_t(layer)};
            }
        }
        return out;
    }

    /// Filtered lookups of an (N, 3) array. Returns (values, bounds): values
    /// shape (N,) for a monochrome map, (N, 3) for RGB; bounds shape (N,).
    py::tuple lookup(const PointArray& points, const std::string& space, const std::string& filter, double filterWidth,
                     const py::object& level, const py::object& bias, int threads) const {
        const std::vector<Point> input = pointRows(points);
        dsm::LookupOptions options;
        options.filter = parseFilter(filter);
        options.filterWidth = filterWidth;
        options.level = parseLevel(level);
        options.bias = parseBias(bias);
        const dsm::LookupSpace where = parseSpace(space);
        const std::size_t n = input.size();
        const int channels = info().channels;
        std::vector<double> values(n * static_cast<std::size_t>(channels)), bounds(n);
        {
            py::gil_scoped_release released;
            parallelChunks(n, workerCount(threads, n), [&](std::size_t begin, std::size_t end) {
                const std::unique_ptr<dsm::ShadowThread> thread = system_->createThread();
                std::vector<dsm::LookupResult> results(std::min(end - begin, kBatchPoints));
                for (std::size_t first = begin; first < end; first += kBatchPoints) {
                    const std::size_t count = std::min(end - first, kBatchPoints);
                    const dsm::Span<const Point> batch(input.data() + first, count);
                    if (system_->lookup(*thread, handle_, where, batch, options, results) != 0) {
                        const dsm::LookupFailure& failure = thread->lastFailure();
                        throw dsm::Error(failure.code, failure.message);
                    }
                    for (std::size_t i = first; i < first + count; ++i) {
                        const dsm::LookupResult& r = results[i - first];
                        for (int c = 0; c < channels; ++c) values[i * channels + c] = r.v[c];
                        bounds[i] = r.errorBound;
                    }
                }
            });
        }
        return py::make_tuple(valuesArray(values, channels), valuesArray(bounds, 1));
    }

    /// Soft shadows of an area light at world points (N, 3): MTSM ray tracing
    /// of the map, or the PCF baseline. `light` is "disk:R" or "rect:W,H"
    /// (full sizes). Returns values shaped like lookup()'s.
    py::array_t<double> softShadow(const PointArray& points, const std::string& light, int samples, int layers,
                                   const py::object& bias, double zThreshold, std::uint64_t seed,
                                   const std::string& method, const std::optional<PointArray>& normals,
                                   int threads) const {
        const std::vector<Point> input = pointRows(points);
        const std::vector<Point> normalRows = normals ? pointRows(*normals) : std::vector<Point>{};
        if (normals && normalRows.size() != input.size())
            throw py::value_error("normals must have one row per point");
        if (method != "mtsm" && method != "pcf") throw py::value_error("method must be 'mtsm' or 'pcf'");
        const dsm::AreaLight area = parseLight(light);
        dsm::SoftShadowOptions options;
        options.samples = samples;
        if (layers != 0) options.layers = layers;  // 0: all of the map's layers
        options.bias = parseBias(bias);
        options.zThreshold = zThreshold;
        options.seed = seed;
        const bool pcf = method == "pcf";
        const std::size_t n = input.size();
        const int channels = info().channels;
        std::vector<double> values(n * static_cast<std::size_t>(channels));
        {
            py::gil_scoped_release released;
            const auto tracer = std::make_shared<const dsm::SoftShadowTracer>(map_, area);
            parallelChunks(n, workerCount(threads, n * static_cast<std::size_t>(std::max(1, samples))),
                           [&](std::size_t begin, std::size_t end) {
                dsm::SoftShadowContext context(tracer);
                dsm::SoftShadowOptions own = options;
                for (std::size_t i = begin; i < end; ++i) {
                    if (!normalRows.empty()) own.normal = normalRows[i];
                    const dsm::SoftShadowResult r =
                        pcf ? context.pcfVisibility(input[i], own) : context.visibility(input[i], own);
                    for (int c = 0; c < channels; ++c) values[i * channels + c] = r.v[c];
                }
            });
        }
        return valuesArray(values, channels);
    }

    py::dict cacheStats() const {
        const dsm::TileCacheStats s = map_->cache().stats();
        py::dict d;
        d["budget_bytes"] = s.budgetBytes;
        d["bytes_in_use"] = s.bytesInUse;
        d["peak_bytes_in_use"] = s.peakBytesInUse;
        d["hits"] = s.hits;
        d["misses"] = s.misses;
        d["tiles_read"] = s.tilesRead;
        d["bytes_read"] = s.bytesRead;
        d["evictions"] = s.evictions;
        d["duplicate_reads"] = s.duplicateReads;
        d["waits"] = s.waits;
        d["tiles_in_use"] = s.tilesInUse;
        d["peak_tiles_in_use"] = s.peakTilesInUse;
        return d;
    }

private:
    /// "disk:R" or "rect:W,H", placed where the map's build put its light.
    dsm::AreaLight parseLight(const std::string& text) const {
        dsm::AreaLightSize size;
        try {
            size = dsm::parseAreaLightSize(text);
        } catch (const dsm::Error& e) {
            throw py::value_error(e.what());
        }
        return dsm::AreaLight::forMap(info(), size);
    }

private:
    std::shared_ptr<dsm::ShadowSystem> system_;
    const dsm::MapHandle* handle_ = nullptr;
    std::shared_ptr<const dsm::DeepShadowMap> map_;
};

/// Options of dsm-build from keyword arguments (names as the long options,
/// with underscores). Unknown names are an error, not silently ignored.
dsm::BuildOptions buildOptions(const py::dict& kwargs) {
    dsm::BuildOptions o;
    for (const auto& item : kwargs) {
        const std::string key = item.first.cast<std::string>();
        const py::handle value = item.second;
        if (key == "resolution") {
            if (py::isinstance<py::int_>(value)) {
                o.width = o.height = value.cast<std::uint32_t>();
            } else {
                const auto wh = value.cast<std::array<std::uint32_t, 2>>();
                o.width = wh[0];
                o.height = wh[1];
            }
        } else if (key == "spp") o.samplesPerPixel = value.cast<std::uint32_t>();
        else if (key == "tolerance") {
            if (!py::isinstance<py::str>(value)) o.tolerance = value.cast<double>();  // a string: "auto"
        }
        else if (key == "filter") {
            if (value.cast<std::string>() != "auto") o.filter = parseFilter(value.cast<std::string>());
        }
        else if (key == "filter_width") {
            if (!py::isinstance<py::str>(value)) o.filterWidth = value.cast<double>();  // a string: "auto"
        }
        else if (key == "mip_levels") {
            // "auto" or 0: the full pyramid.
            if (!py::isinstance<py::str>(value) && value.cast<unsigned>() != 0) o.mipLevels = value.cast<unsigned>();
        }
        else if (key == "tile_size") o.tileSize = value.cast<std::uint32_t>();
        else if (key == "mtsm_layers") {
            if (!py::isinstance<py::str>(value)) o.mtsmLayers = value.cast<int>();  // a string: "auto"
        }
        else if (key == "counts") o.counts = value.cast<bool>();
        else if (key == "centred_compression") o.centredCompression = value.cast<bool>();
        else if (key == "region") o.region = value.cast<std::array<std::uint32_t, 4>>();
        else if (key == "threads") {
            if (value.cast<unsigned>() != 0) o.threads = value.cast<unsigned>();  // 0: all cores
        }
        else if (key == "seed") o.seed = value.cast<std::uint64_t>();
        else if (key == "zlib_level") o.zlibLevel = value.cast<int>();
        else throw py::type_error("build() got an unexpected option '" + key + "'");
    }
    return o;
}

py::dict build(const std::string& sceneText, const std::string& baseDirectory, const std::string& sceneName,
               const std::string& outPath, const py::dict& kwargs) {
    const dsm::BuildOptions options = buildOptions(kwargs);
    dsm::BuildStats s;
    {
        py::gil_scoped_release released;
        const dsm::Scene scene = dsm::parseScene(sceneText, baseDirectory, sceneName);
        s = dsm::buildMap(scene, options, outPath);
    }
    py::dict d;
    d["output"] = outPath;
    d["wall_seconds"] = s.wallSeconds;
    d["sampling_seconds"] = s.samplingSeconds;
    d["crossing_seconds"] = s.crossingSeconds;
    d["sweep_seconds"] = s.sweepSeconds;
    d["compression_seconds"] = s.compressionSeconds;
    d["writing_seconds"] = s.writingSeconds;
    d["samples"] = s.samples;
    d["pixels"] = s.pixels;
    d["vertices"] = s.vertices;
    d["max_vertices_per_pixel"] = s.maxVerticesPerPixel;
    d["tolerance"] = s.tolerance;
    d["file_bytes"] = s.fileBytes;
    d["raw_bytes"] = s.rawBytes;
    return d;
}

}  // namespace

PYBIND11_MODULE(_dsm, m) {
    m.doc() = "libdsm's extension module; use the dsm package.";
    py::register_exception<dsm::Error>(m, "Error", PyExc_RuntimeError);

    py::class_<Map>(m, "Map")
        .def(py::init<const std::string&, double>(), py::arg("path"), py::arg("cache_mb") = -1.0)
        .def_property_readonly("path", &Map::path)
        .def_property_readonly("width", [](const Map& map) { return map.info().width; })
        .def_property_readonly("height", [](const Map& map) { return map.info().height; })
        .def_property_readonly("channels", [](const Map& map) { return map.info().channels; })
        .def_property_readonly("tile_size", [](const Map& map) { return map.info().tileSize; })
        .def_property_readonly("has_counts", [](const Map& map) { return map.info().hasCounts; })
        .def_property_readonly("max_layers", [](const Map& map) { return map.info().maxLayers; })
        .def_property_readonly("file_bytes", [](const Map& map) { return map.info().fileBytes; })
        .def_property_readonly("metadata_text", [](const Map& map) { return map.info().metadata; })
        .def_property_readonly("camera", &Map::camera)
        .def_property_readonly("levels", &Map::levels)
        .def("info_json", &Map::infoJson)
        .def("pixel", &Map::pixel, py::arg("x"), py::arg("y"), py::arg("level") = 0)
        .def("lookup", &Map::lookup, py::arg("points"), py::arg("space"), py::arg("filter"), py::arg("filter_width"),
             py::arg("level"), py::arg("bias"), py::arg("threads"))
        .def("soft_shadow", &Map::softShadow, py::arg("points"), py::arg("light"), py::arg("samples"),
             py::arg("layers"), py::arg("bias"), py::arg("z_threshold"), py::arg("seed"), py::arg("method"),
             py::arg("normals"), py::arg("threads"))
        .def("cache_stats", &Map::cacheStats);

    m.def("build", &build, py::arg("scene_text"), py::arg("base_directory"), py::arg("scene_name"),
          py::arg("out_path"), py::arg("options"));
    m.def("validate", [](const std::string& path) {
        py::gil_scoped_release released;
        dsm::validate(path);
    });
}
