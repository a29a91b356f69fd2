// Helpers shared by the deep OpenEXR import and export.
#include "exr_common.h"

#include <fstream>

DSM_NAMESPACE_BEGIN
namespace exr {

using detail::concat;

namespace {

/// Length of the valid UTF-8 sequence at text[i], or 0 when it is not one
/// (overlong forms, surrogates and code points above U+10FFFF included).
std::size_t utf8SequenceLength(std::string_view text, std::size_t i) {
    const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(text[k]); };
    const unsigned char c = byte(i);
    std::size_t length = 0;
    std::uint32_t min = 0, code = 0;
    if (c >= 0xC2 && c <= 0xDF) length = 2, min = 0x80, code = c & 0x1F;
    else if (c >= 0xE0 && c <= 0xEF) length = 3, min = 0x800, code = c & 0x0F;
    else if (c >= 0xF0 && c <= 0xF4) length = 4, min = 0x10000, code = c & 0x07;
    else return 0;
    if (i + length > text.size()) return 0;
    for (std::size_t k = 1; k < length; ++k) {
        if ((byte(i + k) & 0xC0) != 0x80) return 0;
        code = code << 6 | (byte(i + k) & 0x3F);
    }
    if (code < min || code > 0x10FFFF || (code >= 0xD800 && code <= 0xDFFF)) return 0;
    return length;
}

}  // namespace

std::string safeText(std::string_view text, std::size_t limit) {
    static constexpr char kHex[] = "0123456789ABCDEF";
    std::string out;
    for (std::size_t i = 0; i < text.size();) {
        const unsigned char c = static_cast<unsigned char>(text[i]);
        if (c < 0x80) {
            out += static_cast<char>(c);  // clip() escapes control characters
            ++i;
        } else if (const std::size_t n = utf8SequenceLength(text, i); n > 0) {
            out.append(text.substr(i, n));
            i += n;
        } else {
            out += {'\\', 'x', kHex[c >> 4], kHex[c & 15]};
            ++i;
        }
    }
    return detail::clip(out, limit);
}

std::string quoted(const std::string& path) { return concat("'", safeText(path), "'"); }

std::string openExrMessage(const std::string& path, const std::string& what) {
    std::string text = what;
    // OpenEXR says 'Cannot read image file "PATH". ...': the caller names the file.
    for (const std::string& form : {"image file \"" + path + "\"", "file \"" + path + "\"", "\"" + path + "\""})
        for (auto at = text.find(form); at != std::string::npos; at = text.find(form, at))
            text.replace(at, form.size(), "the file");
    while (!text.empty() && (text.back() == ' ' || text.back() == '\n')) text.pop_back();
    return safeText(text);
}

void checkErrorBoundOption(std::optional<double> value, const char* what) {
    if (!value) return;
    if (!(*value >= kMinExrErrorBound && *value <= 1.0))
        throw Error(ErrorCode::argument, concat(what, " ", *value, " is outside [", kMinExrErrorBound,
                                                ", 1] (float32 samples cannot keep a tighter bound)"));
}

}  // namespace exr

bool hasOpenExrMagic(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    unsigned char magic[4] = {0, 0, 0, 0};
    in.read(reinterpret_cast<char*>(magic), sizeof magic);
    return in && magic[0] == 0x76 && magic[1] == 0x2f && magic[2] == 0x31 && magic[3] == 0x01;
}

DSM_NAMESPACE_END
