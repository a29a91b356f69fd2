#include "dsm/error.h"

#include <string_view>

#include "text.h"

DSM_NAMESPACE_BEGIN

const char* errorCodeName(ErrorCode code) noexcept {
    switch (code) {
    case ErrorCode::io: return "io";
    case ErrorCode::format: return "format";
    case ErrorCode::corrupt: return "corrupt";
    case ErrorCode::limit: return "limit";
    case ErrorCode::argument: return "argument";
    case ErrorCode::scene: return "scene";
    case ErrorCode::unsupported: return "unsupported";
    case ErrorCode::internal: return "internal";
    }
    return "internal";
}

namespace {

constexpr std::size_t kNoFile = std::string_view::npos;

/// Where the detail of `message` starts when it names `file` as the
/// constructor's precondition says, else kNoFile. Messages quote a long or
/// odd path clipped (detail::clip), so that form is accepted too.
std::size_t detailStart(std::string_view message, const std::string& file) {
    const std::string exact = "'" + file + "'";
    const std::string clipped = detail::quotedPath(file);
    for (const std::string* quoted : {&exact, &clipped}) {
        const std::size_t at = message.find(*quoted);
        // At the start, or after a lead-in that says what the file is ("scene ",
        // "hair file "): words without a quote or a colon.
        if (at == kNoFile || message.substr(0, at).find_first_of("':") != kNoFile) continue;
        std::size_t end = at + quoted->size();
        if (message.substr(end, 2) == ": ") end += 2;
        else if (message.substr(end, 1) == " ") end += 1;
        return end;
    }
    return kNoFile;
}

}  // namespace

Error::Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}

Error::Error(ErrorCode code, const std::string& message, const std::string& file)
    : std::runtime_error(message), code_(code) {
    if (file.empty()) return;
    file_ = std::make_shared<const std::string>(file);
    const std::size_t start = detailStart(message, file);
    if (start != kNoFile) detailOffset_ = start;
}

const std::string& Error::file() const noexcept {
    static const std::string none;
    return file_ ? *file_ : none;
}

Error Error::withFile(const std::string& file) const {
    if (file.empty() || detailStart(what(), file) == kNoFile) return *this;
    return Error(code_, what(), file);
}

DSM_NAMESPACE_END
