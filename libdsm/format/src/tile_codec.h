// Tiles on disk <-> tiles in memory (internal). Layout: spec/dsm-format.md,
// "Tile data".
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "dsm/reader.h"
#include "dsm/visibility.h"

namespace dsm::format {

/// A decoded tile: every pixel's arrays concatenated, with per-pixel starts.
struct DecodedTile {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    std::vector<std::uint32_t> vertexStart;  // pixels + 1, into z and counts
    std::vector<std::uint32_t> valueStart;   // pixels + 1, into v
    std::vector<std::uint32_t> layerStart;   // pixels + 1, into layerStarts
    std::vector<std::uint8_t> channels;      // per pixel, 1 or 3
    std::vector<float> z;
    std::vector<float> v;
    std::vector<std::uint32_t> counts;       // empty without counts
    std::vector<std::uint32_t> layerStarts;  // pixel-relative first vertex of layers 1, 2, ...

    std::size_t pixelCount() const { return static_cast<std::size_t>(width) * height; }
    VisibilityView pixel(std::size_t index) const;
    std::size_t memoryBytes() const;
};

/// What the layout of a tile depends on.
struct TileLayout {
    int fileChannels = 1;
    bool hasCounts = false;
    int maxLayers = 1;
};

struct EncodedTile {
    std::vector<std::uint8_t> stored;  // empty for an empty tile
    TileSummary summary;              // offset left 0
};

/// Serialises `pixels` (width * height, row order, already valid) and
/// compresses with zlib at `zlibLevel` when that makes the tile smaller.
EncodedTile encodeTile(std::span<const VisibilityFunction> pixels, const TileLayout& layout, int zlibLevel);

/// Checks the CRC of `stored`, inflates it, parses and checks the layout and
/// every function. Throws dsm::Error prefixed with `where` (file, level, tile),
/// naming the pixel (in level coordinates, from the tile's origin) at fault.
DecodedTile decodeTile(std::span<const std::uint8_t> stored, const TileSummary& summary, std::uint32_t width,
                       std::uint32_t height, const TileLayout& layout, const ReaderOptions& limits,
                       const std::string& where, std::uint32_t originX, std::uint32_t originY);

}  // namespace dsm::format
