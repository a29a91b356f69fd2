#include "dsm/map_json.h"

#include <algorithm>
#include <cstddef>
#include <string_view>

#include <nlohmann/json.hpp>

DSM_NAMESPACE_BEGIN

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

const char* projectionName(Projection projection) {
    switch (projection) {
        case Projection::Perspective: return "perspective";
        case Projection::Orthographic: return "orthographic";
    }
    return "unknown";
}

const char* filterName(PixelFilter filter) {
    switch (filter) {
        case PixelFilter::Box: return "box";
        case PixelFilter::Triangle: return "triangle";
        case PixelFilter::Gaussian: return "gaussian";
    }
    return "unknown";
}

std::optional<PixelFilter> pixelFilterFromName(std::string_view name) {
    for (const PixelFilter f : {PixelFilter::Box, PixelFilter::Triangle, PixelFilter::Gaussian})
        if (name == filterName(f)) return f;
    return std::nullopt;
}

std::string mapInfoJson(const MapInfo& info, const std::string& file, int indent) {
    Json j;
    j["schema_version"] = kMapJsonSchemaVersion;
    j["file"] = file;
    j["file_bytes"] = info.fileBytes;
    j["format_version"] = std::to_string(info.versionMajor) + "." + std::to_string(info.versionMinor);
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
                          {"error_bound", level.errorBound},
                          {"vertices", level.vertexCount},
                          {"non_empty_pixels", level.nonEmptyPixels},
                          {"stored_bytes", level.storedBytes}});
    }
    j["levels"] = std::move(levels);
    j["metadata"] = metadataJson(info.metadata);
    return j.dump(indent, ' ', false, Json::error_handler_t::replace);
}

DSM_NAMESPACE_END
