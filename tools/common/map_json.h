// A map's description as JSON: the schema of `dsm-info --json` (documented in
// docs/dsm-info.md), shared by the tool and the Python bindings so that both
// say exactly the same thing.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/names.h"
#include "dsm/reader.h"
#include "dsm/visibility.h"

namespace dsm {

/// Version of the description schema. The minor version grows when fields are
/// added, the major one when a field changes meaning.
inline constexpr const char* kMapJsonSchemaVersion = "1.2";

/// The description of an open map's header, levels and metadata as a JSON
/// object (text, indented by `indent` spaces; -1 = one line). `file` is the
/// name recorded in the "file" field. Metadata that is JSON is embedded as
/// JSON; other metadata (or JSON nested more than 100 levels deep) as a string.
std::string mapInfoJson(const MapInfo& info, const std::string& file, int indent = 2);

/// The layer of each vertex of a function.
std::vector<std::size_t> vertexLayers(const VisibilityView& f);

/// One pixel's function as the "pixel" object of `dsm-info --pixel --json`:
/// level, x, y, channels, layers and the vertices (z, value per channel,
/// count when the map has counts, layer), the stored floats exactly.
std::string pixelFunctionJson(const VisibilityView& f, unsigned level, std::uint32_t x, std::uint32_t y,
                              int indent = -1);

/// Where a tile lies and what it holds: an element of the "tiles" array of
/// `dsm-info --tiles --json`.
struct TileRow {
    unsigned level = 0;
    std::uint32_t tx = 0, ty = 0;
    std::uint32_t x = 0, y = 0, width = 0, height = 0;  ///< the pixels the tile covers
    TileSummary summary;
};

/// The tiles of a level, row by row (reads only the tile directory).
std::vector<TileRow> levelTiles(const DeepShadowMap& map, unsigned level);

/// The rows as the "tiles" array of `dsm-info --tiles --json`.
std::string tilesJson(const std::vector<TileRow>& rows, int indent = -1);

/// Metadata nested deeper than this is kept as text: formatting JSON recurses
/// once per level, and a file may hold 16 MiB of "[[[[...".
inline constexpr std::size_t kMaxMetadataDepth = 100;

/// Deepest nesting of arrays and objects in JSON text (strings skipped; the
/// text need not be valid JSON).
std::size_t jsonNestingDepth(std::string_view text);

}  // namespace dsm
