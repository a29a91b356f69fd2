// Tiles on disk <-> tiles in memory (internal). Layout: spec/dsm-format.md,
// "Tile data".
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "dsm/reader.h"
#include "dsm/visibility.h"

namespace dsm::format {

/// Where one pixel's arrays start in a DecodedTile; pixel p spans
/// [records[p], records[p + 1]) of each array.
struct PixelRecord {
    std::uint32_t vertexStart;  ///< into depths() and counts()
    std::uint32_t valueStart;   ///< into values()
    std::uint32_t layerStart;   ///< into layerStarts()
    std::uint32_t channels;     ///< 1 or 3 (the pixel's own; an RGB map may hold mono pixels)
};

/// A decoded tile in one block of memory: the pixel records (pixels + 1), then
/// all depths, all values, the counts (if the map has them) and the layer
/// starts, each contiguous. Lookups read a pixel's record and then its depths
/// and values, which lie next to those of its neighbours; a monochrome pixel
/// has one value per vertex.
class DecodedTile {
public:
    DecodedTile() = default;
    /// Storage for a tile of width x height pixels holding these totals; the
    /// records are zero, to be filled by the decoder.
    DecodedTile(std::uint32_t width, std::uint32_t height, std::uint64_t vertices, std::uint64_t values,
                std::uint64_t layerStarts, bool hasCounts);

    std::uint32_t width = 0;
    std::uint32_t height = 0;

    std::size_t pixelCount() const { return static_cast<std::size_t>(width) * height; }
    const PixelRecord* records() const { return records_; }
    const float* depths() const { return z_; }
    const float* values() const { return v_; }
    const std::uint32_t* counts() const { return counts_; }  ///< null without counts
    const std::uint32_t* layerStarts() const { return layerStarts_; }

    PixelRecord* records() { return records_; }
    float* depths() { return z_; }
    float* values() { return v_; }
    std::uint32_t* counts() { return counts_; }
    std::uint32_t* layerStarts() { return layerStarts_; }

    /// Pixel `index` (row-major). Inline: a soft-shadow ray reads one per pixel it crosses.
    VisibilityView pixel(std::size_t index) const {
        if (!records_) return {};
        const PixelRecord& a = records_[index];
        const PixelRecord& b = records_[index + 1];
        const std::size_t vertices = b.vertexStart - a.vertexStart;
        std::span<const std::uint32_t> pixelCounts;
        if (counts_) pixelCounts = std::span<const std::uint32_t>(counts_ + a.vertexStart, vertices);
        return VisibilityView(std::span<const float>(z_ + a.vertexStart, vertices),
                              std::span<const float>(v_ + a.valueStart, b.valueStart - a.valueStart), pixelCounts,
                              static_cast<int>(a.channels),
                              std::span<const std::uint32_t>(layerStarts_ + a.layerStart, b.layerStart - a.layerStart));
    }
    std::size_t memoryBytes() const { return sizeof(DecodedTile) + storageBytes_; }

private:
    std::unique_ptr<std::byte[]> storage_;  // every array below points into it
    std::size_t storageBytes_ = 0;
    PixelRecord* records_ = nullptr;
    float* z_ = nullptr;
    float* v_ = nullptr;
    std::uint32_t* counts_ = nullptr;
    std::uint32_t* layerStarts_ = nullptr;
};

/// What the layout of a tile depends on.
struct TileLayout {
    int fileChannels = 1;
    bool hasCounts = false;
    int maxLayers = 1;
    /// The 1.1 coding (CODED_TILES); otherwise the 1.0 layout of raw arrays.
    bool coded = false;
    /// The level's value step (coded tiles only; 0: values as float32 bits).
    double valueStep = 0.0;
    /// The compressor of tiles stored compressed.
    TileCodec codec = TileCodec::Zlib;
    /// Coded tiles' depths: each pixel's ends predicted from the previous
    /// pixel's (PREDICTED_DEPTHS, what the writer writes); false for the first
    /// 1.1 coding, steps within each pixel, which is read only.
    bool predictedDepths = true;
};

struct EncodedTile {
    std::vector<std::uint8_t> stored;  // empty for an empty tile
    TileSummary summary;              // offset left 0
};

/// Serialises `pixels` (width * height, row order, already valid; with a
/// value step, every value a multiple of it) and compresses with the layout's
/// codec at `codecLevel` (0: not at all) when that makes the tile smaller.
EncodedTile encodeTile(std::span<const VisibilityFunction> pixels, const TileLayout& layout, int codecLevel);

/// Checks the CRC of `stored`, decompresses it, parses and checks the layout and
/// every function. Throws dsm::Error prefixed with `where` (file, level, tile),
/// naming the pixel (in level coordinates, from the tile's origin) at fault.
DecodedTile decodeTile(std::span<const std::uint8_t> stored, const TileSummary& summary, std::uint32_t width,
                       std::uint32_t height, const TileLayout& layout, const ReaderOptions& limits,
                       const std::string& where, std::uint32_t originX, std::uint32_t originY);

}  // namespace dsm::format
