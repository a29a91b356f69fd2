// Small helpers for building dsm::Error messages (internal).
#pragma once

#include <cstddef>
#include <cstdio>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>

namespace dsm::detail {

/// Concatenates its arguments with an ostream; floating-point values get 9
/// significant digits so the reported value round-trips a float exactly.
template <typename... Args>
std::string concat(Args&&... args) {
    std::ostringstream out;
    out.precision(9);
    (out << ... << std::forward<Args>(args));
    return out.str();
}

/// `v` with 17 significant digits, which tell any two doubles apart: for a
/// message about a double that concat()'s 9 digits would round onto the
/// limit it misses, or onto another map's value.
inline std::string exactNumber(double v) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.17g", v);
    return buffer;
}

/// Longest piece of user text (a key, a name, a file name, a JSON excerpt)
/// that a message quotes in full.
inline constexpr std::size_t kMaxQuotedChars = 80;
/// File names are quoted longer: real paths are long.
inline constexpr std::size_t kMaxQuotedPath = 4 * kMaxQuotedChars;

/// User text made fit to quote in a one-line message: control characters are
/// escaped (\n, \t, \xNN) and text longer than `limit` bytes is cut, at a
/// UTF-8 character boundary, and ends in "...". Every message that echoes
/// text from an input goes through here, so a 100 MB key gives a short line.
inline std::string clip(std::string_view text, std::size_t limit = kMaxQuotedChars) {
    static constexpr char kHex[] = "0123456789ABCDEF";
    std::string out;
    std::size_t i = 0;
    for (; i < text.size() && out.size() < limit; ++i) {
        const unsigned char c = static_cast<unsigned char>(text[i]);
        if (c == '\n') out += "\\n";
        else if (c == '\r') out += "\\r";
        else if (c == '\t') out += "\\t";
        else if (c < 0x20 || c == 0x7F) out += {'\\', 'x', kHex[c >> 4], kHex[c & 15]};
        else out += static_cast<char>(c);
    }
    if (i == text.size()) return out;
    // Cut before a partial UTF-8 sequence (continuation bytes are 10xxxxxx).
    std::size_t end = out.size();
    while (end > 0 && (static_cast<unsigned char>(out[end - 1]) & 0xC0) == 0x80) --end;
    if (end > 0 && (static_cast<unsigned char>(out[end - 1]) & 0xC0) == 0xC0) --end;
    else end = out.size();
    out.resize(end);
    return out + "...";
}

/// A file's path as messages quote it: clipped, between single quotes.
/// Appended piece by piece: GCC 12 at -O3 warns (-Wrestrict, a false
/// positive) about its own inlined "'" + std::string&&.
inline std::string quotedPath(std::string_view path) {
    std::string quoted = "'";
    quoted += clip(path, kMaxQuotedPath);
    quoted += '\'';
    return quoted;
}

}  // namespace dsm::detail
