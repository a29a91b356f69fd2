// The on-disk structures of .dsm version 1 (internal). spec/dsm-format.md is
// the authority; this file mirrors its tables.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/reader.h"
#include "dsm/version.h"

namespace dsm::format {

inline constexpr std::array<std::uint8_t, 8> kMagic{0x89, 'D', 'S', 'M', 0x0D, 0x0A, 0x1A, 0x0A};

// Section sizes of version 1.0 (the least a reader accepts) and 1.1; readers
// accept larger ones (a newer minor version appended fields) and read the
// fields they know.
inline constexpr std::uint32_t kHeaderSize = 272;
inline constexpr std::uint32_t kLevelEntrySize = 72;
inline constexpr std::uint32_t kHeaderSize11 = 296;
inline constexpr std::uint32_t kLevelEntrySize11 = 80;
inline constexpr std::uint32_t kTileEntrySize = 40;
/// Header and level entry sizes a file of this minor version has.
inline std::uint32_t headerSizeOf(std::uint16_t minor) { return minor >= 1 ? kHeaderSize11 : kHeaderSize; }
inline std::uint32_t levelEntrySizeOf(std::uint16_t minor) { return minor >= 1 ? kLevelEntrySize11 : kLevelEntrySize; }
inline constexpr std::uint32_t kHeaderCrcOffset = 228;

// Required flags: a reader that does not know a set bit must refuse the file.
inline constexpr std::uint32_t kRequiredHasCounts = 1u << 0;
inline constexpr std::uint32_t kRequiredHasLayers = 1u << 1;
inline constexpr std::uint32_t kRequiredCodedTiles = 1u << 2;  // 1.1
inline constexpr std::uint32_t kRequiredPredictedDepths = 1u << 3;  // 1.1, with coded tiles
inline constexpr std::uint32_t kKnownRequiredFlags =
    kRequiredHasCounts | kRequiredHasLayers | kRequiredCodedTiles | kRequiredPredictedDepths;
/// Each required flag and its name in the spec, lowest bit first.
struct NamedFlag {
    std::uint32_t bit;
    const char* name;
};
inline constexpr NamedFlag kRequiredFlagNames[] = {{kRequiredHasCounts, "HAS_COUNTS"},
                                                   {kRequiredHasLayers, "HAS_LAYERS"},
                                                   {kRequiredCodedTiles, "CODED_TILES"},
                                                   {kRequiredPredictedDepths, "PREDICTED_DEPTHS"}};
/// The required flags of a file that `info` describes.
std::uint32_t requiredFlagsOf(const MapInfo& info);

// Tile codecs (header field `codec`, 1.1) and their level ranges.
inline constexpr std::uint8_t kCodecZlib = 0;
inline constexpr std::uint8_t kCodecZstd = 1;
inline constexpr int kMaxZlibLevel = 9;
inline constexpr int kMaxZstdLevel = 22;

// The finest value step a level may record: 2^-24.
inline constexpr int kFinestValueStepExponent = 24;

// Per-pixel flag bits in a tile's pixel table.
inline constexpr std::uint8_t kPixelRgb = 1u << 0;
inline constexpr std::uint8_t kKnownPixelFlags = kPixelRgb;

inline constexpr unsigned kMaxLevels = 32;
inline constexpr std::uint32_t kMinTileSize = 2;
inline constexpr std::uint32_t kMaxTileSize = 4096;

/// The fixed header (byte offsets in the spec's table).
struct Header {
    std::uint16_t versionMajor = kFormatVersionMajor;
    std::uint16_t versionMinor = kFormatVersionMinor;
    std::uint32_t headerSize = kHeaderSize;
    std::uint32_t requiredFlags = 0;
    std::uint32_t optionalFlags = 0;
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    std::uint32_t tileSize = 0;
    std::uint8_t channels = 1;
    std::uint8_t maxLayers = 1;
    std::uint8_t filter = 0;
    std::uint8_t projection = 0;
    double filterWidth = 1.0;
    std::array<double, 16> worldToLight{};
    std::array<double, 4> screenWindow{};
    double nearPlane = 0.0;
    std::uint32_t levelCount = 0;
    std::uint32_t levelEntrySize = kLevelEntrySize;
    std::uint32_t tileEntrySize = kTileEntrySize;
    std::uint32_t headerCrc = 0;
    std::uint64_t levelTableOffset = 0;
    std::uint64_t metadataOffset = 0;
    std::uint64_t metadataSize = 0;
    std::uint32_t levelTableCrc = 0;
    std::uint32_t metadataCrc = 0;
    std::uint64_t fileSize = 0;
    // Appended in 1.1.
    std::uint8_t codec = kCodecZlib;
    std::uint8_t codecLevel = 0;
    double areaLightRadius = 0.0;
    double areaLightPlaneDepth = 0.0;
};

struct LevelEntry {
    LevelInfo info;
    std::uint64_t directoryOffset = 0;
    std::uint32_t directoryCrc = 0;
};

/// Encodes the header into exactly headerSizeOf(versionMinor) bytes, CRC included.
std::vector<std::uint8_t> encodeHeader(const Header& header);
/// Decodes and checks a header from the first bytes of a file of `fileSize`
/// bytes. Throws dsm::Error (prefixed with `where`) for anything that does not
/// fit: magic, version, required flags, CRC, sizes, field ranges, limits.
Header decodeHeader(const std::uint8_t* data, std::size_t available, std::uint64_t fileSize,
                    const ReaderOptions& limits, const std::string& where);

/// levelEntrySizeOf(minor) bytes.
void encodeLevelEntry(std::vector<std::uint8_t>& out, const LevelEntry& entry, std::uint16_t minor);
/// `size` bytes (the header's levelEntrySize); the value step is read when
/// they hold it (1.1).
LevelEntry decodeLevelEntry(const std::uint8_t* data, std::uint32_t size);

void encodeTileEntry(std::vector<std::uint8_t>& out, const TileSummary& entry);
TileSummary decodeTileEntry(const std::uint8_t* data);  // kTileEntrySize bytes

/// CRC-32 (zlib's polynomial) of a byte range.
std::uint32_t crc32(const std::uint8_t* data, std::size_t size);

/// Header fields <-> MapInfo. headerFromInfo writes `minor`'s fields.
Header headerFromInfo(const MapInfo& info, std::uint16_t minor);
void infoFromHeader(const Header& header, MapInfo& info);

}  // namespace dsm::format
