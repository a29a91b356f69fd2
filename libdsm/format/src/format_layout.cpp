#include "format_layout.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "byte_io.h"
#include "dsm/error.h"
#include "dsm/names.h"
#include "text.h"

namespace dsm::format {

using detail::ByteReader;
using detail::ByteWriter;
using detail::concat;

std::vector<std::uint8_t> encodeHeader(const Header& h) {
    std::vector<std::uint8_t> out;
    const std::uint32_t size = headerSizeOf(h.versionMinor);
    out.reserve(size);
    ByteWriter w(out);
    for (std::uint8_t b : kMagic) w.u8(b);
    w.u16(h.versionMajor);
    w.u16(h.versionMinor);
    w.u32(size);
    w.u32(h.requiredFlags);
    w.u32(h.optionalFlags);
    w.u32(h.width);
    w.u32(h.height);
    w.u32(h.tileSize);
    w.u8(h.channels);
    w.u8(h.maxLayers);
    w.u8(h.filter);
    w.u8(h.projection);
    w.f64(h.filterWidth);
    for (double m : h.worldToLight) w.f64(m);
    for (double s : h.screenWindow) w.f64(s);
    w.f64(h.nearPlane);
    w.u32(h.levelCount);
    w.u32(levelEntrySizeOf(h.versionMinor));
    w.u32(kTileEntrySize);
    w.u32(0);  // header CRC, filled below
    w.u64(h.levelTableOffset);
    w.u64(h.metadataOffset);
    w.u64(h.metadataSize);
    w.u32(h.levelTableCrc);
    w.u32(h.metadataCrc);
    w.u64(h.fileSize);
    if (h.versionMinor >= 1) {
        w.u8(h.codec);
        w.u8(h.codecLevel);
        w.zeros(6);
        w.f64(h.areaLightRadius);
        w.f64(h.areaLightPlaneDepth);
    }
    const std::uint32_t crc = crc32(out.data(), out.size());
    for (int i = 0; i < 4; ++i) out[kHeaderCrcOffset + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(crc >> (8 * i));
    return out;
}

Header decodeHeader(const std::uint8_t* data, std::size_t available, std::uint64_t fileSize,
                    const ReaderOptions& limits, const std::string& where) {
    auto fail = [&](const std::string& what, ErrorCode code = ErrorCode::corrupt) {
        throw Error(code, concat(where, ": ", what));
    };
    if (available < kMagic.size() || std::memcmp(data, kMagic.data(), kMagic.size()) != 0)
        fail("not a deep shadow map (bad magic bytes)", ErrorCode::format);
    if (available < 16) fail(concat("file of ", fileSize, " bytes is too short for a header"));
    ByteReader r(data, available);
    r.skip(kMagic.size());
    Header h;
    h.versionMajor = r.u16();
    h.versionMinor = r.u16();
    if (h.versionMajor != kFormatVersionMajor)
        fail(concat("format version ", h.versionMajor, ".", h.versionMinor, " is not supported (this reader reads ",
                    kFormatVersionMajor, ".x)"),
             ErrorCode::unsupported);
    h.headerSize = r.u32();
    if (h.headerSize < kHeaderSize) fail(concat("header size ", h.headerSize, " is below the minimum ", kHeaderSize));
    if (h.headerSize > fileSize || h.headerSize > available)
        fail(concat("header size ", h.headerSize, " exceeds the file size ", fileSize));
    {
        std::vector<std::uint8_t> copy(data, data + h.headerSize);
        const std::uint32_t stored = static_cast<std::uint32_t>(copy[kHeaderCrcOffset]) |
                                     static_cast<std::uint32_t>(copy[kHeaderCrcOffset + 1]) << 8 |
                                     static_cast<std::uint32_t>(copy[kHeaderCrcOffset + 2]) << 16 |
                                     static_cast<std::uint32_t>(copy[kHeaderCrcOffset + 3]) << 24;
        std::memset(copy.data() + kHeaderCrcOffset, 0, 4);
        const std::uint32_t actual = crc32(copy.data(), copy.size());
        if (stored != actual) fail(concat("header CRC-32 mismatch (stored ", stored, ", computed ", actual, ")"));
    }
    h.requiredFlags = r.u32();
    h.optionalFlags = r.u32();
    if (h.requiredFlags & ~kKnownRequiredFlags)
        fail(concat("unknown required flags 0x", std::hex, h.requiredFlags & ~kKnownRequiredFlags),
             ErrorCode::unsupported);
    h.width = r.u32();
    h.height = r.u32();
    h.tileSize = r.u32();
    h.channels = r.u8();
    h.maxLayers = r.u8();
    h.filter = r.u8();
    h.projection = r.u8();
    h.filterWidth = r.f64();
    for (double& m : h.worldToLight) m = r.f64();
    for (double& s : h.screenWindow) s = r.f64();
    h.nearPlane = r.f64();
    h.levelCount = r.u32();
    h.levelEntrySize = r.u32();
    h.tileEntrySize = r.u32();
    h.headerCrc = r.u32();
    h.levelTableOffset = r.u64();
    h.metadataOffset = r.u64();
    h.metadataSize = r.u64();
    h.levelTableCrc = r.u32();
    h.metadataCrc = r.u32();
    h.fileSize = r.u64();
    if (h.headerSize >= kHeaderSize11) {
        h.codec = r.u8();
        h.codecLevel = r.u8();
        r.skip(6);
        h.areaLightRadius = r.f64();
        h.areaLightPlaneDepth = r.f64();
    }
    if (!r.ok()) fail("header is truncated");

    if (h.versionMinor >= 1 && h.headerSize < kHeaderSize11)
        fail(concat("header size ", h.headerSize, " is below the ", kHeaderSize11, " of version 1.", h.versionMinor));
    if ((h.requiredFlags & kRequiredCodedTiles) && h.versionMinor < 1)
        fail(concat("coded tiles flag in a version 1.", h.versionMinor, " file"));
    if ((h.requiredFlags & kRequiredPredictedDepths) && !(h.requiredFlags & kRequiredCodedTiles))
        fail("predicted depths flag without the coded tiles flag");
    if (h.codec != kCodecZlib && h.codec != kCodecZstd)
        fail(concat("unknown tile codec ", int(h.codec)), ErrorCode::unsupported);
    if (h.codec == kCodecZlib && h.codecLevel > kMaxZlibLevel)
        fail(concat("zlib level ", int(h.codecLevel), " is not in [0, ", kMaxZlibLevel, "]"));
    if (h.codec == kCodecZstd && h.codecLevel > kMaxZstdLevel)
        fail(concat("zstd level ", int(h.codecLevel), " is not in [0, ", kMaxZstdLevel, "]"));
    if (!std::isfinite(h.areaLightRadius) || h.areaLightRadius < 0.0 || !std::isfinite(h.areaLightPlaneDepth) ||
        h.areaLightPlaneDepth < 0.0)
        fail(concat("area light radius ", h.areaLightRadius, " or plane depth ", h.areaLightPlaneDepth,
                    " is not a finite value >= 0"));

    if (h.fileSize != fileSize)
        fail(concat("file is ", fileSize, " bytes but its header records ", h.fileSize, " (truncated or extended)"));
    if (h.width == 0 || h.height == 0) fail(concat("image size ", h.width, "x", h.height, " is empty"));
    if (h.width > limits.maxWidth || h.height > limits.maxHeight)
        fail(concat("image size ", h.width, "x", h.height, " exceeds the reader's limit ", limits.maxWidth, "x",
                    limits.maxHeight),
             ErrorCode::limit);
    if (h.tileSize < kMinTileSize || h.tileSize > kMaxTileSize || !std::has_single_bit(h.tileSize))
        fail(concat("tile size ", h.tileSize, " is not a power of two from ", kMinTileSize, " to ", kMaxTileSize));
    if (h.channels != 1 && h.channels != 3) fail(concat("channel count ", int(h.channels), " is not 1 or 3"));
    if (h.maxLayers < 1) fail("layer count 0 (must be at least 1)");
    if (((h.requiredFlags & kRequiredHasLayers) != 0) != (h.maxLayers > 1))
        fail(concat("layer flag does not match the layer count ", int(h.maxLayers)));
    if (h.filter > 2) fail(concat("unknown pixel filter ", int(h.filter)));
    if (h.projection > 1) fail(concat("unknown projection ", int(h.projection)));
    if (!std::isfinite(h.filterWidth) || h.filterWidth < 0.0) fail(concat("filter width ", h.filterWidth, " is invalid"));
    if (h.levelCount < 1 || h.levelCount > fullLevelCount(h.width, h.height))
        fail(concat("level count ", h.levelCount, " is not in [1, ", fullLevelCount(h.width, h.height), "]"));
    if (h.levelEntrySize < levelEntrySizeOf(h.versionMinor) || h.levelEntrySize > (1u << 16))
        fail(concat("level entry size ", h.levelEntrySize, " is invalid"));
    if (h.tileEntrySize < kTileEntrySize || h.tileEntrySize > (1u << 16))
        fail(concat("tile entry size ", h.tileEntrySize, " is invalid"));
    const std::uint64_t levelTableBytes = std::uint64_t(h.levelCount) * h.levelEntrySize;
    if (h.levelTableOffset < h.headerSize || h.levelTableOffset > fileSize ||
        levelTableBytes > fileSize - h.levelTableOffset)
        fail(concat("level table at ", h.levelTableOffset, " (", levelTableBytes, " bytes) does not fit in the file"));
    if (h.metadataSize > limits.maxMetadataBytes)
        fail(concat("metadata of ", h.metadataSize, " bytes exceeds the reader's limit ", limits.maxMetadataBytes),
             ErrorCode::limit);
    if (h.metadataOffset < h.headerSize || h.metadataOffset > fileSize || h.metadataSize > fileSize - h.metadataOffset)
        fail(concat("metadata at ", h.metadataOffset, " (", h.metadataSize, " bytes) does not fit in the file"));
    return h;
}

void encodeLevelEntry(std::vector<std::uint8_t>& out, const LevelEntry& e, std::uint16_t minor) {
    ByteWriter w(out);
    w.u32(e.info.width);
    w.u32(e.info.height);
    w.u32(e.info.tilesX);
    w.u32(e.info.tilesY);
    w.f64(e.info.tolerance);
    w.f64(e.info.errorBound);
    w.u64(e.directoryOffset);
    w.u64(e.info.vertexCount);
    w.u64(e.info.nonEmptyPixels);
    w.u64(e.info.storedBytes);
    w.u32(e.directoryCrc);
    w.u32(0);
    if (minor >= 1) w.f64(e.info.valueStep);
}

LevelEntry decodeLevelEntry(const std::uint8_t* data, std::uint32_t size) {
    ByteReader r(data, size);
    LevelEntry e;
    e.info.width = r.u32();
    e.info.height = r.u32();
    e.info.tilesX = r.u32();
    e.info.tilesY = r.u32();
    e.info.tolerance = r.f64();
    e.info.errorBound = r.f64();
    e.directoryOffset = r.u64();
    e.info.vertexCount = r.u64();
    e.info.nonEmptyPixels = r.u64();
    e.info.storedBytes = r.u64();
    e.directoryCrc = r.u32();
    if (size >= kLevelEntrySize11) {
        r.skip(4);
        e.info.valueStep = r.f64();
    }
    return e;
}

void encodeTileEntry(std::vector<std::uint8_t>& out, const TileSummary& t) {
    ByteWriter w(out);
    w.u64(t.offset);
    w.u32(t.storedBytes);
    w.u32(t.rawBytes);
    w.u32(t.crc32);
    w.u32(t.vertexCount);
    w.f32(t.minZ);
    w.f32(t.maxZ);
    w.u32(t.nonEmptyPixels);
    w.u32(0);
}

TileSummary decodeTileEntry(const std::uint8_t* data) {
    ByteReader r(data, kTileEntrySize);
    TileSummary t;
    t.offset = r.u64();
    t.storedBytes = r.u32();
    t.rawBytes = r.u32();
    t.crc32 = r.u32();
    t.vertexCount = r.u32();
    t.minZ = r.f32();
    t.maxZ = r.f32();
    t.nonEmptyPixels = r.u32();
    return t;
}

std::uint32_t requiredFlagsOf(const MapInfo& info) {
    return (info.hasCounts ? kRequiredHasCounts : 0u) | (info.maxLayers > 1 ? kRequiredHasLayers : 0u) |
           (info.codedTiles ? kRequiredCodedTiles : 0u) |
           (info.codedTiles && info.predictedDepths ? kRequiredPredictedDepths : 0u);
}

Header headerFromInfo(const MapInfo& info, std::uint16_t minor) {
    Header h;
    h.versionMinor = minor;
    h.width = info.width;
    h.height = info.height;
    h.tileSize = info.tileSize;
    h.channels = static_cast<std::uint8_t>(info.channels);
    h.maxLayers = static_cast<std::uint8_t>(info.maxLayers);
    h.requiredFlags = requiredFlagsOf(info);
    h.codec = static_cast<std::uint8_t>(info.codec);
    h.codecLevel = static_cast<std::uint8_t>(std::max(info.codecLevel, 0));
    h.areaLightRadius = info.areaLightRadius;
    h.areaLightPlaneDepth = info.areaLightPlaneDepth;
    h.filter = static_cast<std::uint8_t>(info.filter);
    h.projection = static_cast<std::uint8_t>(info.camera.projection);
    h.filterWidth = info.filterWidth;
    h.worldToLight = info.camera.worldToLight;
    h.screenWindow = info.camera.screenWindow;
    h.nearPlane = info.camera.nearPlane;
    h.levelCount = static_cast<std::uint32_t>(info.levels.size());
    return h;
}

void infoFromHeader(const Header& h, MapInfo& info) {
    info.versionMajor = h.versionMajor;
    info.versionMinor = h.versionMinor;
    info.width = h.width;
    info.height = h.height;
    info.tileSize = h.tileSize;
    info.channels = h.channels;
    info.hasCounts = (h.requiredFlags & kRequiredHasCounts) != 0;
    info.maxLayers = h.maxLayers;
    info.filter = static_cast<PixelFilter>(h.filter);
    info.filterWidth = h.filterWidth;
    info.camera.projection = static_cast<Projection>(h.projection);
    info.camera.worldToLight = h.worldToLight;
    info.camera.screenWindow = h.screenWindow;
    info.camera.nearPlane = h.nearPlane;
    info.fileBytes = h.fileSize;
    info.codedTiles = (h.requiredFlags & kRequiredCodedTiles) != 0;
    info.predictedDepths = (h.requiredFlags & kRequiredPredictedDepths) != 0;
    info.codec = static_cast<TileCodec>(h.codec);
    info.codecLevel = h.headerSize >= kHeaderSize11 ? h.codecLevel : -1;
    info.areaLightRadius = h.areaLightRadius;
    info.areaLightPlaneDepth = h.areaLightPlaneDepth;
}

}  // namespace dsm::format

DSM_NAMESPACE_BEGIN

// Declared in dsm/names.h; here beside the flags' bits (a reader refuses
// unknown flags and HAS_LAYERS that disagrees with maxLayers, so the flags
// follow from MapInfo).
std::vector<std::string> requiredFlagNames(const MapInfo& info) {
    const std::uint32_t flags = format::requiredFlagsOf(info);
    std::vector<std::string> names;
    for (const format::NamedFlag& f : format::kRequiredFlagNames)
        if (flags & f.bit) names.emplace_back(f.name);
    return names;
}

DSM_NAMESPACE_END
