// Caches, opening maps (path, memory, callbacks), their information and single
// pixels, through the C API.
#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

#include "c_api.h"

using dsm::c::fail;
using dsm::c::failNaming;
using dsm::c::guarded;
using dsm::c::missing;

namespace {

// The caller's read callbacks as a MapInput; calls `release` when the map lets go.
class CallbackInput final : public dsm::MapInput {
public:
    explicit CallbackInput(const dsm_read_callbacks& callbacks) : callbacks_(callbacks) {}
    ~CallbackInput() override {
        if (callbacks_.release) callbacks_.release(callbacks_.user);
    }
    CallbackInput(const CallbackInput&) = delete;
    CallbackInput& operator=(const CallbackInput&) = delete;

    std::uint64_t size() const override { return callbacks_.total_bytes; }

    std::size_t read(std::uint64_t offset, void* out, std::size_t count) const override {
        // Keep each request within what int64_t reports.
        count = std::min<std::size_t>(count, std::size_t(std::numeric_limits<std::int64_t>::max()));
        const std::int64_t n = callbacks_.read(callbacks_.user, offset, out, count);
        if (n < 0 || static_cast<std::uint64_t>(n) > count) throw std::runtime_error("the read callback failed");
        return static_cast<std::size_t>(n);
    }

private:
    dsm_read_callbacks callbacks_;
};

dsm_result readerOptions(const dsm_open_options* given, dsm::ReaderOptions& options, const char* function) {
    dsm_open_options o = DSM_OPEN_OPTIONS_INIT;
    if (const dsm_result r = dsm::c::readVersioned(given, o, function); r != DSM_OK) return r;
    if (o.cache) options.cache = o.cache->cache;
    if (o.max_width) options.maxWidth = o.max_width;
    if (o.max_height) options.maxHeight = o.max_height;
    if (o.max_vertices_per_pixel) options.maxVerticesPerPixel = o.max_vertices_per_pixel;
    if (o.max_tile_bytes) options.maxTileBytes = o.max_tile_bytes;
    if (o.max_metadata_bytes) options.maxMetadataBytes = o.max_metadata_bytes;
    return DSM_OK;
}

dsm_result openInput(const std::shared_ptr<const dsm::MapInput>& input, const char* name, const char* defaultName,
                     const dsm_open_options* options, dsm_map** map, const char* function) {
    dsm::ReaderOptions reader;
    if (const dsm_result r = readerOptions(options, reader, function); r != DSM_OK) return r;
    auto handle = std::make_unique<dsm_map>();
    handle->map = dsm::DeepShadowMap::open(input, name ? name : defaultName, reader);
    *map = handle.release();
    return DSM_OK;
}

}  // namespace

extern "C" {

dsm_result dsm_cache_create(uint64_t budget_bytes, dsm_cache** cache) {
    return guarded([&] {
        if (!cache) return missing("dsm_cache_create", "cache");
        if (budget_bytes > std::numeric_limits<std::size_t>::max())
            return fail(DSM_ERROR_ARGUMENT, "dsm_cache_create", "the budget does not fit in memory");
        auto handle = std::make_unique<dsm_cache>();
        handle->cache = dsm::TileCache::create(static_cast<std::size_t>(budget_bytes));
        *cache = handle.release();
        return DSM_OK;
    });
}

void dsm_cache_destroy(dsm_cache* cache) { delete cache; }

dsm_result dsm_cache_bytes_in_use(const dsm_cache* cache, uint64_t* bytes) {
    return guarded([&] {
        if (!cache) return missing("dsm_cache_bytes_in_use", "cache");
        if (!bytes) return missing("dsm_cache_bytes_in_use", "bytes");
        *bytes = cache->cache->stats().bytesInUse;
        return DSM_OK;
    });
}

dsm_result dsm_map_open(const char* path, const dsm_open_options* options, dsm_map** map) {
    return guarded([&] {
        if (!path) return missing("dsm_map_open", "path");
        if (!map) return missing("dsm_map_open", "map");
        dsm::ReaderOptions reader;
        if (const dsm_result r = readerOptions(options, reader, "dsm_map_open"); r != DSM_OK) return r;
        auto handle = std::make_unique<dsm_map>();
        handle->map = dsm::DeepShadowMap::open(std::string(path), reader);
        *map = handle.release();
        return DSM_OK;
    });
}

dsm_result dsm_map_open_memory(const void* data, size_t size, const char* name, const dsm_open_options* options,
                               dsm_map** map) {
    return guarded([&] {
        if (!data) return missing("dsm_map_open_memory", "data");
        if (!map) return missing("dsm_map_open_memory", "map");
        return openInput(dsm::MapInput::memory(data, size), name, "<memory>", options, map, "dsm_map_open_memory");
    });
}

dsm_result dsm_map_open_callbacks(const dsm_read_callbacks* callbacks, const char* name,
                                  const dsm_open_options* options, dsm_map** map) {
    // The input owns `release` from here on: it runs when the map closes or the open fails.
    std::shared_ptr<const dsm::MapInput> input;
    const dsm_result made = guarded([&] {
        if (!callbacks) return missing("dsm_map_open_callbacks", "callbacks");
        dsm_read_callbacks given = DSM_READ_CALLBACKS_INIT;
        if (const dsm_result r = dsm::c::readVersioned(callbacks, given, "dsm_map_open_callbacks"); r != DSM_OK) {
            if (callbacks->size >= sizeof(dsm_read_callbacks) && callbacks->release)
                callbacks->release(callbacks->user);
            return r;
        }
        input = std::make_shared<CallbackInput>(given);
        if (!given.read) return missing("dsm_map_open_callbacks", "callbacks->read");
        if (!map) return missing("dsm_map_open_callbacks", "map");
        return DSM_OK;
    });
    if (made != DSM_OK) return made;
    return guarded([&] { return openInput(input, name, "<callbacks>", options, map, "dsm_map_open_callbacks"); });
}

void dsm_map_close(dsm_map* map) { delete map; }

dsm_result dsm_map_get_info(const dsm_map* map, dsm_map_info* info) {
    return guarded([&] {
        if (!map) return missing("dsm_map_get_info", "map");
        return dsm::c::mapInfo(*map->map, info, "dsm_map_get_info");
    });
}

dsm_result dsm_map_get_level(const dsm_map* map, uint32_t level, dsm_level_info* info) {
    return guarded([&] {
        if (!map) return missing("dsm_map_get_level", "map");
        if (!info) return missing("dsm_map_get_level", "info");
        const dsm::MapInfo& m = map->map->info();
        if (level >= m.levels.size())
            return failNaming(DSM_ERROR_ARGUMENT,
                              ("'" + map->map->path() + "': level " + std::to_string(level) + " does not exist (" +
                               std::to_string(m.levels.size()) + " levels)")
                                  .c_str(),
                              map->map->path().c_str());
        const dsm::LevelInfo& L = m.levels[level];
        *info = dsm_level_info{L.width,      L.height,      L.tilesX,         L.tilesY,     L.tolerance,
                               L.errorBound, L.vertexCount, L.nonEmptyPixels, L.storedBytes};
        return DSM_OK;
    });
}

dsm_result dsm_map_get_metadata(const dsm_map* map, const char** json, size_t* length) {
    return guarded([&] {
        if (!map) return missing("dsm_map_get_metadata", "map");
        if (!json) return missing("dsm_map_get_metadata", "json");
        const std::string& metadata = map->map->info().metadata;
        *json = metadata.c_str();
        if (length) *length = metadata.size();
        return DSM_OK;
    });
}

dsm_result dsm_map_get_pixel(const dsm_map* map, uint32_t level, uint32_t x, uint32_t y, dsm_pixel** pixel) {
    return guarded([&] {
        if (!map) return missing("dsm_map_get_pixel", "map");
        if (!pixel) return missing("dsm_map_get_pixel", "pixel");
        auto handle = std::make_unique<dsm_pixel>();
        handle->function = map->map->pixel(level, x, y);
        *pixel = handle.release();
        return DSM_OK;
    });
}

dsm_result dsm_pixel_get_function(const dsm_pixel* pixel, dsm_pixel_function* function) {
    return guarded([&] {
        if (!pixel) return missing("dsm_pixel_get_function", "pixel");
        if (!function) return missing("dsm_pixel_get_function", "function");
        const dsm::VisibilityView& view = pixel->function.view();
        dsm_pixel_function full = DSM_PIXEL_FUNCTION_INIT;
        full.channels = view.channels();
        full.vertex_count = static_cast<uint32_t>(view.size());
        full.z = view.depths().data();
        full.v = view.allValues().data();
        full.counts = view.hasCounts() ? view.counts().data() : nullptr;
        full.layer_count = static_cast<uint32_t>(view.layerCount());
        full.layer_starts = view.layerStarts().empty() ? nullptr : view.layerStarts().data();
        return dsm::c::writeVersioned(full, function, "dsm_pixel_get_function");
    });
}

dsm_result dsm_pixel_evaluate(const dsm_pixel* pixel, double z, double* visibility) {
    return guarded([&] {
        if (!pixel) return missing("dsm_pixel_evaluate", "pixel");
        if (!visibility) return missing("dsm_pixel_evaluate", "visibility");
        const dsm::VisibilityView& view = pixel->function.view();
        double v[3] = {1.0, 1.0, 1.0};
        view.evaluate(z, v);
        if (view.channels() == 1) v[1] = v[2] = v[0];
        std::copy(v, v + 3, visibility);
        return DSM_OK;
    });
}

void dsm_pixel_release(dsm_pixel* pixel) { delete pixel; }

}  // extern "C"

namespace dsm::c {

dsm_result mapInfo(const DeepShadowMap& map, dsm_map_info* info, const char* function) noexcept {
    if (!info) return missing(function, "info");
        const dsm::MapInfo& m = map.info();
        dsm_map_info full{};
        full.size = sizeof(dsm_map_info);
        full.width = m.width;
        full.height = m.height;
        full.tile_size = m.tileSize;
        full.channels = m.channels;
        full.has_counts = m.hasCounts ? 1 : 0;
        full.max_layers = m.maxLayers;
        full.level_count = static_cast<uint32_t>(m.levels.size());
        full.projection = static_cast<int32_t>(m.camera.projection);
        std::copy(m.camera.worldToLight.begin(), m.camera.worldToLight.end(), full.world_to_light);
        std::copy(m.camera.screenWindow.begin(), m.camera.screenWindow.end(), full.screen_window);
        full.near_plane = m.camera.nearPlane;
        full.filter = static_cast<int32_t>(m.filter);
        full.filter_width = m.filterWidth;
        full.error_bound = m.levels.empty() ? 0.0 : m.levels[0].errorBound;
        full.file_bytes = m.fileBytes;
        full.version_major = m.versionMajor;
        full.version_minor = m.versionMinor;
    return writeVersioned(full, info, function);
}

}  // namespace dsm::c
