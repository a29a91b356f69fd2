// Writing maps pixel by pixel through the C API: pixels are gathered per
// level-0 tile and each tile goes to MapWriter as soon as it is complete.
#include <algorithm>
#include <string>
#include <vector>

#include "dsm/build_visibility.h"
#include "dsm/writer.h"
#include "c_api.h"

using dsm::c::fail;
using dsm::c::failNaming;
using dsm::c::guarded;
using dsm::c::missing;

struct dsm_writer {
    struct PendingTile {
        std::vector<dsm::VisibilityFunction> pixels;  // empty until the first pixel arrives
        std::vector<bool> set;
        std::size_t setCount = 0;
        bool written = false;
    };
    std::string path;
    dsm::WriterOptions options;
    std::unique_ptr<dsm::MapWriter> writer;
    std::vector<PendingTile> tiles;
    bool done = false;
};

namespace {

std::string pixelWhere(const dsm_writer& w, uint32_t x, uint32_t y) {
    return "'" + w.path + "' pixel " + std::to_string(x) + "," + std::to_string(y);
}

void writeTile(dsm_writer& w, std::uint32_t tx, std::uint32_t ty) {
    dsm_writer::PendingTile& tile = w.tiles[std::size_t(ty) * w.writer->tilesX() + tx];
    if (tile.pixels.empty())
        tile.pixels.assign(std::size_t(w.writer->tileWidth(tx)) * w.writer->tileHeight(ty),
                           dsm::VisibilityFunction(w.options.channels, w.options.counts));
    w.writer->writeTile(tx, ty, tile.pixels);
    tile = dsm_writer::PendingTile{};
    tile.written = true;
}

// Puts a finished function into its tile, and writes the tile once it is full.
dsm_result setPixel(dsm_writer& w, uint32_t x, uint32_t y, dsm::VisibilityFunction&& function) {
    const std::uint32_t size = w.options.tileSize;
    const std::uint32_t tx = x / size, ty = y / size;
    dsm_writer::PendingTile& tile = w.tiles[std::size_t(ty) * w.writer->tilesX() + tx];
    const std::uint32_t width = w.writer->tileWidth(tx);
    const std::size_t index = std::size_t(y - ty * size) * width + (x - tx * size);
    if (tile.written || (!tile.set.empty() && tile.set[index]))
        return fail(DSM_ERROR_ARGUMENT, (pixelWhere(w, x, y) + ": set twice").c_str());
    if (tile.pixels.empty()) {
        const std::size_t count = std::size_t(width) * w.writer->tileHeight(ty);
        tile.pixels.assign(count, dsm::VisibilityFunction(w.options.channels, w.options.counts));
        tile.set.assign(count, false);
    }
    tile.pixels[index] = std::move(function);
    tile.set[index] = true;
    if (++tile.setCount == tile.pixels.size()) writeTile(w, tx, ty);
    return DSM_OK;
}

// The writer is usable and (x, y) is inside the map; a failure result otherwise.
dsm_result checkPixel(const dsm_writer* w, uint32_t x, uint32_t y, const char* function) {
    if (!w) return missing(function, "writer");
    if (w->done) return fail(DSM_ERROR_ARGUMENT, function, ("'" + w->path + "': the writer is finished").c_str());
    if (x >= w->options.width || y >= w->options.height)
        return failNaming(DSM_ERROR_ARGUMENT,
                          (pixelWhere(*w, x, y) + ": outside the " + std::to_string(w->options.width) + "x" +
                           std::to_string(w->options.height) + " map")
                              .c_str(),
                          w->path.c_str());
    return DSM_OK;
}

}  // namespace

extern "C" {

dsm_result dsm_writer_open(const char* path, const dsm_write_options* options, dsm_writer** writer) {
    return guarded([&] {
        if (!path) return missing("dsm_writer_open", "path");
        if (!options) return missing("dsm_writer_open", "options");
        if (!writer) return missing("dsm_writer_open", "writer");
        dsm_write_options o = DSM_WRITE_OPTIONS_INIT;
        if (const dsm_result r = dsm::c::readVersioned(options, o, "dsm_writer_open"); r != DSM_OK) return r;
        if (o.projection != DSM_PROJECTION_PERSPECTIVE && o.projection != DSM_PROJECTION_ORTHOGRAPHIC)
            return fail(DSM_ERROR_ARGUMENT, "dsm_writer_open", "projection is not perspective or orthographic");
        if (o.filter < DSM_FILTER_BOX || o.filter > DSM_FILTER_GAUSSIAN)
            return fail(DSM_ERROR_ARGUMENT, "dsm_writer_open", "filter is not box, triangle or gaussian");
        auto handle = std::make_unique<dsm_writer>();
        handle->path = path;
        dsm::WriterOptions& w = handle->options;
        w.width = o.width;
        w.height = o.height;
        w.tileSize = o.tile_size;
        w.channels = o.channels;
        w.counts = o.counts != 0;
        w.maxLayers = o.max_layers;
        w.camera.projection = static_cast<dsm::Projection>(o.projection);
        std::copy(o.world_to_light, o.world_to_light + 16, w.camera.worldToLight.begin());
        std::copy(o.screen_window, o.screen_window + 4, w.camera.screenWindow.begin());
        w.camera.nearPlane = o.near_plane;
        w.filter = static_cast<dsm::PixelFilter>(o.filter);
        w.filterWidth = o.filter_width;
        w.tolerance = o.tolerance;
        if (o.mip_levels != 0) w.mipLevels = o.mip_levels;  // 0: a full pyramid
        w.levelToleranceFactor = o.level_tolerance_factor;
        w.centredCompression = o.centred_compression != 0;
        w.zlibLevel = o.zlib_level;
        w.metadata = o.metadata ? o.metadata : "{}";
        handle->writer = std::make_unique<dsm::MapWriter>(handle->path, w);
        handle->tiles.resize(std::size_t(handle->writer->tilesX()) * handle->writer->tilesY());
        *writer = handle.release();
        return DSM_OK;
    });
}

dsm_result dsm_writer_set_pixel_function(dsm_writer* writer, uint32_t x, uint32_t y,
                                         const dsm_pixel_function* function) {
    return guarded([&] {
        if (const dsm_result r = checkPixel(writer, x, y, "dsm_writer_set_pixel_function"); r != DSM_OK) return r;
        if (!function) return missing("dsm_writer_set_pixel_function", "function");
        dsm_pixel_function f = DSM_PIXEL_FUNCTION_INIT;
        if (const dsm_result r = dsm::c::readVersioned(function, f, "dsm_writer_set_pixel_function"); r != DSM_OK)
            return r;
        const std::string where = pixelWhere(*writer, x, y);
        if (f.channels != 1 && f.channels != 3)
            return fail(DSM_ERROR_ARGUMENT, where.c_str(), "channels is not 1 or 3");
        if (f.vertex_count > 0 && (!f.z || !f.v)) return fail(DSM_ERROR_ARGUMENT, where.c_str(), "z or v is NULL");
        if (f.layer_count < 1 || (f.layer_count > 1 && !f.layer_starts))
            return fail(DSM_ERROR_ARGUMENT, where.c_str(), "layer_count is 0, or layer_starts is NULL");
        dsm::VisibilityFunction out(f.channels, f.counts != nullptr);
        out.reserve(f.vertex_count);
        std::uint32_t layer = 1;
        for (std::uint32_t i = 0; i < f.vertex_count; ++i) {
            while (layer < f.layer_count && f.layer_starts[layer - 1] == i) {
                out.beginLayer();
                ++layer;
            }
            out.append(f.z[i], f.v + std::size_t(i) * std::size_t(f.channels), f.counts ? f.counts[i] : 0u);
        }
        if (layer != f.layer_count)
            return fail(DSM_ERROR_ARGUMENT, where.c_str(), "layer_starts are not increasing vertex indices");
        try {
            out.validate();
        } catch (const dsm::Error& e) {
            return fail(e.code(), where.c_str(), e.what());
        }
        return setPixel(*writer, x, y, std::move(out));
    });
}

dsm_result dsm_writer_set_pixel_samples(dsm_writer* writer, uint32_t x, uint32_t y, const dsm_sample_ray* rays,
                                        size_t ray_count) {
    return guarded([&] {
        if (const dsm_result r = checkPixel(writer, x, y, "dsm_writer_set_pixel_samples"); r != DSM_OK) return r;
        if (ray_count > 0 && !rays) return missing("dsm_writer_set_pixel_samples", "rays");
        const std::string where = pixelWhere(*writer, x, y);
        std::vector<std::vector<dsm::SurfaceHit>> hits(ray_count);
        std::vector<dsm::SampleRay> sampleRays(ray_count);
        std::vector<double> weights(ray_count);
        for (std::size_t k = 0; k < ray_count; ++k) {
            if (rays[k].hit_count > 0 && !rays[k].hits)
                return fail(DSM_ERROR_ARGUMENT, where.c_str(), ("ray " + std::to_string(k) + ": hits is NULL").c_str());
            hits[k].resize(rays[k].hit_count);
            for (std::size_t h = 0; h < rays[k].hit_count; ++h) {
                hits[k][h].z = rays[k].hits[h].z;
                for (std::size_t c = 0; c < 3; ++c) hits[k][h].opacity[c] = rays[k].hits[h].opacity[c];
            }
            sampleRays[k].hits = hits[k];
            weights[k] = rays[k].weight;
        }
        dsm::CompressorOptions compression;
        compression.tolerance = writer->options.tolerance;
        compression.channels = writer->options.channels;
        compression.keepCounts = writer->options.counts;
        compression.maxLayers = writer->options.maxLayers;
        compression.centred = writer->options.centredCompression;
        dsm::VisibilityFunction function;
        try {
            function = dsm::buildVisibility(sampleRays, weights, compression);
        } catch (const dsm::Error& e) {
            return fail(e.code(), where.c_str(), e.what());
        }
        return setPixel(*writer, x, y, std::move(function));
    });
}

dsm_result dsm_writer_finish(dsm_writer* writer) {
    return guarded([&] {
        if (!writer) return missing("dsm_writer_finish", "writer");
        if (writer->done)
            return fail(DSM_ERROR_ARGUMENT, "dsm_writer_finish", ("'" + writer->path + "': already finished").c_str());
        writer->done = true;  // a failure below leaves nothing to retry: the temporary file is gone with the writer
        for (std::uint32_t ty = 0; ty < writer->writer->tilesY(); ++ty)
            for (std::uint32_t tx = 0; tx < writer->writer->tilesX(); ++tx)
                if (!writer->tiles[std::size_t(ty) * writer->writer->tilesX() + tx].written) writeTile(*writer, tx, ty);
        writer->writer->finish();
        return DSM_OK;
    });
}

void dsm_writer_destroy(dsm_writer* writer) {
    try {
        delete writer;  // MapWriter's destructor removes an unfinished temporary file
    } catch (...) {
    }
}

}  // extern "C"
