// A file holding the current fuzz input, for readers that take a path: an
// anonymous in-memory file (opened through /proc/self/fd), or a temporary file
// where memfd_create is not available. One per process, rewritten for every
// input.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <sys/mman.h>
#include <unistd.h>

struct ScratchFile {
    int fd = -1;
    std::string path;

    explicit ScratchFile(const char* name) {
        fd = ::memfd_create(name, MFD_CLOEXEC);
        if (fd >= 0) {
            path = "/proc/self/fd/" + std::to_string(fd);
            return;
        }
        const char* tmp = std::getenv("TMPDIR");
        std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/" + name + "-XXXXXX";
        fd = ::mkstemp(pattern.data());
        if (fd < 0) {
            std::perror("cannot create a scratch file");
            std::abort();
        }
        path = pattern;
    }
    ~ScratchFile() {
        ::close(fd);
        if (path.rfind("/proc/", 0) != 0) ::unlink(path.c_str());
    }
    ScratchFile(const ScratchFile&) = delete;
    ScratchFile& operator=(const ScratchFile&) = delete;

    void write(const std::uint8_t* data, std::size_t size) {
        if (::ftruncate(fd, static_cast<off_t>(size)) != 0) std::abort();
        std::size_t done = 0;
        while (done < size) {
            const ssize_t n = ::pwrite(fd, data + done, size - done, static_cast<off_t>(done));
            if (n <= 0) std::abort();
            done += static_cast<std::size_t>(n);
        }
    }
};
