// Helpers shared by the deep OpenEXR import and export (internal).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <ImfHeader.h>

#include "dsm/error.h"
#include "dsm/exr_deep.h"
#include "text.h"

DSM_NAMESPACE_BEGIN
namespace exr {

/// Largest display or data window side, in pixels: the largest map.
inline constexpr std::uint32_t kMaxExrExtent = 1u << 17;
inline constexpr std::uint64_t kMaxSamplesPerPixel = 1u << 24;
/// Most pixels in one tile of a tiled file. OpenEXR 3.1 accepts a deep
/// tile whose sample-count table (width x height x 4 bytes) fits 32 unsigned
/// bits but then sizes that table through an int, so tiles of 2^29 to 2^30
/// pixels would ask it for a negative size.
inline constexpr std::uint64_t kMaxExrTilePixels = 1u << 24;
/// Most samples decoded at once (one read of tiles or scanlines).
inline constexpr std::uint64_t kMaxSamplesPerBand = 1ull << 27;

/// Text from a file (attribute, part and channel names, OpenEXR's messages)
/// made fit for a one-line, UTF-8 message: valid UTF-8 is kept, control
/// characters and bytes that are not valid UTF-8 become \xNN escapes, and
/// long text is cut (detail::clip()).
std::string safeText(std::string_view text, std::size_t limit = detail::kMaxQuotedPath);

/// `path` in single quotes, made safe (safeText()).
std::string quoted(const std::string& path);

/// OpenEXR's message for a failure on `path`, without the file name it
/// repeats (the caller names the file once) and made safe.
std::string openExrMessage(const std::string& path, const std::string& what);

/// A maxDeviation or maxLinearError option: unset for the default, else in
/// [kMinExrErrorBound, 1] (NaN refused).
void checkErrorBoundOption(std::optional<double> value, const char* what);

template <class T>
const T* findAttribute(const Imf::Header& h, const char* name) {
    return h.findTypedAttribute<T>(name);
}

}  // namespace exr
DSM_NAMESPACE_END
