// Checks of an OpenEXR file's headers before OpenEXR reads them (internal;
// spec/exr-interop.md "Limits").
#include "exr_header_check.h"

#include <cstring>
#include <fstream>
#include <utility>

#include "dsm/error.h"
#include "exr_common.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using exr::quoted;
using exr::safeText;

namespace {

/// The value size OpenEXR 3.1 reads for an attribute type whatever size the
/// file records, or 0 for a type read by its content or its recorded size.
std::uint32_t fixedExrAttributeSize(const std::string& type) {
    static const std::pair<const char*, std::uint32_t> kSizes[] = {
        {"box2f", 16},   {"box2i", 16},          {"chromaticities", 32}, {"compression", 1}, {"deepImageState", 1},
        {"double", 8},   {"envmap", 1},          {"float", 4},           {"int", 4},         {"keycode", 28},
        {"lineOrder", 1}, {"m33d", 72},          {"m33f", 36},           {"m44d", 128},      {"m44f", 64},
        {"rational", 8}, {"tiledesc", 9},        {"timecode", 8},        {"v2d", 16},        {"v2f", 8},
        {"v2i", 8},      {"v3d", 24},            {"v3f", 12},            {"v3i", 12}};
    for (const auto& [name, size] : kSizes)
        if (type == name) return size;
    return 0;
}

std::uint32_t littleEndian32(const std::string& bytes, std::size_t at) {
    std::uint32_t v = 0;
    for (std::size_t i = 0; i < 4; ++i) v |= std::uint32_t(std::uint8_t(bytes[at + i])) << (8 * i);
    return v;
}

/// Why OpenEXR 3.1 would read a different number of bytes than `value` (an
/// attribute of type `type`, as recorded) holds, or "" when it reads exactly
/// those: the types it reads by their content must fill their recorded size.
std::string exrAttributeDisagreement(const std::string& type, const std::string& value) {
    const std::size_t size = value.size();
    if (type == "chlist") {
        // name\0 (1 to 255 bytes), 16 bytes of channel, ..., then an empty name.
        for (std::size_t at = 0;;) {
            const std::size_t end = value.find('\0', at);
            if (end == std::string::npos || end - at > 255)
                return "its channel list does not end within them";
            if (end == at) {
                if (end + 1 == size) return "";
                return concat("its channel list ends after ", end + 1);
            }
            at = end + 1 + 16;
            if (at > size) return "its channel list does not end within them";
        }
    }
    if (type == "stringvector") {
        // int32 length + bytes, repeated until the recorded size is read.
        for (std::size_t at = 0; at < size;) {
            if (size - at < 4) return "its strings do not fill them";
            const std::uint32_t length = littleEndian32(value, at);
            at += 4;
            if (length > size - at) return "a string in it runs past them";
            at += length;
        }
        return "";
    }
    if (type == "floatvector") return size % 4 == 0 ? "" : "that is not a whole number of floats";
    if (type == "preview") {
        if (size < 8) return "a preview needs at least 8 for its width and height";
        const std::uint64_t pixels = std::uint64_t(littleEndian32(value, 0)) * littleEndian32(value, 4);
        return pixels * 4 + 8 == size ? "" : concat("its preview image needs ", pixels * 4 + 8);
    }
    if (type == "idmanifest") return size >= 4 ? "" : "an idmanifest needs at least 4 for its size field";
    return "";
}

/// Reads the attribute list of every header of an OpenEXR file without
/// OpenEXR and refuses a size no file of this length can hold. OpenEXR 3.1
/// allocates the size an attribute claims before reading it, so a few damaged
/// bytes would otherwise cost gigabytes. The layout (magic, version, then
/// name\0 type\0 int32-size value ..., a header ending in an empty name,
/// and multi-part files ending their headers with one more) is OpenEXR's
/// documented file layout. OpenEXR reads fixed-size types and channel lists
/// by their content, not by the recorded size; an attribute whose content
/// disagrees with its size is refused too, since OpenEXR would read the rest
/// of the header out of step and meet sizes this walk never checked. Tiles
/// larger than kMaxExrTilePixels are refused before OpenEXR sizes a table
/// for them.
/// Anything else is left for OpenEXR to judge.
}  // namespace

void exr::checkExrHeaderSizes(const std::string& path, std::uint64_t fileSize) {
    std::ifstream in(path, std::ios::binary);
    std::uint8_t start[8];
    if (!in.read(reinterpret_cast<char*>(start), sizeof start)) return;
    if (start[0] != 0x76 || start[1] != 0x2f || start[2] != 0x31 || start[3] != 0x01) return;
    const bool multiPart = (start[5] & 0x10) != 0;  // version flag bit 12
    std::uint64_t offset = sizeof start;
    // A name or type longer than 255 bytes is invalid; OpenEXR reports it.
    const auto readName = [&](std::string& name) {
        name.clear();
        for (char c; in.get(c);) {
            ++offset;
            if (c == '\0') return true;
            if (name.size() == 255) return false;
            name.push_back(c);
        }
        return false;
    };
    std::string name, type, value;
    int part = 0;
    for (bool headerStart = true;;) {
        if (!readName(name)) return;
        if (name.empty()) {
            // An empty name ends a header; right at a header's start it ends a
            // multi-part file's list of headers.
            if (!multiPart || headerStart) return;
            headerStart = true;
            ++part;
            continue;
        }
        headerStart = false;
        if (!readName(type)) return;
        std::uint8_t size[4];
        if (!in.read(reinterpret_cast<char*>(size), sizeof size)) return;
        offset += sizeof size;
        const std::int32_t claimed = static_cast<std::int32_t>(std::uint32_t(size[0]) | std::uint32_t(size[1]) << 8 |
                                                               std::uint32_t(size[2]) << 16 |
                                                               std::uint32_t(size[3]) << 24);
        const std::string attribute =
            concat(quoted(path), ": ", multiPart ? concat("part ", part, " ") : std::string(), "header attribute '",
                   safeText(name), "' (", safeText(type), ")");
        if (claimed < 0 || std::uint64_t(claimed) > fileSize - offset)
            throw Error(ErrorCode::corrupt, concat(attribute, " claims ", claimed, " bytes but the file has ",
                                                   fileSize - offset, " bytes left"));
        if (const std::uint32_t fixed = fixedExrAttributeSize(type); fixed != 0 && std::uint32_t(claimed) != fixed)
            throw Error(ErrorCode::corrupt,
                        concat(attribute, " records ", claimed, " bytes but a ", type, " holds ", fixed));
        if (type == "tiledesc") {
            // xSize, ySize (unsigned int32), then the level and rounding modes.
            value.resize(std::size_t(claimed));
            if (!in.read(value.data(), claimed)) return;
            const std::uint64_t width = littleEndian32(value, 0), height = littleEndian32(value, 4);
            if (width * height > kMaxExrTilePixels)
                throw Error(ErrorCode::limit, concat(attribute, " describes ", width, " x ", height,
                                                     " pixel tiles; at most ", kMaxExrTilePixels,
                                                     " pixels in a tile are read"));
        }
        if (type == "chlist" || type == "stringvector" || type == "floatvector" || type == "preview" ||
            type == "idmanifest") {
            value.resize(std::size_t(claimed));
            if (!in.read(value.data(), claimed)) return;
            if (const std::string why = exrAttributeDisagreement(type, value); !why.empty())
                throw Error(ErrorCode::corrupt, concat(attribute, " records ", claimed, " bytes but ", why));
        }
        offset += std::uint64_t(claimed);
        if (!in.seekg(static_cast<std::streamoff>(offset))) return;
    }
}

/// Bounds OpenEXR's own allocations for every file it opens from now on: its
/// header check refuses data windows and tiles larger than a map can be.
void exr::limitOpenExrAllocations() {
    static const bool once = [] {
        Imf::Header::setMaxImageSize(int(kMaxExrExtent), int(kMaxExrExtent));
        Imf::Header::setMaxTileSize(int(kMaxExrExtent), int(kMaxExrExtent));
        return true;
    }();
    (void)once;
}

DSM_NAMESPACE_END
