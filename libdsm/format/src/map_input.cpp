#include "dsm/map_input.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

class FileInput final : public MapInput {
public:
    explicit FileInput(const std::string& path) {
        using detail::concat;
        // O_NONBLOCK: opening a FIFO would otherwise wait for a writer forever.
        // It is refused below, and means nothing for the regular file we keep.
        fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
        if (fd_ < 0) throw Error(ErrorCode::io, concat("'", path, "': cannot open: ", std::strerror(errno)), path);
        struct stat st {};
        if (::fstat(fd_, &st) != 0) {
            const int reason = errno;
            ::close(fd_);
            throw Error(ErrorCode::io, concat("'", path, "': cannot stat: ", std::strerror(reason)), path);
        }
        if (!S_ISREG(st.st_mode)) {
            ::close(fd_);
            throw Error(ErrorCode::io, concat("'", path, "': not a regular file"), path);
        }
        ::fcntl(fd_, F_SETFL, ::fcntl(fd_, F_GETFL) & ~O_NONBLOCK);
        size_ = static_cast<std::uint64_t>(st.st_size);
    }
    ~FileInput() override { ::close(fd_); }
    FileInput(const FileInput&) = delete;
    FileInput& operator=(const FileInput&) = delete;

    std::uint64_t size() const override { return size_; }

    std::size_t read(std::uint64_t offset, void* out, std::size_t count) const override {
        for (;;) {
            const ssize_t n = ::pread(fd_, out, count, static_cast<off_t>(offset));
            if (n >= 0) return static_cast<std::size_t>(n);
            if (errno != EINTR) throw std::runtime_error(std::strerror(errno));
        }
    }

private:
    int fd_ = -1;
    std::uint64_t size_ = 0;
};

class MemoryInput final : public MapInput {
public:
    MemoryInput(const void* data, std::size_t size) : data_(static_cast<const std::uint8_t*>(data)), size_(size) {}

    std::uint64_t size() const override { return size_; }

    std::size_t read(std::uint64_t offset, void* out, std::size_t count) const override {
        if (offset >= size_) return 0;
        const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(count, size_ - offset));
        std::memcpy(out, data_ + offset, n);
        return n;
    }

private:
    const std::uint8_t* data_;
    std::size_t size_;
};

}  // namespace

std::shared_ptr<const MapInput> MapInput::file(const std::string& path) { return std::make_shared<FileInput>(path); }

std::shared_ptr<const MapInput> MapInput::memory(const void* data, std::size_t size) {
    if (data == nullptr && size != 0) throw Error(ErrorCode::argument, "map input: no data for a buffer of bytes");
    return std::make_shared<MemoryInput>(data, size);
}

DSM_NAMESPACE_END
