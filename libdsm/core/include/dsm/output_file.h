// The one way libdsm writes a file (maps, deep EXRs, pictures, statistics):
// into a hidden temporary beside the target, with every write checked, then
// fsync of the file, rename over the target and fsync of the directory. The
// target's name therefore shows the old file or the complete new one, never a
// half-written one. Guarantees for users: docs/robustness.md, "Outputs".
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// Checks, before any work is done, that `path` can be written as an output:
/// not empty, not a directory (nor a name ending in '/'), not a device, FIFO
/// or socket, in a directory that exists and may be written. Throws
/// dsm::Error naming the file (ErrorCode::argument for a name that cannot be
/// an output file, ErrorCode::io for a place that cannot be written).
DSM_API void checkOutputPath(const std::string& path);

/// Throws dsm::Error (ErrorCode::argument) when `output` is the same file as
/// one of `inputs` (same device and inode, so also through hard and symbolic
/// links). Inputs that do not exist are ignored.
DSM_API void refuseOutputOverInputs(const std::string& output, const std::vector<std::string>& inputs);

/// Throws dsm::Error (ErrorCode::argument) when two of `outputs` name the same
/// file: the same existing file, or the same name in the same directory.
DSM_API void refuseSharedOutputs(const std::vector<std::string>& outputs);

/// Temporaries left beside `path` by interrupted writes: the files
/// `.NAME.tmp-*` next to it (NAME is `path`'s file name) not modified for
/// `minimumAgeSeconds`. Sorted paths.
DSM_API std::vector<std::string> staleTemporaries(const std::string& path, std::int64_t minimumAgeSeconds = 86400);

/// Removes staleTemporaries(path, minimumAgeSeconds); returns how many were
/// removed. Never throws: a temporary that cannot be removed is left.
DSM_API std::size_t removeStaleTemporaries(const std::string& path, std::int64_t minimumAgeSeconds = 86400);

/// An output being written. The constructor checks the path (checkOutputPath)
/// and creates the temporary `.NAME.tmp-XXXXXX` beside it (plus `suffix`, for
/// third-party writers that choose a format by the name's extension). Write
/// through write() / writeAt(), or let another library write
/// temporaryPath() by name. commit() makes it the file `path`; destroying an
/// OutputFile that was not committed removes the temporary.
///
/// Thread safety: not thread-safe; calls on one OutputFile must not overlap.
/// Separate OutputFiles (to different paths) are independent.
class DSM_API OutputFile {
public:
    explicit OutputFile(std::string path, std::string_view suffix = {});
    ~OutputFile();
    OutputFile(const OutputFile&) = delete;
    OutputFile& operator=(const OutputFile&) = delete;

    /// The target name.
    const std::string& path() const { return path_; }
    /// Where the bytes go until commit().
    const std::string& temporaryPath() const { return temporary_; }

    /// Appends bytes (buffered). Throws dsm::Error (ErrorCode::io) naming the
    /// target when the system refuses them (a full disk, a quota, an I/O error).
    void write(const void* data, std::size_t size);
    /// Overwrites bytes already appended, at `offset` (e.g. a header).
    void writeAt(std::uint64_t offset, const void* data, std::size_t size);
    /// Bytes appended so far.
    std::uint64_t size() const { return size_; }

    /// Flushes and fsyncs the temporary, renames it over path() and fsyncs the
    /// directory. Throws dsm::Error (ErrorCode::io) when any step fails; the
    /// temporary is then removed and path() is unchanged. Afterwards old
    /// temporaries of the same name (removeStaleTemporaries) are cleared.
    void commit();

private:
    void flushBuffer();
    [[noreturn]] void fail(const std::string& what) const;

    std::string path_;
    std::string temporary_;
    int fd_ = -1;
    std::vector<unsigned char> buffer_;
    std::uint64_t size_ = 0;
    bool committed_ = false;
};

DSM_NAMESPACE_END
