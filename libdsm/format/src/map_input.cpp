#include "dsm/map_input.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dsm/error.h"
#include "regular_file.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

class FileInput final : public MapInput {
public:
    explicit FileInput(const std::string& path) {
        struct stat st {};
        fd_ = openRegularFile(path, st);
        size_ = static_cast<std::uint64_t>(st.st_size);
    }
    ~FileInput() override { ::close(fd_); }
    FileInput(const FileInput&) = delete;
    FileInput& operator=(const FileInput&) = delete;

    std::uint64_t size() const override { return size_; }

    std::size_t read(std::uint64_t offset, void* out, std::size_t count) const override {
        return readAt(fd_, offset, out, count);
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
