// The one exception type that crosses libdsm's API.
#pragma once

#include <stdexcept>
#include <string>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// What kind of failure a dsm::Error reports. Tools choose their exit status
/// and the C API its dsm_result from this code, never from the message text.
enum class ErrorCode {
    io,           ///< a file could not be opened, read, written, renamed or synced
    format,       ///< not a deep shadow map (or not the expected kind of file) at all
    corrupt,      ///< a map or image whose bytes contradict the format
    limit,        ///< an input exceeds a documented limit (size, nesting, memory)
    argument,     ///< a caller passed a value outside the documented range
    scene,        ///< a scene description is invalid (the message names its JSON pointer)
    unsupported,  ///< a valid input that this version cannot handle (newer format, feature)
    internal,     ///< a broken invariant inside libdsm: a bug to report
};

/// The code's name as printed in messages and documentation ("io", "corrupt", ...).
DSM_API const char* errorCodeName(ErrorCode code) noexcept;

/// Every failure inside libdsm is reported by throwing dsm::Error. The message
/// is one line and names what is wrong and where: the file, mip level, tile,
/// pixel, vertex index, JSON pointer or input line, whichever are known.
/// Thread safety: as std::runtime_error (immutable; const members from any thread).
class DSM_API Error : public std::runtime_error {
public:
    Error(ErrorCode code, const std::string& message);

    ErrorCode code() const noexcept { return code_; }

private:
    ErrorCode code_;
};

DSM_NAMESPACE_END
