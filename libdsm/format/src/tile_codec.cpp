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

DecodedTile::DecodedTile(std::uint32_t w, std::uint32_t h, std::uint64_t vertices, std::uint64_t valueTotal,
                         std::uint64_t layerTotal, bool hasCounts)
    : width(w), height(h) {
    static_assert(sizeof(PixelRecord) == 16 && sizeof(float) == 4 && alignof(PixelRecord) == 4);
    const std::size_t pixels = pixelCount();
    storageBytes_ = (pixels + 1) * sizeof(PixelRecord) + 4 * (vertices * (hasCounts ? 2 : 1) + valueTotal + layerTotal);
    // An array of bytes from new[] implicitly creates the records and floats
    // placed in it (C++20); every one is written before it is read.
    storage_.reset(new std::byte[storageBytes_]);
    std::byte* at = storage_.get();
    records_ = reinterpret_cast<PixelRecord*>(at);
    at += (pixels + 1) * sizeof(PixelRecord);
    for (std::size_t p = 0; p <= pixels; ++p) records_[p] = PixelRecord{0, 0, 0, 1};
    z_ = reinterpret_cast<float*>(at);
    at += 4 * vertices;
    v_ = reinterpret_cast<float*>(at);
    at += 4 * valueTotal;
    if (hasCounts) {
        counts_ = reinterpret_cast<std::uint32_t*>(at);
        at += 4 * vertices;
    }
    layerStarts_ = reinterpret_cast<std::uint32_t*>(at);
}

VisibilityView DecodedTile::pixel(std::size_t p) const {
    if (!records_) return {};
    const PixelRecord& a = records_[p];
    const PixelRecord& b = records_[p + 1];
    const std::size_t vertices = b.vertexStart - a.vertexStart;
    std::span<const std::uint32_t> pixelCounts;
    if (counts_) pixelCounts = std::span<const std::uint32_t>(counts_ + a.vertexStart, vertices);
    return VisibilityView(std::span<const float>(z_ + a.vertexStart, vertices),
                          std::span<const float>(v_ + a.valueStart, b.valueStart - a.valueStart), pixelCounts,
                          static_cast<int>(a.channels),
                          std::span<const std::uint32_t>(layerStarts_ + a.layerStart, b.layerStart - a.layerStart));
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
    const std::size_t pixels = static_cast<std::size_t>(width) * height;
    if (summary.empty()) return DecodedTile(width, height, 0, 0, 0, false);

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

    // The pixel table first, checked and totalled, so that the tile is
    // allocated once at its final size.
    ByteReader r(raw.data(), raw.size());
    if (!r.need(pixelTableBytes(pixels))) fail(concat("tile of ", raw.size(), " bytes is too short for its pixel table"));
    std::vector<PixelRecord> records(pixels + 1, PixelRecord{0, 0, 0, 1});
    std::uint64_t previous = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint32_t cumulative = r.u32();
        if (cumulative < previous) fail(concat(pixelAt(p), ": cumulative vertex count decreases"));
        if (cumulative - previous > limits.maxVerticesPerPixel)
            fail(concat(pixelAt(p), ": ", cumulative - previous, " vertices exceed the reader's limit ",
                        limits.maxVerticesPerPixel),
                 ErrorCode::limit);
        records[p + 1].vertexStart = cumulative;
        previous = cumulative;
    }
    if (previous != summary.vertexCount)
        fail(concat("pixel table holds ", previous, " vertices, the directory ", summary.vertexCount));
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint8_t flags = r.u8();
        if (flags & ~kKnownPixelFlags) fail(concat(pixelAt(p), ": unknown flags 0x", std::hex, int(flags)));
        records[p].channels = (flags & kPixelRgb) ? 3 : 1;
        if (static_cast<int>(records[p].channels) > layout.fileChannels)
            fail(concat(pixelAt(p), ": RGB pixel in a monochrome map"));
    }
    std::uint64_t layerTotal = 0, valueTotal = 0, expected = pixelTableBytes(pixels);
    const std::uint64_t perVertexExtra = 4 + (layout.hasCounts ? 4 : 0);
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint8_t layers = r.u8();
        const std::uint32_t n = records[p + 1].vertexStart - records[p].vertexStart;
        if (layers < 1 || layers > layout.maxLayers)
            fail(concat(pixelAt(p), ": layer count ", int(layers), " is not in [1, ", layout.maxLayers, "]"));
        if (layers > 1 && layers > n) fail(concat(pixelAt(p), ": ", int(layers), " layers but ", n, " vertices"));
        layerTotal += layers - 1u;
        valueTotal += std::uint64_t(n) * records[p].channels;
        expected += 4ull * (layers - 1u) + n * (perVertexExtra + 4ull * records[p].channels);
        records[p + 1].valueStart = static_cast<std::uint32_t>(valueTotal);
        records[p + 1].layerStart = static_cast<std::uint32_t>(layerTotal);
    }
    if (expected != raw.size())
        fail(concat("tile holds ", raw.size(), " bytes but its pixel table describes ", expected));
    r.seek(pixelTableBytes(pixels));

    DecodedTile tile(width, height, summary.vertexCount, valueTotal, layerTotal, layout.hasCounts);
    std::copy(records.begin(), records.end(), tile.records());
    float* const z = tile.depths();
    float* const v = tile.values();
    std::uint32_t* const counts = tile.counts();
    std::uint32_t* const layerStarts = tile.layerStarts();
    float minZ = std::numeric_limits<float>::infinity(), maxZ = -std::numeric_limits<float>::infinity();
    std::uint32_t nonEmpty = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        const PixelRecord& a = records[p];
        const PixelRecord& b = records[p + 1];
        for (std::uint32_t l = a.layerStart; l < b.layerStart; ++l) layerStarts[l] = r.u32();
        for (std::uint32_t i = a.vertexStart; i < b.vertexStart; ++i) z[i] = r.f32();
        for (std::uint32_t i = a.valueStart; i < b.valueStart; ++i) v[i] = r.f32();
        if (layout.hasCounts)
            for (std::uint32_t i = a.vertexStart; i < b.vertexStart; ++i) counts[i] = r.u32();
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
