#include "tile_codec.h"

#include <algorithm>
#include <limits>

#include <zlib.h>

#include "byte_io.h"
#include "dsm/error.h"
#include "format_layout.h"
#include "text.h"

namespace dsm::format {

using detail::ByteReader;
using detail::ByteWriter;
using detail::concat;

namespace {

std::size_t pixelTableBytes(std::size_t pixels) {
    const std::size_t bytes = pixels * 6;
    return (bytes + 3) & ~std::size_t(3);
}

}  // namespace

VisibilityView DecodedTile::pixel(std::size_t p) const {
    const std::size_t v0 = vertexStart[p], v1 = vertexStart[p + 1];
    const std::size_t c0 = valueStart[p], c1 = valueStart[p + 1];
    const std::size_t l0 = layerStart[p], l1 = layerStart[p + 1];
    std::span<const std::uint32_t> pixelCounts;
    if (!counts.empty()) pixelCounts = std::span<const std::uint32_t>(counts).subspan(v0, v1 - v0);
    return VisibilityView(std::span<const float>(z).subspan(v0, v1 - v0), std::span<const float>(v).subspan(c0, c1 - c0),
                          pixelCounts, channels[p], std::span<const std::uint32_t>(layerStarts).subspan(l0, l1 - l0));
}

std::size_t DecodedTile::memoryBytes() const {
    return sizeof(DecodedTile) + (vertexStart.size() + valueStart.size() + layerStart.size()) * 4 + channels.size() +
           z.size() * 4 + v.size() * 4 + counts.size() * 4 + layerStarts.size() * 4;
}

EncodedTile encodeTile(std::span<const VisibilityFunction> pixels, const TileLayout& layout, int zlibLevel) {
    EncodedTile out;
    TileSummary& s = out.summary;
    std::uint64_t vertices = 0;
    float minZ = std::numeric_limits<float>::infinity(), maxZ = -std::numeric_limits<float>::infinity();
    for (const VisibilityFunction& f : pixels) {
        vertices += f.size();
        if (!f.empty()) {
            ++s.nonEmptyPixels;
            minZ = std::min(minZ, f.z(0));
            maxZ = std::max(maxZ, f.z(f.size() - 1));
        }
    }
    if (vertices == 0) return out;  // empty tile: nothing stored
    if (vertices > UINT32_MAX)
        throw Error(ErrorCode::limit, concat("tile holds ", vertices, " vertices, more than 2^32 - 1"));
    s.vertexCount = static_cast<std::uint32_t>(vertices);
    s.minZ = minZ;
    s.maxZ = maxZ;

    std::vector<std::uint8_t> raw;
    ByteWriter w(raw);
    std::uint32_t running = 0;
    for (const VisibilityFunction& f : pixels) w.u32(running += static_cast<std::uint32_t>(f.size()));
    for (const VisibilityFunction& f : pixels) w.u8(f.channels() == 3 ? kPixelRgb : 0);
    for (const VisibilityFunction& f : pixels) w.u8(static_cast<std::uint8_t>(f.layerCount()));
    w.zeros(pixelTableBytes(pixels.size()) - pixels.size() * 6);
    for (const VisibilityFunction& f : pixels) {
        for (std::size_t layer = 1; layer < f.layerCount(); ++layer) w.u32(static_cast<std::uint32_t>(f.layerBegin(layer)));
        for (float z : f.depths()) w.f32(z);
        for (float v : f.allValues()) w.f32(v);
        if (layout.hasCounts)
            for (std::size_t i = 0; i < f.size(); ++i) w.u32(f.count(i));
    }
    if (raw.size() > UINT32_MAX) throw Error(ErrorCode::limit, concat("tile of ", raw.size(), " bytes exceeds 4 GiB"));
    s.rawBytes = static_cast<std::uint32_t>(raw.size());

    if (zlibLevel > 0) {
        uLongf bound = compressBound(static_cast<uLong>(raw.size()));
        std::vector<std::uint8_t> packed(bound);
        if (compress2(packed.data(), &bound, raw.data(), static_cast<uLong>(raw.size()), zlibLevel) != Z_OK)
            throw Error(ErrorCode::internal, "zlib failed to compress a tile");
        if (bound < raw.size()) {
            packed.resize(bound);
            out.stored = std::move(packed);
        }
    }
    if (out.stored.empty()) out.stored = std::move(raw);
    s.storedBytes = static_cast<std::uint32_t>(out.stored.size());
    s.crc32 = crc32(out.stored.data(), out.stored.size());
    return out;
}

DecodedTile decodeTile(std::span<const std::uint8_t> stored, const TileSummary& summary, std::uint32_t width,
                       std::uint32_t height, const TileLayout& layout, const ReaderOptions& limits,
                       const std::string& where, std::uint32_t originX, std::uint32_t originY) {
    auto fail = [&](const std::string& what, ErrorCode code = ErrorCode::corrupt) {
        throw Error(code, concat(where, ": ", what));
    };
    // Pixel p of the tile in level coordinates, as the validation errors below name it.
    auto pixelAt = [&](std::size_t p) { return concat("pixel ", originX + p % width, ",", originY + p / width); };
    DecodedTile tile;
    tile.width = width;
    tile.height = height;
    const std::size_t pixels = tile.pixelCount();
    tile.vertexStart.assign(pixels + 1, 0);
    tile.valueStart.assign(pixels + 1, 0);
    tile.layerStart.assign(pixels + 1, 0);
    tile.channels.assign(pixels, 1);
    if (summary.empty()) return tile;

    if (stored.size() != summary.storedBytes) fail("stored size does not match the directory");
    const std::uint32_t crc = crc32(stored.data(), stored.size());
    if (crc != summary.crc32) fail(concat("CRC-32 mismatch (stored ", summary.crc32, ", computed ", crc, ")"));
    if (summary.rawBytes > limits.maxTileBytes)
        fail(concat("tile of ", summary.rawBytes, " bytes exceeds the reader's limit ", limits.maxTileBytes),
             ErrorCode::limit);
    std::vector<std::uint8_t> inflated;
    std::span<const std::uint8_t> raw = stored;
    if (summary.storedBytes < summary.rawBytes) {
        inflated.resize(summary.rawBytes);
        uLongf size = summary.rawBytes;
        const int rc = uncompress(inflated.data(), &size, stored.data(), static_cast<uLong>(stored.size()));
        if (rc != Z_OK) fail(concat("zlib cannot inflate the tile (error ", rc, ")"));
        if (size != summary.rawBytes) fail(concat("tile inflates to ", size, " bytes, not ", summary.rawBytes));
        raw = inflated;
    } else if (summary.storedBytes > summary.rawBytes) {
        fail(concat("stored size ", summary.storedBytes, " exceeds the raw size ", summary.rawBytes));
    }

    ByteReader r(raw.data(), raw.size());
    if (!r.need(pixelTableBytes(pixels))) fail(concat("tile of ", raw.size(), " bytes is too short for its pixel table"));
    std::uint64_t previous = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint32_t cumulative = r.u32();
        if (cumulative < previous) fail(concat(pixelAt(p), ": cumulative vertex count decreases"));
        if (cumulative - previous > limits.maxVerticesPerPixel)
            fail(concat(pixelAt(p), ": ", cumulative - previous, " vertices exceed the reader's limit ",
                        limits.maxVerticesPerPixel),
                 ErrorCode::limit);
        tile.vertexStart[p + 1] = cumulative;
        previous = cumulative;
    }
    if (previous != summary.vertexCount)
        fail(concat("pixel table holds ", previous, " vertices, the directory ", summary.vertexCount));
    std::vector<std::uint8_t> layers(pixels);
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint8_t flags = r.u8();
        if (flags & ~kKnownPixelFlags) fail(concat(pixelAt(p), ": unknown flags 0x", std::hex, int(flags)));
        tile.channels[p] = (flags & kPixelRgb) ? 3 : 1;
        if (tile.channels[p] > layout.fileChannels) fail(concat(pixelAt(p), ": RGB pixel in a monochrome map"));
    }
    std::uint64_t layerTotal = 0, valueTotal = 0, expected = pixelTableBytes(pixels);
    const std::uint64_t perVertexExtra = 4 + (layout.hasCounts ? 4 : 0);
    for (std::size_t p = 0; p < pixels; ++p) {
        layers[p] = r.u8();
        const std::uint32_t n = tile.vertexStart[p + 1] - tile.vertexStart[p];
        if (layers[p] < 1 || layers[p] > layout.maxLayers)
            fail(concat(pixelAt(p), ": layer count ", int(layers[p]), " is not in [1, ", layout.maxLayers, "]"));
        if (layers[p] > 1 && layers[p] > n) fail(concat(pixelAt(p), ": ", int(layers[p]), " layers but ", n, " vertices"));
        layerTotal += layers[p] - 1u;
        valueTotal += std::uint64_t(n) * tile.channels[p];
        expected += 4ull * (layers[p] - 1u) + n * (perVertexExtra + 4ull * tile.channels[p]);
        tile.valueStart[p + 1] = static_cast<std::uint32_t>(valueTotal);
        tile.layerStart[p + 1] = static_cast<std::uint32_t>(layerTotal);
    }
    if (expected != raw.size())
        fail(concat("tile holds ", raw.size(), " bytes but its pixel table describes ", expected));
    r.seek(pixelTableBytes(pixels));

    tile.z.resize(summary.vertexCount);
    tile.v.resize(valueTotal);
    tile.layerStarts.resize(layerTotal);
    if (layout.hasCounts) tile.counts.resize(summary.vertexCount);
    float minZ = std::numeric_limits<float>::infinity(), maxZ = -std::numeric_limits<float>::infinity();
    std::uint32_t nonEmpty = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        for (std::uint32_t l = tile.layerStart[p]; l < tile.layerStart[p + 1]; ++l) tile.layerStarts[l] = r.u32();
        for (std::uint32_t i = tile.vertexStart[p]; i < tile.vertexStart[p + 1]; ++i) tile.z[i] = r.f32();
        for (std::uint32_t i = tile.valueStart[p]; i < tile.valueStart[p + 1]; ++i) tile.v[i] = r.f32();
        if (layout.hasCounts)
            for (std::uint32_t i = tile.vertexStart[p]; i < tile.vertexStart[p + 1]; ++i) tile.counts[i] = r.u32();
        const VisibilityView view = tile.pixel(p);
        try {
            view.validate();
        } catch (const Error& e) {
            fail(concat("pixel ", originX + p % width, ",", originY + p / width, ": ", e.what()));
        }
        if (!view.empty()) {
            ++nonEmpty;
            minZ = std::min(minZ, view.z(0));
            maxZ = std::max(maxZ, view.z(view.size() - 1));
        }
    }
    if (!r.ok()) fail("tile data is truncated");
    if (minZ != summary.minZ || maxZ != summary.maxZ)
        fail(concat("depth range [", minZ, ", ", maxZ, "] differs from the directory's [", summary.minZ, ", ",
                    summary.maxZ, "]"));
    if (nonEmpty != summary.nonEmptyPixels)
        fail(concat(nonEmpty, " non-empty pixels, the directory says ", summary.nonEmptyPixels));
    return tile;
}

}  // namespace dsm::format
