// Where a map's bytes come from: a file, a buffer in memory, or the caller's
// own reads (an input hook, as Ptex's PtexInputHandler or OpenEXRCore's read
// function). DeepShadowMap::open() reads every byte through one of these.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// A read-only, random-access source of a map's bytes. The reader calls read()
/// from any number of threads at once (tiles load in parallel), so an
/// implementation must be thread-safe; it lives as long as the map it opened.
class DSM_API MapInput {
public:
    virtual ~MapInput() = default;

    /// The number of bytes the map holds.
    virtual std::uint64_t size() const = 0;
    /// Copies up to `count` bytes from `offset` into `out` and returns how many
    /// it copied: fewer than `count` only at the end of the data. On failure it
    /// throws (any std::exception); the reader reports it as an ErrorCode::io
    /// dsm::Error naming the map and the part it was reading, with what() as the reason.
    virtual std::size_t read(std::uint64_t offset, void* out, std::size_t count) const = 0;

    /// A regular file, read with pread. Throws ErrorCode::io when it cannot be
    /// opened or is not a regular file.
    static std::shared_ptr<const MapInput> file(const std::string& path);
    /// `size` bytes at `data`, not copied: they must stay unchanged while a
    /// map opened from them is open.
    static std::shared_ptr<const MapInput> memory(const void* data, std::size_t size);
};

DSM_NAMESPACE_END
