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

// Section sizes written by this version; readers accept larger ones (a newer
// minor version appended fields) and read the fields they know.
inline constexpr std::uint32_t kHeaderSize = 272;
inline constexpr std::uint32_t kLevelEntrySize = 72;
inline constexpr std::uint32_t kTileEntrySize = 40;
inline constexpr std::uint32_t kHeaderCrcOffset = 228;

// Required flags: a reader that does not know a set bit must refuse the file.
inline constexpr std::uint32_t kRequiredHasCounts = 1u << 0;
inline constexpr std::uint32_t kRequiredHasLayers = 1u << 1;
inline constexpr std::uint32_t kKnownRequiredFlags = kRequiredHasCounts | kRequiredHasLayers;

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
};

struct LevelEntry {
    LevelInfo info;
    std::uint64_t directoryOffset = 0;
    std::uint32_t directoryCrc = 0;
};

/// Encodes the header into exactly kHeaderSize bytes, CRC included.
std::vector<std::uint8_t> encodeHeader(const Header& header);
/// Decodes and checks a header from the first bytes of a file of `fileSize`
/// bytes. Throws dsm::Error (prefixed with `where`) for anything that does not
/// fit: magic, version, required flags, CRC, sizes, field ranges, limits.
Header decodeHeader(const std::uint8_t* data, std::size_t available, std::uint64_t fileSize,
                    const ReaderOptions& limits, const std::string& where);

void encodeLevelEntry(std::vector<std::uint8_t>& out, const LevelEntry& entry);
LevelEntry decodeLevelEntry(const std::uint8_t* data);  // kLevelEntrySize bytes

void encodeTileEntry(std::vector<std::uint8_t>& out, const TileSummary& entry);
TileSummary decodeTileEntry(const std::uint8_t* data);  // kTileEntrySize bytes

/// CRC-32 (zlib's polynomial) of a byte range.
std::uint32_t crc32(const std::uint8_t* data, std::size_t size);

/// Header fields <-> MapInfo.
Header headerFromInfo(const MapInfo& info);
void infoFromHeader(const Header& header, MapInfo& info);

}  // namespace dsm::format
