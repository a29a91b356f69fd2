#include "map_json.h"

#include <algorithm>
#include <cstddef>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "dsm/names.h"

namespace dsm {

namespace {

using Json = nlohmann::ordered_json;

Json metadataJson(const std::string& text) {
    if (jsonNestingDepth(text) <= kMaxMetadataDepth) {
        Json parsed = Json::parse(text, nullptr, /*allow_exceptions=*/false);
        if (!parsed.is_discarded()) return parsed;
    }
    return Json(text);
}

}  // namespace

std::size_t jsonNestingDepth(std::string_view text) {
    std::size_t depth = 0, deepest = 0;
    bool inString = false, escaped = false;
    for (const char c : text) {
        if (inString) {
            if (escaped) escaped = false;
            else if (c == '\\') escaped = true;
            else if (c == '"') inString = false;
        } else if (c == '"') {
            inString = true;
        } else if (c == '[' || c == '{') {
            deepest = std::max(deepest, ++depth);
        } else if ((c == ']' || c == '}') && depth > 0) {
            --depth;
        }
    }
    return deepest;
}

std::string mapInfoJson(const MapInfo& info, const std::string& file, int indent) {
    Json j;
    j["schema_version"] = kMapJsonSchemaVersion;
    j["file"] = file;
    j["file_bytes"] = info.fileBytes;
    j["format_version"] = std::to_string(info.versionMajor) + "." + std::to_string(info.versionMinor);
    j["required_flags"] = requiredFlagNames(info);
    j["tile_coding"] = {{"coded", info.codedTiles},
                        {"codec", info.codec == dsm::TileCodec::Zstd ? "zstd" : "zlib"},
                        {"level", info.codecLevel >= 0 ? Json(info.codecLevel) : Json(nullptr)}};
    j["area_light"] = {{"radius", info.areaLightRadius}, {"plane_depth", info.areaLightPlaneDepth}};
    j["width"] = info.width;
    j["height"] = info.height;
    j["tile_size"] = info.tileSize;
    j["channels"] = info.channels;
    j["has_counts"] = info.hasCounts;
    j["max_layers"] = info.maxLayers;
    j["camera"] = {{"projection", projectionName(info.camera.projection)},
                   {"world_to_light", info.camera.worldToLight},
                   {"screen_window", info.camera.screenWindow},
                   {"near_plane", info.camera.nearPlane}};
    j["filter"] = {{"type", filterName(info.filter)}, {"width", info.filterWidth}};
    Json levels = Json::array();
    for (std::size_t l = 0; l < info.levels.size(); ++l) {
        const LevelInfo& level = info.levels[l];
        levels.push_back({{"level", l},
                          {"width", level.width},
                          {"height", level.height},
                          {"tiles_x", level.tilesX},
                          {"tiles_y", level.tilesY},
                          {"tolerance", level.tolerance},
                          {"value_step", level.valueStep},
                          {"error_bound", level.errorBound},
                          {"vertices", level.vertexCount},
                          {"non_empty_pixels", level.nonEmptyPixels},
                          {"stored_bytes", level.storedBytes}});
    }
    j["levels"] = std::move(levels);
    j["metadata"] = metadataJson(info.metadata);
    return j.dump(indent, ' ', false, Json::error_handler_t::replace);
}

std::vector<std::size_t> vertexLayers(const VisibilityView& f) {
    std::vector<std::size_t> layers(f.size(), 0);
    for (std::size_t layer = 0; layer < f.layerCount(); ++layer)
        for (std::size_t i = f.layerBegin(layer); i < f.layerEnd(layer); ++i) layers[i] = layer;
    return layers;
}

std::string pixelFunctionJson(const VisibilityView& f, unsigned level, std::uint32_t x, std::uint32_t y,
                              int indent) {
    const std::vector<std::size_t> layers = vertexLayers(f);
    Json vertices = Json::array();
    for (std::size_t i = 0; i < f.size(); ++i) {
        Json value = Json::array();
        for (int c = 0; c < f.channels(); ++c) value.push_back(f.value(i, c));
        Json vertex{{"z", f.z(i)}, {"value", std::move(value)}};
        if (f.hasCounts()) vertex["count"] = f.count(i);
        vertex["layer"] = layers[i];
        vertices.push_back(std::move(vertex));
    }
    const Json j{{"level", level},           {"x", x},
                 {"y", y},                   {"channels", f.channels()},
                 {"layers", f.layerCount()}, {"vertices", std::move(vertices)}};
    return j.dump(indent, ' ', false, Json::error_handler_t::replace);
}

std::vector<TileRow> levelTiles(const DeepShadowMap& map, unsigned level) {
    std::vector<TileRow> rows;
    const std::uint32_t size = map.info().tileSize;
    const LevelInfo& L = map.info().levels.at(level);
    for (std::uint32_t ty = 0; ty < L.tilesY; ++ty)
        for (std::uint32_t tx = 0; tx < L.tilesX; ++tx) {
            const std::uint32_t x = tx * size, y = ty * size;
            rows.push_back({level, tx, ty, x, y, std::min(size, L.width - x), std::min(size, L.height - y),
                            map.tile(level, tx, ty)});
        }
    return rows;
}

std::string tilesJson(const std::vector<TileRow>& rows, int indent) {
    Json tiles = Json::array();
    for (const TileRow& t : rows)
        tiles.push_back({{"level", t.level},
                         {"tx", t.tx},
                         {"ty", t.ty},
                         {"x", t.x},
                         {"y", t.y},
                         {"width", t.width},
                         {"height", t.height},
                         {"stored_bytes", t.summary.storedBytes},
                         {"raw_bytes", t.summary.rawBytes},
                         {"vertices", t.summary.vertexCount},
                         {"non_empty_pixels", t.summary.nonEmptyPixels},
                         {"min_z", t.summary.minZ},
                         {"max_z", t.summary.maxZ},
                         {"crc32", t.summary.crc32}});
    return tiles.dump(indent, ' ', false, Json::error_handler_t::replace);
}

}  // namespace dsm
