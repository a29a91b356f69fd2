// Reading a regular file by descriptor (internal): what MapInput::file and
// the shadow system's file pool share.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include <sys/stat.h>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// Opens `path` for reading and fills `st`. Refuses anything but a regular
/// file without blocking on it (a FIFO would wait for a writer forever).
/// Throws dsm::Error (io) carrying the path.
int openRegularFile(const std::string& path, struct stat& st);

/// pread() of up to `count` bytes at `offset`, retried when interrupted;
/// returns the bytes read (0 at the end). Throws std::runtime_error with the
/// system's reason on failure.
std::size_t readAt(int fd, std::uint64_t offset, void* out, std::size_t count);

DSM_NAMESPACE_END
