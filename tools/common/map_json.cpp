#include "map_json.h"

#include <algorithm>
#include <cstddef>
#include <string_view>

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
    j["tile_coding"] = {{"coded", info.codedTiles},
                        {"codec", "zlib"},
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

}  // namespace dsm
