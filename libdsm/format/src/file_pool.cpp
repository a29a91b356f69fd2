#include "file_pool.h"

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

using detail::concat;


struct FilePool::File {
    std::string path;
    int fd = -1;
    int readers = 0;                     // reads in progress (the file is not closed meanwhile)
    std::list<File*>::iterator position;  // in open_ while fd >= 0
    // What identifies the file opened first: a reopen must find the same one.
    dev_t device = 0;
    ino_t inode = 0;
    std::uint64_t size = 0;
    struct timespec modified {};
};

namespace {

class PooledInput final : public MapInput {
public:
    PooledInput(std::shared_ptr<FilePool> pool, std::unique_ptr<FilePool::File> file)
        : pool_(std::move(pool)), file_(std::move(file)) {}
    ~PooledInput() override;

    std::uint64_t size() const override { return file_->size; }

    std::size_t read(std::uint64_t offset, void* out, std::size_t count) const override {
        const int fd = pool_->acquire(*file_);  // throws if it cannot be reopened
        struct Release {
            FilePool& pool;
            FilePool::File& file;
            ~Release() { pool.release(file); }
        } release{*pool_, *file_};
        return readAt(fd, offset, out, count);
    }

    FilePool& pool() const { return *pool_; }
    FilePool::File& file() const { return *file_; }

private:
    std::shared_ptr<FilePool> pool_;
    std::unique_ptr<FilePool::File> file_;
};

}  // namespace

std::shared_ptr<FilePool> FilePool::create(unsigned maxOpen) { return std::shared_ptr<FilePool>(new FilePool(maxOpen)); }

std::shared_ptr<const MapInput> FilePool::open(const std::string& path) {
    auto file = std::make_unique<File>();
    file->path = path;
    std::lock_guard lock(mutex_);
    closeIdleBeyond(maxOpen_ - 1);
    struct stat st {};
    file->fd = openRegularFile(path, st);
    file->device = st.st_dev;
    file->inode = st.st_ino;
    file->size = static_cast<std::uint64_t>(st.st_size);
    file->modified = st.st_mtim;
    listOpened(*file);
    return std::make_shared<PooledInput>(shared_from_this(), std::move(file));
}

PooledInput::~PooledInput() { pool_->forget(*file_); }

void FilePool::forget(File& file) {
    std::lock_guard lock(mutex_);
    if (file.fd < 0) return;
    ::close(file.fd);
    file.fd = -1;
    open_.erase(file.position);
    --stats_.filesOpen;
}

void FilePool::listOpened(File& file) {
    open_.push_front(&file);
    file.position = open_.begin();
    ++stats_.opens;
    ++stats_.filesOpen;
    stats_.peakFilesOpen = std::max(stats_.peakFilesOpen, stats_.filesOpen);
}

void FilePool::closeIdleBeyond(unsigned limit) {
    // Least recently used first; files being read stay open.
    for (auto it = open_.end(); stats_.filesOpen > limit && it != open_.begin();) {
        --it;
        File& f = **it;
        if (f.readers > 0) continue;
        ::close(f.fd);
        f.fd = -1;
        it = open_.erase(it);
        --stats_.filesOpen;
    }
}

int FilePool::acquire(File& file) {
    std::lock_guard lock(mutex_);
    if (file.fd < 0) {
        closeIdleBeyond(maxOpen_ - 1);
        struct stat st {};
        const int fd = openRegularFile(file.path, st);
        if (st.st_dev != file.device || st.st_ino != file.inode ||
            static_cast<std::uint64_t>(st.st_size) != file.size || st.st_mtim.tv_sec != file.modified.tv_sec ||
            st.st_mtim.tv_nsec != file.modified.tv_nsec) {
            ::close(fd);
            throw std::runtime_error("the file was replaced or changed since it was opened");
        }
        file.fd = fd;
        listOpened(file);
        ++stats_.reopens;
    } else if (file.position != open_.begin()) {
        open_.splice(open_.begin(), open_, file.position);
        file.position = open_.begin();
    }
    ++file.readers;
    return file.fd;
}

void FilePool::release(File& file) {
    std::lock_guard lock(mutex_);
    --file.readers;
}

FilePoolStats FilePool::stats() const {
    std::lock_guard lock(mutex_);
    return stats_;
}

void FilePool::resetStats() {
    std::lock_guard lock(mutex_);
    stats_.opens = 0;
    stats_.reopens = 0;
    stats_.peakFilesOpen = stats_.filesOpen;
}

DSM_NAMESPACE_END
