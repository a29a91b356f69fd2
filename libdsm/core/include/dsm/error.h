// The one exception type that crosses libdsm's API.
#pragma once

#include <cstddef>
#include <memory>
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
///
/// An error about a file also carries that file: file() is the path as the
/// caller gave it to libdsm (or the name given with a MapInput or a scene
/// stream), and detail() is the message without the quoted file at its start.
/// A program that shows files under other names (standard input read through a
/// temporary copy, say) prints its own name for file() followed by detail(),
/// and never parses the message. An error that concerns several files (two
/// maps that cannot be merged) carries the one its message starts with.
/// Thread safety: as std::runtime_error (immutable; const members from any thread).
class DSM_API Error : public std::runtime_error {
public:
    /// An error that names no file: file() is empty and detail() is the message.
    Error(ErrorCode code, const std::string& message);
    /// An error about `file`. Precondition: `message` starts with the file
    /// quoted as messages quote it ("'a.dsm': ...", "'a.dsm' level 1 tile
    /// 0,2: ..."), possibly after a few words saying what the file is, with
    /// no quote or colon ("scene 'a.json': /light: ..."). When it does not,
    /// detail() is the whole message.
    Error(ErrorCode code, const std::string& message, const std::string& file);

    ErrorCode code() const noexcept { return code_; }
    /// The file the error concerns; empty when it names no file.
    const std::string& file() const noexcept;
    /// The message after its quoted file and the ": " or " " that follows it
    /// ("level 1 tile 0,2: CRC-32 mismatch"); the whole message when the error
    /// names no file.
    const char* detail() const noexcept { return what() + detailOffset_; }

    /// This error naming `file` when its message starts with that file quoted
    /// (see the constructor), else a copy of it unchanged. libdsm's entry
    /// points use it to attach the path a caller gave to the errors raised
    /// below them.
    Error withFile(const std::string& file) const;

private:
    ErrorCode code_;
    std::shared_ptr<const std::string> file_;  // shared: copying stays noexcept, as exceptions require
    std::size_t detailOffset_ = 0;
};

DSM_NAMESPACE_END
