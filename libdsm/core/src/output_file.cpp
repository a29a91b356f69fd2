#include "dsm/output_file.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <system_error>

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

namespace fs = std::filesystem;

constexpr std::size_t kBufferSize = std::size_t(1) << 20;

std::string quoted(const std::string& path) { return concat("'", path, "'"); }

/// The directory an output goes to ("." for a bare name).
std::string directoryOf(const std::string& path) {
    const fs::path parent = fs::path(path).parent_path();
    return parent.empty() ? std::string(".") : parent.string();
}

std::string fileNameOf(const std::string& path) { return fs::path(path).filename().string(); }

/// How the names of an output's temporaries start: hidden, beside it.
/// Appended piece by piece: GCC 12 at -O3 warns (-Wrestrict, a false
/// positive) about its own inlined "." + std::string&&.
std::string temporaryPrefix(const std::string& path) {
    std::string prefix = ".";
    prefix += fileNameOf(path);
    prefix += ".tmp-";
    return prefix;
}

/// What a file is, for comparing names: its device and inode when it exists,
/// else its directory's device and inode and its name there.
struct FileIdentity {
    dev_t device = 0;
    ino_t inode = 0;
    std::string nameInDirectory;  // empty when the file exists
    bool known = false;

    bool operator==(const FileIdentity& other) const {
        return known && other.known && device == other.device && inode == other.inode &&
               nameInDirectory == other.nameInDirectory;
    }
};

FileIdentity existingIdentity(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return {};
    return {st.st_dev, st.st_ino, {}, true};
}

FileIdentity outputIdentity(const std::string& path) {
    FileIdentity identity = existingIdentity(path);
    if (identity.known) return identity;
    identity = existingIdentity(directoryOf(path));
    identity.nameInDirectory = fileNameOf(path);
    return identity;
}

/// Writes all of [data, data + size) at the descriptor's position (or at
/// `offset` when it is not negative); false with errno set when it cannot.
bool writeFully(int fd, const unsigned char* data, std::size_t size, off_t offset = -1) {
    while (size > 0) {
        const ssize_t n = offset < 0 ? ::write(fd, data, size) : ::pwrite(fd, data, size, offset);
        if (n < 0) {
            if (errno == EINTR) continue;
            return false;
        }
        if (n == 0) {
            errno = EIO;
            return false;
        }
        data += n;
        size -= std::size_t(n);
        if (offset >= 0) offset += n;
    }
    return true;
}

}  // namespace

void checkOutputPath(const std::string& path) {
    if (path.empty()) throw Error(ErrorCode::argument, "the output file name is empty");
    const std::string where = quoted(path);
    const std::string name = fileNameOf(path);
    if (path.back() == '/' || name == "." || name == "..")
        throw Error(ErrorCode::argument, concat(where, ": names a directory; name a file to write"), path);
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0) {
        if (S_ISDIR(st.st_mode))
            throw Error(ErrorCode::argument, concat(where, ": is a directory; name a file to write"), path);
        if (!S_ISREG(st.st_mode))
            throw Error(ErrorCode::argument,
                        concat(where, ": is not a regular file (a device, FIFO or socket); name a file to write"),
                        path);
    }
    const std::string directory = directoryOf(path);
    if (::stat(directory.c_str(), &st) != 0)
        throw Error(ErrorCode::io, concat(where, ": cannot write in the directory '", directory, "': ",
                                          std::strerror(errno)),
                    path);
    if (!S_ISDIR(st.st_mode))
        throw Error(ErrorCode::io, concat(where, ": cannot write there: '", directory, "' is not a directory"),
                    path);
    if (::access(directory.c_str(), W_OK | X_OK) != 0)
        throw Error(ErrorCode::io, concat(where, ": cannot write in the directory '", directory, "': ",
                                          std::strerror(errno)),
                    path);
}

void refuseOutputOverInputs(const std::string& output, const std::vector<std::string>& inputs) {
    const FileIdentity target = existingIdentity(output);
    if (!target.known) return;
    for (const std::string& input : inputs)
        if (existingIdentity(input) == target)
            throw Error(ErrorCode::argument,
                        input == output ? concat(quoted(output), ": the output is also an input; write to another file")
                                        : concat(quoted(output), ": the output is the same file as the input '", input,
                                                 "'; write to another file"),
                        output);
}

void refuseSharedOutputs(const std::vector<std::string>& outputs) {
    for (std::size_t i = 0; i < outputs.size(); ++i)
        for (std::size_t j = i + 1; j < outputs.size(); ++j)
            if (outputIdentity(outputs[i]) == outputIdentity(outputs[j]))
                throw Error(ErrorCode::argument, concat(quoted(outputs[j]), ": is also the output '", outputs[i],
                                                        "'; give each output its own file"),
                                outputs[j]);
}

std::vector<std::string> staleTemporaries(const std::string& path, std::int64_t minimumAgeSeconds) {
    std::vector<std::string> found;
    const std::string directory = directoryOf(path);
    const std::string prefix = temporaryPrefix(path);
    DIR* listing = ::opendir(directory.c_str());
    if (!listing) return found;
    const std::time_t now = std::time(nullptr);
    while (const dirent* entry = ::readdir(listing)) {
        const std::string name = entry->d_name;
        if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) continue;
        const std::string candidate = (fs::path(path).parent_path() / name).string();
        struct stat st {};
        if (::lstat(candidate.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) continue;
        if (now - st.st_mtime >= minimumAgeSeconds) found.push_back(candidate);
    }
    ::closedir(listing);
    std::sort(found.begin(), found.end());
    return found;
}

std::size_t removeStaleTemporaries(const std::string& path, std::int64_t minimumAgeSeconds) {
    std::size_t removed = 0;
    for (const std::string& stale : staleTemporaries(path, minimumAgeSeconds))
        if (::unlink(stale.c_str()) == 0) ++removed;
    return removed;
}

OutputFile::OutputFile(std::string path, std::string_view suffix) : path_(std::move(path)) {
    checkOutputPath(path_);
    const fs::path target(path_);
    std::string pattern = (target.parent_path() / (temporaryPrefix(path_) + "XXXXXX")).string();
    pattern += suffix;
    fd_ = ::mkstemps(pattern.data(), static_cast<int>(suffix.size()));
    if (fd_ < 0) fail(concat("cannot create a temporary file beside it: ", std::strerror(errno)));
    temporary_ = pattern;
    ::fchmod(fd_, 0644);  // mkstemp creates 0600; outputs are meant to be shared like any image
}

OutputFile::~OutputFile() {
    if (fd_ >= 0) ::close(fd_);
    if (!committed_ && !temporary_.empty()) ::unlink(temporary_.c_str());
}

void OutputFile::fail(const std::string& what) const {
    throw Error(ErrorCode::io, concat(quoted(path_), ": ", what), path_);
}

void OutputFile::flushBuffer() {
    if (buffer_.empty()) return;
    if (!writeFully(fd_, buffer_.data(), buffer_.size())) fail(concat("write failed: ", std::strerror(errno)));
    buffer_.clear();
}

void OutputFile::write(const void* data, std::size_t size) {
    if (committed_) fail("written after it was finished");
    const auto* bytes = static_cast<const unsigned char*>(data);
    if (buffer_.size() + size > kBufferSize) {
        flushBuffer();
        if (size >= kBufferSize) {
            if (!writeFully(fd_, bytes, size)) fail(concat("write failed: ", std::strerror(errno)));
            size_ += size;
            return;
        }
    }
    if (buffer_.capacity() < kBufferSize) buffer_.reserve(kBufferSize);
    buffer_.insert(buffer_.end(), bytes, bytes + size);
    size_ += size;
}

void OutputFile::writeAt(std::uint64_t offset, const void* data, std::size_t size) {
    if (committed_) fail("written after it was finished");
    if (offset + size > size_) fail(concat("write at ", offset, " beyond the ", size_, " bytes written"));
    flushBuffer();
    if (!writeFully(fd_, static_cast<const unsigned char*>(data), size, static_cast<off_t>(offset)))
        fail(concat("write failed: ", std::strerror(errno)));
}

void OutputFile::commit() {
    if (committed_) fail("finished twice");
    flushBuffer();
    if (::fsync(fd_) != 0) fail(concat("cannot sync the written file: ", std::strerror(errno)));
    const int closed = ::close(fd_);
    fd_ = -1;
    if (closed != 0) fail(concat("close failed: ", std::strerror(errno)));
    if (::rename(temporary_.c_str(), path_.c_str()) != 0)
        fail(concat("cannot rename the finished file into place: ", std::strerror(errno)));
    committed_ = true;
    // The new name lasts a crash only once the directory is on disk too.
    const std::string directory = directoryOf(path_);
    const int dir = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dir >= 0) {
        const bool synced = ::fsync(dir) == 0 || errno == EINVAL;  // EINVAL: the file system cannot sync directories
        const int error = errno;
        ::close(dir);
        if (!synced) fail(concat("written, but its directory could not be synced: ", std::strerror(error)));
    }
    removeStaleTemporaries(path_);
}

DSM_NAMESPACE_END
