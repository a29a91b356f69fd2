#include "tile_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <functional>
#include <cmath>
#include <cstring>
#include <limits>
#include <new>

#include <zlib.h>
#include <zstd.h>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "byte_io.h"
#include "dsm/error.h"
#include "format_layout.h"
#include "kept_objects.h"
#include "text.h"

namespace dsm::format {

using detail::ByteReader;
using detail::ByteWriter;
using detail::concat;
using detail::VarintReader;

namespace {

std::size_t pixelTableBytes(std::size_t pixels) {
    const std::size_t bytes = pixels * 6;
    return (bytes + 3) & ~std::size_t(3);
}

// Zigzag mapping of a signed difference to an unsigned one: 0, -1, 1, -2, ...
std::uint32_t zigzag(std::uint32_t difference) {
    const auto d = static_cast<std::int32_t>(difference);
    return (static_cast<std::uint32_t>(d) << 1) ^ static_cast<std::uint32_t>(d >> 31);
}
std::uint32_t unzigzag(std::uint32_t u) { return (u >> 1) ^ (0u - (u & 1u)); }

// The integer a coded tile stores a value as: its multiple of the step, or
// its float32 bits when there is no step. Layers start from the key of 1.
std::uint32_t valueKey(float v, double step) {
    if (step == 0.0) return std::bit_cast<std::uint32_t>(v);
    const double multiple = std::round(static_cast<double>(v) / step);
    if (multiple * step != static_cast<double>(v))
        throw Error(ErrorCode::internal, concat("value ", v, " is not a multiple of the value step ", step));
    return static_cast<std::uint32_t>(multiple);
}

// Appends each pixel's flag byte to `raw` and returns where they begin. A
// pixel is flagged RGB only when its channels differ somewhere: a grey pixel
// (values equal at every vertex as stored, or no vertices at all) is written
// monochrome, in a third of the room, and its bytes do not depend on how it
// was made (a stitch's empty part, a builder's empty RGB pixel, channels that
// met on the value step).
std::size_t writePixelFlags(std::span<const VisibilityFunction> pixels, std::vector<std::uint8_t>& raw) {
    const std::size_t begin = raw.size();
    for (const VisibilityFunction& f : pixels) raw.push_back(f.channels() == 3 && !f.isMonochrome() ? kPixelRgb : 0);
    return begin;
}

// How many values a vertex pixel `p` is written with, as its flag (at `flags` in
// `raw`) says: the pixels are not tested again.
int writtenChannels(const std::vector<std::uint8_t>& raw, std::size_t flags, std::size_t p) {
    return (raw[flags + p] & kPixelRgb) ? 3 : 1;
}

// The 1.0 layout: the pixel table, then per pixel raw arrays.
std::vector<std::uint8_t> plainTileBytes(std::span<const VisibilityFunction> pixels, const TileLayout& layout) {
    std::vector<std::uint8_t> raw;
    ByteWriter w(raw);
    std::uint32_t running = 0;
    for (const VisibilityFunction& f : pixels) w.u32(running += static_cast<std::uint32_t>(f.size()));
    const std::size_t flags = writePixelFlags(pixels, raw);
    for (const VisibilityFunction& f : pixels) w.u8(static_cast<std::uint8_t>(f.layerCount()));
    w.zeros(pixelTableBytes(pixels.size()) - pixels.size() * 6);
    for (std::size_t p = 0; p < pixels.size(); ++p) {
        const VisibilityFunction& f = pixels[p];
        for (std::size_t layer = 1; layer < f.layerCount(); ++layer) w.u32(static_cast<std::uint32_t>(f.layerBegin(layer)));
        for (float z : f.depths()) w.f32(z);
        const int channels = writtenChannels(raw, flags, p);
        for (std::size_t i = 0; i < f.size(); ++i)
            for (int k = 0; k < channels; ++k) w.f32(f.value(i, k));
        if (layout.hasCounts)
            for (std::size_t i = 0; i < f.size(); ++i) w.u32(f.count(i));
    }
    return raw;
}

// The parts of a coded tile in order, each deflated as blocks of its own.
enum TilePart : std::size_t { kPixelTable, kDepthEnds, kDepthSteps, kValues, kCounts };

// The 1.1 coding: every part of the tile in turn, as variable-length
// integers, each small for the data deep shadow maps hold (spec §7).
// `partEnds` receives where each part after the first begins (TilePart).
std::vector<std::uint8_t> codedTileBytes(std::span<const VisibilityFunction> pixels, const TileLayout& layout,
                                         std::vector<std::size_t>& partEnds) {
    std::vector<std::uint8_t> raw;
    ByteWriter w(raw);
    for (const VisibilityFunction& f : pixels) w.varint(static_cast<std::uint32_t>(f.size()));
    const std::size_t flags = writePixelFlags(pixels, raw);
    for (const VisibilityFunction& f : pixels) w.u8(static_cast<std::uint8_t>(f.layerCount()));
    for (const VisibilityFunction& f : pixels)
        for (std::size_t layer = 1; layer < f.layerCount(); ++layer)
            w.varint(static_cast<std::uint32_t>(f.layerBegin(layer) - f.layerBegin(layer - 1)));
    // Depths: float32 bit patterns, which rise with the depth. Each pixel's
    // ends (first and last depth) from the previous non-empty pixel's
    // (signed), in the part of the pixel table; then, in a part of their own,
    // the steps between the depths in between. The ends of neighbouring
    // pixels lie close (a receiver's depth changes smoothly across the map),
    // the steps within a pixel do not: 6 % smaller than steps from the first
    // depth on over the hair ball.
    std::uint32_t previousFirst = 0, previousLast = 0;
    partEnds.push_back(raw.size());  // deflated apart from the table: examples 0.2-0.7 % smaller
    for (const VisibilityFunction& f : pixels) {
        if (f.empty()) continue;
        const std::uint32_t first = std::bit_cast<std::uint32_t>(f.z(0));
        const std::uint32_t last = std::bit_cast<std::uint32_t>(f.z(f.size() - 1));
        w.varint(zigzag(first - previousFirst));
        if (f.size() > 1) w.varint(zigzag(last - previousLast));
        previousFirst = first;
        previousLast = last;
    }
    partEnds.push_back(raw.size());
    for (const VisibilityFunction& f : pixels)
        for (std::size_t i = 1; i + 1 < f.size(); ++i)
            w.varint(std::bit_cast<std::uint32_t>(f.z(i)) - std::bit_cast<std::uint32_t>(f.z(i - 1)));
    partEnds.push_back(raw.size());
    // Values: per channel, the fall from the previous vertex of the layer (from
    // 1 at a layer's first vertex).
    const std::uint32_t one = valueKey(1.0f, layout.valueStep);
    for (std::size_t p = 0; p < pixels.size(); ++p) {
        const VisibilityFunction& f = pixels[p];
        const int c = writtenChannels(raw, flags, p);
        std::uint32_t previous[3] = {one, one, one};
        std::size_t nextLayer = 1;
        for (std::size_t i = 0; i < f.size(); ++i) {
            if (nextLayer < f.layerCount() && i == f.layerBegin(nextLayer)) {
                previous[0] = previous[1] = previous[2] = one;
                ++nextLayer;
            }
            for (int k = 0; k < c; ++k) {
                const std::uint32_t key = valueKey(f.value(i, k), layout.valueStep);
                w.varint(previous[k] - key);
                previous[k] = key;
            }
        }
    }
    partEnds.push_back(raw.size());
    if (layout.hasCounts)
        for (const VisibilityFunction& f : pixels)
            for (std::size_t i = 0; i < f.size(); ++i) w.varint(f.count(i));
    return raw;
}

// A zlib stream kept from tile to tile; reset, it writes the same bytes as a
// new stream. deflateParts() sets the level with each part's strategy, so a
// stream made for one level serves any.
struct DeflateStream {
    z_stream z{};
    bool holdsState = false;
};

struct DeflateStreamTraits {
    static DeflateStream* make() { return new (std::nothrow) DeflateStream; }
    static void destroy(DeflateStream* stream) {
        if (stream->holdsState) deflateEnd(&stream->z);
        delete stream;
    }
};

// `stream` ready for a tile at `level`: reset, or made anew. False when zlib
// fails (the stream then holds no state).
bool readyForTile(DeflateStream& stream, int level) {
    if (stream.holdsState && deflateReset(&stream.z) == Z_OK) return true;
    if (stream.holdsState) deflateEnd(&stream.z);
    stream.z = z_stream{};
    stream.holdsState = deflateInit(&stream.z, level) == Z_OK;
    return stream.holdsState;
}

// Whether deflate's search for repeated strings pays on `bytes`: whether a
// quarter or more of its positions start four bytes seen before within
// deflate's window, as one probe of a table of the last position of each
// hash finds them. The depth steps of the examples' tiles repeat at 0-9 % of
// their positions; steps repeated pixel after pixel (parallel cards under an
// orthographic light, synthetic maps) at nearly all.
bool repeatsStrings(const std::uint8_t* bytes, std::size_t size) {
    constexpr int kHashBits = 12;
    constexpr std::size_t kWindow = 32768;
    if (size < 4) return false;
    // Per hash: the last position with it + 1 (0: none) above the four bytes there.
    std::array<std::uint64_t, std::size_t(1) << kHashBits> lastSeen{};
    const std::size_t positions = size - 3, enough = (positions + 3) / 4;
    std::size_t repeats = 0;
    for (std::size_t i = 0; i < positions; ++i) {
        std::uint32_t four;
        std::memcpy(&four, bytes + i, 4);
        std::uint64_t& seen = lastSeen[(four * 2654435761u) >> (32 - kHashBits)];
        const std::size_t at = static_cast<std::size_t>(seen >> 32);
        if (at != 0 && static_cast<std::uint32_t>(seen) == four && i - (at - 1) <= kWindow && ++repeats == enough)
            return true;
        if (repeats + (positions - i - 1) < enough) return false;  // too few positions left
        seen = (std::uint64_t(i + 1) << 32) | four;
    }
    return false;
}

// The deflate strategy of part `k` of a coded tile. The depths' ends and
// steps are varints with few repeated strings in them: deflate's search for
// matches keeps them 0-1 % smaller than runs and Huffman codes alone
// (Z_RLE) do, at several times the cost; unless they do repeat. The pixel
// table, values and counts repeat strings (plateaus, layers: runs alone make
// an area light's values 66 % larger), where Z_FILTERED, which drops matches
// of five bytes or fewer, codes the examples' values and counts up to 3 %
// smaller than the default strategy (the leaves' RGB values 0.8 % larger).
int partStrategy(std::size_t k, const std::uint8_t* bytes, std::size_t size) {
    const bool varintDepths = k == kDepthEnds || k == kDepthSteps;
    return varintDepths && !repeatsStrings(bytes, size) ? Z_RLE : Z_FILTERED;
}

// One zlib stream of `raw` that ends a deflate block at each of `partEnds`
// (Z_BLOCK), so that each part of a coded tile gets Huffman codes of its own
// (4 % smaller than one compress2() over the hair ball's tiles) and the
// strategy that suits it. Empty when zlib fails.
std::vector<std::uint8_t> deflateParts(const std::vector<std::uint8_t>& raw, const std::vector<std::size_t>& partEnds,
                                       int level) {
    static detail::KeptObjects<DeflateStream, DeflateStreamTraits> kept;
    const decltype(kept)::Lease stream(kept);
    if (!stream.get() || !readyForTile(*stream.get(), level)) return {};
    z_stream& z = stream.get()->z;
    std::vector<std::uint8_t> out(compressBound(static_cast<uLong>(raw.size())) + 16 * (partEnds.size() + 1));
    z.next_out = out.data();
    z.avail_out = static_cast<uInt>(out.size());
    std::size_t begin = 0;
    bool ok = true;
    for (std::size_t k = 0; k <= partEnds.size() && ok; ++k) {
        const std::size_t end = k < partEnds.size() ? partEnds[k] : raw.size();
        const bool last = k == partEnds.size();
        if (!last && end == begin) continue;  // an empty part ends no block (zlib would make no progress)
        // Set before the part is given: deflateParams() deflates any input
        // still pending with the strategy before (none is: each part ends a
        // block). A stream reset for this tile kept the last tile's strategy.
        if (deflateParams(&z, level, partStrategy(k, raw.data() + begin, end - begin)) != Z_OK) {
            ok = false;
            break;
        }
        z.next_in = const_cast<Bytef*>(raw.data() + begin);
        z.avail_in = static_cast<uInt>(end - begin);
        const int rc = deflate(&z, last ? Z_FINISH : Z_BLOCK);
        ok = last ? rc == Z_STREAM_END : rc == Z_OK && z.avail_in == 0;
        begin = end;
    }
    out.resize(ok ? z.total_out : 0);
    return out;
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

namespace {

struct ZstdCompressionTraits {
    static ZSTD_CCtx* make() { return ZSTD_createCCtx(); }
    static void destroy(ZSTD_CCtx* context) { ZSTD_freeCCtx(context); }
};

// `raw` as one zstd frame at `level`; empty when zstd fails. The context
// is kept for later tiles; the frame is the same as from a new one.
std::vector<std::uint8_t> zstdFrame(const std::vector<std::uint8_t>& raw, int level) {
    static detail::KeptObjects<ZSTD_CCtx, ZstdCompressionTraits> kept;
    const decltype(kept)::Lease context(kept);
    if (!context.get()) return {};
    std::vector<std::uint8_t> out(ZSTD_compressBound(raw.size()));
    const std::size_t n = ZSTD_compressCCtx(context.get(), out.data(), out.size(), raw.data(), raw.size(), level);
    if (ZSTD_isError(n)) return {};
    out.resize(n);
    return out;
}

}  // namespace

EncodedTile encodeTile(std::span<const VisibilityFunction> pixels, const TileLayout& layout, int codecLevel) {
    if (layout.coded && !layout.predictedDepths)
        throw Error(ErrorCode::internal, "coded tiles are written with predicted depths only");
    const int zlibLevel = layout.codec == TileCodec::Zlib ? codecLevel : 0;
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

    std::vector<std::size_t> partEnds;
    std::vector<std::uint8_t> raw = layout.coded ? codedTileBytes(pixels, layout, partEnds) : plainTileBytes(pixels, layout);
    if (raw.size() > UINT32_MAX) throw Error(ErrorCode::limit, concat("tile of ", raw.size(), " bytes exceeds 4 GiB"));
    s.rawBytes = static_cast<std::uint32_t>(raw.size());

    if (layout.codec == TileCodec::Zstd && codecLevel > 0) {
        std::vector<std::uint8_t> packed = zstdFrame(raw, codecLevel);
        if (packed.empty()) throw Error(ErrorCode::internal, "zstd failed to compress a tile");
        if (packed.size() < raw.size()) out.stored = std::move(packed);
    } else if (zlibLevel > 0 && layout.coded) {
        std::vector<std::uint8_t> packed = deflateParts(raw, partEnds, zlibLevel);
        if (packed.empty()) throw Error(ErrorCode::internal, "zlib failed to compress a tile");
        if (packed.size() < raw.size()) out.stored = std::move(packed);
    } else if (zlibLevel > 0) {
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

namespace {

// Parses a tile's bytes after decompression into a DecodedTile, checking the
// layout but not yet the functions. `fail` throws.
using Fail = std::function<void(const std::string&, ErrorCode)>;

struct TileShape {
    std::uint32_t width;
    std::uint32_t height;
    std::size_t pixels;
    std::function<std::string(std::size_t)> pixelAt;  // "pixel x,y" in level coordinates
};

// Sets each record's channels from a pixel flag byte.
void readPixelFlag(std::uint8_t flags, PixelRecord& record, std::size_t p, const TileShape& shape,
                   const TileLayout& layout, const Fail& fail) {
    if (flags & ~kKnownPixelFlags)
        fail(concat(shape.pixelAt(p), ": unknown flags 0x", std::hex, int(flags)), ErrorCode::corrupt);
    record.channels = (flags & kPixelRgb) ? 3 : 1;
    if (static_cast<int>(record.channels) > layout.fileChannels)
        fail(concat(shape.pixelAt(p), ": RGB pixel in a monochrome map"), ErrorCode::corrupt);
}

void checkPixelVertices(std::uint64_t n, std::size_t p, const TileShape& shape, const ReaderOptions& limits,
                        const Fail& fail) {
    if (n > limits.maxVerticesPerPixel)
        fail(concat(shape.pixelAt(p), ": ", n, " vertices exceed the reader's limit ", limits.maxVerticesPerPixel),
             ErrorCode::limit);
}

void checkLayerCount(std::uint8_t layers, std::uint32_t n, std::size_t p, const TileShape& shape,
                     const TileLayout& layout, const Fail& fail) {
    if (layers < 1 || layers > layout.maxLayers)
        fail(concat(shape.pixelAt(p), ": layer count ", int(layers), " is not in [1, ", layout.maxLayers, "]"),
             ErrorCode::corrupt);
    if (layers > 1 && layers > n)
        fail(concat(shape.pixelAt(p), ": ", int(layers), " layers but ", n, " vertices"), ErrorCode::corrupt);
}

// Reads each pixel's layer count (one byte, from `readLayers`), checks it
// against the pixel's vertices and sets the value and layer starts of the
// records that follow; `layerTotal` counts the layers beyond each pixel's
// first, `valueTotal` the values. Shared by both tile layouts.
template <class ReadLayers>
void readLayerCounts(ReadLayers readLayers, std::vector<PixelRecord>& records, const TileShape& shape,
                     const TileLayout& layout, const Fail& fail, std::uint64_t& layerTotal,
                     std::uint64_t& valueTotal) {
    for (std::size_t p = 0; p + 1 < records.size(); ++p) {
        const std::uint8_t layers = readLayers();
        const std::uint32_t n = records[p + 1].vertexStart - records[p].vertexStart;
        if (layers != 1) checkLayerCount(layers, n, p, shape, layout, fail);  // 1 is always valid
        layerTotal += layers - 1u;
        valueTotal += std::uint64_t(n) * records[p].channels;
        records[p + 1].valueStart = static_cast<std::uint32_t>(valueTotal);
        records[p + 1].layerStart = static_cast<std::uint32_t>(layerTotal);
    }
}

DecodedTile parsePlainTile(std::span<const std::uint8_t> raw, const TileSummary& summary, const TileShape& shape,
                           const TileLayout& layout, const ReaderOptions& limits, const Fail& fail) {
    const std::size_t pixels = shape.pixels;
    ByteReader r(raw.data(), raw.size());
    if (!r.need(pixelTableBytes(pixels)))
        fail(concat("tile of ", raw.size(), " bytes is too short for its pixel table"), ErrorCode::corrupt);
    std::vector<PixelRecord> records(pixels + 1, PixelRecord{0, 0, 0, 1});
    std::uint64_t previous = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint32_t cumulative = r.u32();
        if (cumulative < previous) fail(concat(shape.pixelAt(p), ": cumulative vertex count decreases"), ErrorCode::corrupt);
        checkPixelVertices(cumulative - previous, p, shape, limits, fail);
        records[p + 1].vertexStart = cumulative;
        previous = cumulative;
    }
    if (previous != summary.vertexCount)
        fail(concat("pixel table holds ", previous, " vertices, the directory ", summary.vertexCount), ErrorCode::corrupt);
    for (std::size_t p = 0; p < pixels; ++p) readPixelFlag(r.u8(), records[p], p, shape, layout, fail);
    std::uint64_t layerTotal = 0, valueTotal = 0;
    readLayerCounts([&] { return r.u8(); }, records, shape, layout, fail, layerTotal, valueTotal);
    const std::uint64_t perVertexExtra = 4 + (layout.hasCounts ? 4 : 0);
    const std::uint64_t expected =
        pixelTableBytes(pixels) + 4 * layerTotal + previous * perVertexExtra + 4 * valueTotal;
    if (expected != raw.size())
        fail(concat("tile holds ", raw.size(), " bytes but its pixel table describes ", expected), ErrorCode::corrupt);
    r.seek(pixelTableBytes(pixels));

    DecodedTile tile(shape.width, shape.height, summary.vertexCount, valueTotal, layerTotal, layout.hasCounts);
    std::copy(records.begin(), records.end(), tile.records());
    float* const z = tile.depths();
    float* const v = tile.values();
    std::uint32_t* const counts = tile.counts();
    std::uint32_t* const layerStarts = tile.layerStarts();
    for (std::size_t p = 0; p < pixels; ++p) {
        const PixelRecord& a = records[p];
        const PixelRecord& b = records[p + 1];
        for (std::uint32_t l = a.layerStart; l < b.layerStart; ++l) layerStarts[l] = r.u32();
        for (std::uint32_t i = a.vertexStart; i < b.vertexStart; ++i) z[i] = r.f32();
        for (std::uint32_t i = a.valueStart; i < b.valueStart; ++i) v[i] = r.f32();
        if (layout.hasCounts)
            for (std::uint32_t i = a.vertexStart; i < b.vertexStart; ++i) counts[i] = r.u32();
    }
    if (!r.ok()) fail("tile data is truncated", ErrorCode::corrupt);
    return tile;
}

// What the coded decoder's own checks found while decoding, so that the
// functions need no second pass: the depth range, the non-empty pixels, and
// whether anything looked wrong (a depth not finite, negative or decreasing, a
// value outside [0, 1] or increasing, a layer start out of order). Anything
// wrong sends the tile through VisibilityView::validate(), which names the
// fault (and accepts what these checks reject only conservatively, such as a
// depth of -0).
struct DecodeChecks {
    bool suspect = false;
    std::uint32_t minBits = UINT32_MAX;
    std::uint32_t maxBits = 0;
    std::uint32_t nonEmptyPixels = 0;
};

constexpr std::uint32_t kInfinityBits = 0x7F800000;  // bits(+inf): finite non-negative floats lie below it

// Values of one layer run of `n` vertices of `c` channels: each the previous
// key less a difference, from `one`. `Quantised`: keys are multiples of the
// step; otherwise float32 bits. A run's keys stay in [0, one] exactly when its
// differences add up to no more than `one` (each is non-negative), which is
// checked once for the run.
#ifdef __SSE2__
// A run of at most 8 one-byte differences (`bytes`, the first lowest, zero
// past the run) from `one`: all 8 keys at once, as floats, into out[0..7] (the
// lanes past the run repeat its last key, for the caller to overwrite).
// Returns the differences' sum.
template <bool Quantised>
[[gnu::always_inline]] inline std::uint32_t storeByteRun(std::uint64_t bytes, std::uint32_t one, float step,
                                                         float* out) {
    const __m128i zero = _mm_setzero_si128();
    __m128i sum = _mm_unpacklo_epi8(_mm_cvtsi64_si128(static_cast<long long>(bytes)), zero);  // 8 x u16
    sum = _mm_add_epi16(sum, _mm_slli_si128(sum, 2));  // running sums: at most 8 * 127
    sum = _mm_add_epi16(sum, _mm_slli_si128(sum, 4));
    sum = _mm_add_epi16(sum, _mm_slli_si128(sum, 8));
    const __m128i ones = _mm_set1_epi32(static_cast<int>(one));
    const __m128i low = _mm_sub_epi32(ones, _mm_unpacklo_epi16(sum, zero));
    const __m128i high = _mm_sub_epi32(ones, _mm_unpackhi_epi16(sum, zero));
    if constexpr (Quantised) {  // as static_cast<float>(int32) * step, lane by lane
        const __m128 s = _mm_set1_ps(step);
        _mm_storeu_ps(out, _mm_mul_ps(_mm_cvtepi32_ps(low), s));
        _mm_storeu_ps(out + 4, _mm_mul_ps(_mm_cvtepi32_ps(high), s));
    } else {
        _mm_storeu_si128(reinterpret_cast<__m128i*>(out), low);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(out + 4), high);
    }
    return static_cast<std::uint32_t>(_mm_extract_epi16(sum, 7));
}
#endif

// `valuesEnd`: the end of the tile's values, up to which a run may write
// past its own (what follows is decoded later).
template <bool Quantised>
[[gnu::always_inline]] inline void decodeValueRun(VarintReader& r, std::uint32_t n, std::uint32_t c, std::uint32_t one,
                                                  float step, float*& out, const float* valuesEnd, bool& suspect) {
    const auto toFloat = [step](std::uint32_t key) {
        // A key of a quantised value is at most 2^24: converted as a signed
        // 32-bit integer, which is one instruction.
        if constexpr (Quantised) {
            return static_cast<float>(static_cast<std::int32_t>(key)) * step;
        } else {
            (void)step;  // float32 bits need no step
            return std::bit_cast<float>(key);
        }
    };
    float* const at = out;
    if (c == 1) {
        std::uint32_t key = one;
        std::uint64_t bytes;
        if (n <= 8 && r.singleBytes(n, bytes)) {
            // The common run: short, each difference one byte.
#ifdef __SSE2__
            if (valuesEnd - at >= 8) {
                suspect |= storeByteRun<Quantised>(bytes, one, step, at) > one;
                out = at + n;
                return;
            }
#endif
            for (std::uint32_t i = 0; i < n; ++i, bytes >>= 8) {
                key -= static_cast<std::uint32_t>(bytes & 0xFF);
                at[i] = toFloat(key);
            }
            suspect |= key > one;  // fell below 0: by at most 8 * 127, so wrapped above `one`
        } else {
            std::uint64_t fall = 0;
            r.forEach(n, [&](std::size_t i, std::uint32_t d) {
                fall += d;
                key -= d;
                at[i] = toFloat(key);
            });
            suspect |= fall > one;
        }
        out = at + n;
    } else {
        std::uint32_t key[3] = {one, one, one};
        std::uint64_t fall[3] = {0, 0, 0};
        std::uint32_t k = 0;
        r.forEach(std::size_t(n) * 3, [&](std::size_t i, std::uint32_t d) {
            fall[k] += d;
            key[k] -= d;
            at[i] = toFloat(key[k]);
            k = k == 2 ? 0 : k + 1;
        });
        suspect |= fall[0] > one || fall[1] > one || fall[2] > one;
        out = at + std::size_t(n) * 3;
    }
}

template <bool Quantised>
void decodeValues(VarintReader& reader, const PixelRecord* records, std::size_t pixels,
                  const std::uint32_t* layerStarts, float* v, std::uint32_t one, float step, bool& suspect) {
    VarintReader r = reader;  // local copies, kept in registers
    bool fell = false;
    const float* const valuesEnd = v + records[pixels].valueStart;
    for (std::size_t p = 0; p < pixels; ++p) {
        const PixelRecord& a = records[p];
        const PixelRecord& b = records[p + 1];
        const std::uint32_t n = b.vertexStart - a.vertexStart;
        float* out = v + a.valueStart;
        if (a.layerStart == b.layerStart) {  // one layer: one run
            decodeValueRun<Quantised>(r, n, a.channels, one, step, out, valuesEnd, fell);
            continue;
        }
        std::uint32_t begin = 0;
        for (std::uint32_t l = a.layerStart; l <= b.layerStart; ++l) {
            // Layer starts out of order were flagged when read; clamped here so
            // that the run stays within the pixel.
            const std::uint32_t end = l < b.layerStart ? std::min(std::max(layerStarts[l], begin), n) : n;
            decodeValueRun<Quantised>(r, end - begin, a.channels, one, step, out, valuesEnd, fell);
            begin = end;
        }
    }
    reader = r;
    suspect |= fell;
}

// Depths are float32 bit patterns: non-decreasing ones below bits(+inf) are
// finite, non-negative, non-decreasing depths.

// A pixel's first and last depth, noted for the checks of the whole tile.
[[gnu::always_inline]] inline void noteDepthEnds(std::uint32_t first, std::uint32_t last, DecodeChecks& checks) {
    ++checks.nonEmptyPixels;
    checks.suspect |= last < first;  // a last depth of bits(+inf) or above: by maxBits, once for the tile
    checks.minBits = std::min(checks.minBits, first);
    checks.maxBits = std::max(checks.maxBits, last);
}

// The depths z[from + 1 .. to - 1], each a step up from the one before;
// returns the last one's bits (z[from]'s when there are none) and whether a
// step wrapped past 2^32 - 1, as the sum of the steps beyond 32 bits (one
// check for the run: the steps are non-negative).
[[gnu::always_inline]] inline std::uint64_t decodeDepthSteps(VarintReader& r, float* z, std::uint32_t from,
                                                             std::uint32_t to) {
    std::uint64_t bits = std::bit_cast<std::uint32_t>(z[from]);
    float* const at = z + from + 1;
    r.forEach(to - from - 1, [&](std::size_t i, std::uint32_t step) {
        bits += step;
        at[i] = std::bit_cast<float>(static_cast<std::uint32_t>(bits));
    });
    return bits;
}

// PREDICTED_DEPTHS (spec §7): the ends of every pixel, each from the
// previous non-empty pixel's (zigzag differences), then the steps between
// them. One integer a vertex in all (a pixel of one vertex has one end, of
// two its two ends, of n > 2 two ends and n - 2 steps), read as one run
// first: their lengths vary from integer to integer in no order.
void decodePredictedDepths(VarintReader& reader, const PixelRecord* records, std::size_t pixels, float* z,
                           DecodeChecks& tileChecks) {
    constexpr std::uint32_t kRun = 8;  // steps of a pixel written at once, past its own
    const std::uint32_t vertices = records[pixels].vertexStart;
    const std::unique_ptr<std::uint32_t[]> integers(new std::uint32_t[std::size_t(vertices) + kRun]);
    reader.readInto(integers.get(), vertices);
    std::fill_n(integers.get() + vertices, kRun, 0u);
    std::size_t endCount = 0;
    for (std::size_t p = 0; p < pixels; ++p)
        endCount += std::min(records[p + 1].vertexStart - records[p].vertexStart, 2u);
    DecodeChecks checks = tileChecks;
    const std::uint32_t* end = integers.get();
    const std::uint32_t* step = end + endCount;
    std::uint32_t previousFirst = 0, previousLast = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint32_t a = records[p].vertexStart, b = records[p + 1].vertexStart;
        if (a == b) continue;
        const std::uint32_t first = previousFirst + unzigzag(*end++);
        const std::uint32_t last = b - a > 1 ? previousLast + unzigzag(*end++) : first;
        previousFirst = first;
        previousLast = last;
        noteDepthEnds(first, last, checks);
        z[a] = std::bit_cast<float>(first);
        // The steps between, summed in 64 bits: beyond the last depth, or
        // wrapped past 2^32 - 1, is one check for the pixel (the steps are
        // non-negative).
        const std::uint32_t steps = b - a > 2 ? b - a - 2 : 0;
        if (steps > 0 && steps <= kRun && a + 1 + kRun <= vertices) {
            // The common pixel: kRun depths written whatever its count, so
            // that no branch depends on it; those past its own belong to the
            // pixels after it, which write them again.
            std::uint64_t bits = first, sums[kRun];
            for (std::uint32_t k = 0; k < kRun; ++k) {
                bits += step[k];
                sums[k] = bits;
                z[a + 1 + k] = std::bit_cast<float>(static_cast<std::uint32_t>(bits));
            }
            step += steps;
            checks.suspect |= sums[steps - 1] > last;
        } else if (steps > 0) {
            std::uint64_t bits = first;
            for (std::uint32_t i = a + 1; i < b - 1; ++i) {
                bits += *step++;
                z[i] = std::bit_cast<float>(static_cast<std::uint32_t>(bits));
            }
            checks.suspect |= bits > last;
        }
        z[b - 1] = std::bit_cast<float>(last);  // after the steps, which may have passed it
    }
    checks.suspect |= checks.maxBits >= kInfinityBits;
    tileChecks = checks;
}

// The first 1.1 coding (files without PREDICTED_DEPTHS): pixel by pixel, the
// first depth from the previous non-empty pixel's first, the rest as steps.
void decodeDepthsByPixel(VarintReader& reader, const PixelRecord* records, std::size_t pixels, float* z,
                         DecodeChecks& tileChecks) {
    VarintReader r = reader;  // local copies, kept in registers
    DecodeChecks checks = tileChecks;
    std::uint32_t previousFirst = 0;
    for (std::size_t p = 0; p < pixels; ++p) {
        const std::uint32_t a = records[p].vertexStart, b = records[p + 1].vertexStart;
        if (a == b) continue;
        const std::uint32_t first = previousFirst + unzigzag(r.next());
        previousFirst = first;
        z[a] = std::bit_cast<float>(first);
        const std::uint64_t last = decodeDepthSteps(r, z, a, b);
        checks.suspect |= last > UINT32_MAX;
        noteDepthEnds(first, static_cast<std::uint32_t>(last), checks);
    }
    reader = r;
    checks.suspect |= checks.maxBits >= kInfinityBits;
    tileChecks = checks;
}

// Whether the `count` bytes at `bytes` all equal `value` (8 compared at once).
bool allBytesAre(const std::uint8_t* bytes, std::size_t count, std::uint8_t value) {
    const std::uint64_t word = 0x0101010101010101u * value;
    std::size_t i = 0;
    for (; i + 8 <= count; i += 8) {
        std::uint64_t w;
        std::memcpy(&w, bytes + i, 8);
        if (w != word) return false;
    }
    for (; i < count; ++i)
        if (bytes[i] != value) return false;
    return true;
}

// Reads a coded tile's vertex counts again one by one, and fails naming the
// first pixel over the reader's limit, a truncation, or the total that
// differs from the directory's.
[[noreturn]] void failVertexCounts(std::span<const std::uint8_t> raw, const TileSummary& summary,
                                   const TileShape& shape, const ReaderOptions& limits, const Fail& fail) {
    VarintReader r(raw.data(), raw.data() + raw.size());
    std::uint64_t total = 0;
    for (std::size_t p = 0; p < shape.pixels; ++p) {
        const std::uint32_t n = r.next();
        checkPixelVertices(n, p, shape, limits, fail);
        total += n;
        if (total > summary.vertexCount) break;  // reported below, before the sum can overflow
    }
    if (!r.ok()) fail("tile data is truncated in its vertex counts", ErrorCode::corrupt);
    fail(concat("pixel table holds ", total, total > summary.vertexCount ? " or more" : "", " vertices, the directory ",
                summary.vertexCount),
         ErrorCode::corrupt);
    throw Error(ErrorCode::internal, "vertex counts reported no fault");  // fail() throws
}

DecodedTile parseCodedTile(std::span<const std::uint8_t> raw, const TileSummary& summary, const TileShape& shape,
                           const TileLayout& layout, const ReaderOptions& limits, const Fail& fail,
                           DecodeChecks& checks) {
    const std::size_t pixels = shape.pixels;
    VarintReader r(raw.data(), raw.data() + raw.size());
    std::vector<PixelRecord> records(pixels + 1, PixelRecord{0, 0, 0, 1});
    // The counts' checks once for the tile; a tile that fails them is read
    // again count by count, to name what is wrong.
    std::uint64_t total = 0;
    std::uint32_t most = 0;
    PixelRecord* record = records.data();
    r.forEach(pixels, [&](std::size_t, std::uint32_t n) {
        total += n;
        most = std::max(most, n);
        (++record)->vertexStart = static_cast<std::uint32_t>(total);
    });
    if (!r.ok() || most > limits.maxVerticesPerPixel || total != summary.vertexCount)
        failVertexCounts(raw, summary, shape, limits, fail);
    std::uint64_t layerTotal = 0, valueTotal = 0;
    if (r.remaining() >= 2 * pixels) {
        const std::uint8_t* const flags = r.bytes(pixels);
        const std::uint8_t* layers = r.bytes(pixels);
        if (allBytesAre(flags, pixels, 0) && allBytesAre(layers, pixels, 1)) {
            // The common tile: monochrome pixels of one layer, a value a vertex.
            for (std::size_t p = 1; p <= pixels; ++p) records[p].valueStart = records[p].vertexStart;
            valueTotal = total;
        } else {
            for (std::size_t p = 0; p < pixels; ++p)
                if (flags[p] != 0) readPixelFlag(flags[p], records[p], p, shape, layout, fail);
            readLayerCounts([&] { return *layers++; }, records, shape, layout, fail, layerTotal, valueTotal);
        }
    } else {  // too short: byte by byte, a missing byte read as 0
        for (std::size_t p = 0; p < pixels; ++p)
            if (const std::uint8_t flags = r.byte(); flags != 0) readPixelFlag(flags, records[p], p, shape, layout, fail);
        readLayerCounts([&] { return r.byte(); }, records, shape, layout, fail, layerTotal, valueTotal);
        fail("tile data is truncated in its pixel table", ErrorCode::corrupt);
    }
    // Every integer still to come takes at least one byte: a check of the
    // totals against what is left bounds what is allocated by the raw size.
    const std::uint64_t integers = layerTotal + total + valueTotal + (layout.hasCounts ? total : 0);
    if (integers > r.remaining())
        fail(concat("tile holds ", raw.size(), " bytes, too few for the ", integers,
                    " integers its pixel table describes"),
             ErrorCode::corrupt);

    DecodedTile tile(shape.width, shape.height, summary.vertexCount, valueTotal, layerTotal, layout.hasCounts);
    std::copy(records.begin(), records.end(), tile.records());
    std::uint32_t* const layerStarts = tile.layerStarts();
    for (std::size_t p = 0; p < pixels && layerTotal > 0; ++p) {
        const std::uint32_t n = records[p + 1].vertexStart - records[p].vertexStart;
        std::uint32_t start = 0;
        for (std::uint32_t l = records[p].layerStart; l < records[p + 1].layerStart; ++l) {
            const std::uint32_t d = r.next();
            checks.suspect |= d == 0 || d >= n - start;  // not strictly inside (start, n)
            layerStarts[l] = start += d;
        }
    }
    if (layout.predictedDepths) decodePredictedDepths(r, records.data(), pixels, tile.depths(), checks);
    else decodeDepthsByPixel(r, records.data(), pixels, tile.depths(), checks);
    const double step = layout.valueStep;
    if (step == 0.0)
        decodeValues<false>(r, records.data(), pixels, layerStarts, tile.values(), std::bit_cast<std::uint32_t>(1.0f),
                            0.0f, checks.suspect);
    else  // a power of two: the float and the key of 1 are exact
        decodeValues<true>(r, records.data(), pixels, layerStarts, tile.values(),
                           static_cast<std::uint32_t>(1.0 / step), static_cast<float>(step), checks.suspect);
    if (layout.hasCounts) {
        std::uint32_t* const counts = tile.counts();
        r.forEach(summary.vertexCount, [&](std::size_t i, std::uint32_t count) { counts[i] = count; });
    }
    if (!r.ok()) fail("tile data is truncated", ErrorCode::corrupt);
    if (!r.atEnd())
        fail(concat("tile holds ", r.remaining(), " bytes after what its pixel table describes"), ErrorCode::corrupt);
    return tile;
}

// Checks every function of a tile (VisibilityView::validate) and gathers
// the depth range and the non-empty pixels.
DecodeChecks checkFunctions(const DecodedTile& tile, const TileShape& shape, const Fail& fail) {
    DecodeChecks checks;
    float minZ = std::numeric_limits<float>::infinity(), maxZ = -std::numeric_limits<float>::infinity();
    for (std::size_t p = 0; p < shape.pixels; ++p) {
        const VisibilityView view = tile.pixel(p);
        try {
            view.validate();
        } catch (const Error& e) {
            fail(concat(shape.pixelAt(p), ": ", e.what()), ErrorCode::corrupt);
        }
        if (!view.empty()) {
            ++checks.nonEmptyPixels;
            minZ = std::min(minZ, view.z(0));
            maxZ = std::max(maxZ, view.z(view.size() - 1));
        }
    }
    checks.minBits = std::bit_cast<std::uint32_t>(minZ);
    checks.maxBits = std::bit_cast<std::uint32_t>(maxZ);
    return checks;
}

// zlib's uncompress() into `out`, without the Adler-32 of the inflated bytes
// (the tile's CRC-32, checked before, covers the stored ones): a ninth of
// inflate's work. The same results otherwise, `size` the bytes written.
int inflateWithoutAdler(std::uint8_t* out, std::size_t outSize, std::span<const std::uint8_t> in, std::size_t& size) {
    z_stream z{};
    int rc = inflateInit(&z);
    if (rc != Z_OK) return rc;
    inflateValidate(&z, 0);
    z.next_in = const_cast<Bytef*>(in.data());
    z.avail_in = static_cast<uInt>(in.size());
    z.next_out = out;
    z.avail_out = static_cast<uInt>(outSize);
    do rc = inflate(&z, Z_NO_FLUSH);
    while (rc == Z_OK);
    size = z.total_out;
    inflateEnd(&z);
    if (rc == Z_STREAM_END) return Z_OK;
    if (rc == Z_NEED_DICT || (rc == Z_BUF_ERROR && z.avail_out > 0)) return Z_DATA_ERROR;
    return rc;
}

struct ZstdDecompressionTraits {
    static ZSTD_DCtx* make() { return ZSTD_createDCtx(); }
    static void destroy(ZSTD_DCtx* context) { ZSTD_freeDCtx(context); }
};

// ZSTD_decompress()'s result, with a context kept from an earlier tile
// (ZSTD_decompress() sets one up each call, about the cost of decompressing
// a small tile).
std::size_t zstdDecompress(void* out, std::size_t outSize, const void* in, std::size_t inSize) {
    static detail::KeptObjects<ZSTD_DCtx, ZstdDecompressionTraits> kept;
    const decltype(kept)::Lease context(kept);
    if (!context.get()) return ZSTD_decompress(out, outSize, in, inSize);  // out of memory for one
    return ZSTD_decompressDCtx(context.get(), out, outSize, in, inSize);
}

}  // namespace

DecodedTile decodeTile(std::span<const std::uint8_t> stored, const TileSummary& summary, std::uint32_t width,
                       std::uint32_t height, const TileLayout& layout, const ReaderOptions& limits,
                       const std::string& where, std::uint32_t originX, std::uint32_t originY) {
    const Fail fail = [&](const std::string& what, ErrorCode code) { throw Error(code, concat(where, ": ", what)); };
    const std::size_t pixels = static_cast<std::size_t>(width) * height;
    if (summary.empty()) return DecodedTile(width, height, 0, 0, 0, false);

    if (stored.size() != summary.storedBytes) fail("stored size does not match the directory", ErrorCode::corrupt);
    const std::uint32_t crc = crc32(stored.data(), stored.size());
    if (crc != summary.crc32)
        fail(concat("CRC-32 mismatch (stored ", summary.crc32, ", computed ", crc, ")"), ErrorCode::corrupt);
    if (summary.rawBytes > limits.maxTileBytes)
        fail(concat("tile of ", summary.rawBytes, " bytes exceeds the reader's limit ", limits.maxTileBytes),
             ErrorCode::limit);
    std::unique_ptr<std::uint8_t[]> inflated;  // not zeroed first: inflate writes all of it or fails
    std::span<const std::uint8_t> raw = stored;
    if (summary.storedBytes < summary.rawBytes && layout.codec == TileCodec::Zstd) {
        inflated.reset(new std::uint8_t[summary.rawBytes]);
        const std::size_t size = zstdDecompress(inflated.get(), summary.rawBytes, stored.data(), stored.size());
        if (ZSTD_isError(size))
            fail(concat("zstd cannot decompress the tile (", ZSTD_getErrorName(size), ")"), ErrorCode::corrupt);
        if (size != summary.rawBytes)
            fail(concat("tile decompresses to ", size, " bytes, not ", summary.rawBytes), ErrorCode::corrupt);
        raw = std::span<const std::uint8_t>(inflated.get(), summary.rawBytes);
    } else if (summary.storedBytes < summary.rawBytes) {
        inflated.reset(new std::uint8_t[summary.rawBytes]);
        std::size_t size = 0;
        const int rc = inflateWithoutAdler(inflated.get(), summary.rawBytes, stored, size);
        if (rc != Z_OK) fail(concat("zlib cannot inflate the tile (error ", rc, ")"), ErrorCode::corrupt);
        if (size != summary.rawBytes)
            fail(concat("tile inflates to ", size, " bytes, not ", summary.rawBytes), ErrorCode::corrupt);
        raw = std::span<const std::uint8_t>(inflated.get(), summary.rawBytes);
    } else if (summary.storedBytes > summary.rawBytes) {
        fail(concat("stored size ", summary.storedBytes, " exceeds the raw size ", summary.rawBytes), ErrorCode::corrupt);
    }

    const TileShape shape{width, height, pixels,
                          [&](std::size_t p) { return concat("pixel ", originX + p % width, ",", originY + p / width); }};
    DecodeChecks checks;
    DecodedTile tile = layout.coded ? parseCodedTile(raw, summary, shape, layout, limits, fail, checks)
                                    : parsePlainTile(raw, summary, shape, layout, limits, fail);
    if (!layout.coded || checks.suspect) checks = checkFunctions(tile, shape, fail);
    const float minZ = std::bit_cast<float>(checks.minBits), maxZ = std::bit_cast<float>(checks.maxBits);
    if (minZ != summary.minZ || maxZ != summary.maxZ)
        fail(concat("depth range [", minZ, ", ", maxZ, "] differs from the directory's [", summary.minZ, ", ",
                    summary.maxZ, "]"),
             ErrorCode::corrupt);
    if (checks.nonEmptyPixels != summary.nonEmptyPixels)
        fail(concat(checks.nonEmptyPixels, " non-empty pixels, the directory says ", summary.nonEmptyPixels),
             ErrorCode::corrupt);
    return tile;
}

}  // namespace dsm::format
