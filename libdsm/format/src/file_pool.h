// Open files shared under a cap (internal): the inputs of the maps a
// ShadowSystem opens. Each file is opened on demand and may be closed when
// more than `maxOpen` are open and it is not being read; it is then reopened
// at its next read, after checking that it is still the same file.
#pragma once

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>

#include "dsm/map_input.h"
#include "tested_internal.h"

DSM_NAMESPACE_BEGIN

struct FilePoolStats {
    std::uint64_t filesOpen = 0;      ///< descriptors open now
    std::uint64_t peakFilesOpen = 0;  ///< most open at once since creation or resetStats()
    std::uint64_t opens = 0;          ///< files opened (first opens and reopens)
    std::uint64_t reopens = 0;        ///< opens of a file closed earlier to stay within the cap
};

class DSM_TESTED_INTERNAL FilePool : public std::enable_shared_from_this<FilePool> {
public:
    /// At most `maxOpen` (at least 1) files are kept open; more are open at
    /// once only while more than `maxOpen` reads run at the same time.
    static std::shared_ptr<FilePool> create(unsigned maxOpen);

    /// An input reading `path` through the pool. Opens it at once (so that a
    /// missing or irregular file fails here) and throws dsm::Error (io) naming
    /// the path. The pool lives as long as any of its inputs.
    std::shared_ptr<const MapInput> open(const std::string& path);

    FilePoolStats stats() const;
    void resetStats();
    unsigned maxOpen() const { return maxOpen_; }

    struct File;
    /// The descriptor of `file` for one read, opened if needed; release() after.
    int acquire(File& file);
    void release(File& file);
    /// Closes `file` for good (its input is destroyed).
    void forget(File& file);

private:
    explicit FilePool(unsigned maxOpen) : maxOpen_(maxOpen < 1 ? 1 : maxOpen) {}
    void closeIdleBeyond(unsigned limit);  // with mutex_ held
    void listOpened(File& file);           // a file just opened: first in open_, counted; with mutex_ held

    const unsigned maxOpen_;
    mutable std::mutex mutex_;
    std::list<File*> open_;  // most recently used first
    FilePoolStats stats_;
};

DSM_NAMESPACE_END
