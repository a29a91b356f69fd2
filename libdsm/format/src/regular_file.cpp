#include "regular_file.h"

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <unistd.h>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

int openRegularFile(const std::string& path, struct stat& st) {
    // O_NONBLOCK: opening a FIFO would otherwise wait for a writer forever.
    // It is refused below, and means nothing for the regular file kept.
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) throw Error(ErrorCode::io, concat("'", path, "': cannot open: ", std::strerror(errno)), path);
    if (::fstat(fd, &st) != 0) {
        const int reason = errno;
        ::close(fd);
        throw Error(ErrorCode::io, concat("'", path, "': cannot stat: ", std::strerror(reason)), path);
    }
    if (!S_ISREG(st.st_mode)) {
        ::close(fd);
        throw Error(ErrorCode::io, concat("'", path, "': not a regular file"), path);
    }
    ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
    return fd;
}

std::size_t readAt(int fd, std::uint64_t offset, void* out, std::size_t count) {
    for (;;) {
        const ssize_t n = ::pread(fd, out, count, static_cast<off_t>(offset));
        if (n >= 0) return static_cast<std::size_t>(n);
        if (errno != EINTR) throw std::runtime_error(std::strerror(errno));
    }
}

DSM_NAMESPACE_END
