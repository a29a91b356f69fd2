// The part of TileCache that the map reader uses (internal).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>

#include "dsm/tile_cache.h"
#include "tested_internal.h"

DSM_NAMESPACE_BEGIN

/// Identifies one tile: an id from newFileId() for each open file, the mip
/// level and the tile index within the level.
struct TileKey {
    std::uint64_t file = 0;
    std::uint32_t level = 0;
    std::uint32_t tile = 0;
    friend bool operator==(const TileKey&, const TileKey&) = default;
};

/// What a loader returns: the decoded tile, its size in memory (what counts
/// against the budget) and the number of file bytes read to make it.
struct LoadedTile {
    std::shared_ptr<const void> data;
    std::size_t memoryBytes = 0;
    std::size_t fileBytes = 0;
};

struct DSM_TESTED_INTERNAL TileCache::Impl {
    explicit Impl(std::size_t budgetBytes);
    ~Impl();

    /// The cached tile for `key`, or the result of `load()` (then cached).
    /// `load` runs without any cache lock held and may throw; the exception
    /// propagates and nothing is cached. Two threads missing the same tile at
    /// once may both load it; the first to finish is kept.
    /// A loader that returns null data is a bug: get() throws dsm::Error.
    std::shared_ptr<const void> get(const TileKey& key, const std::function<LoadedTile()>& load);

    /// Typed convenience over get().
    template <typename T>
    std::shared_ptr<const T> get(const TileKey& key, const std::function<LoadedTile()>& load) {
        return std::static_pointer_cast<const T>(get(key, load));
    }

    /// A fresh id for a newly opened file.
    std::uint64_t newFileId();
    /// Drops every tile of one file (called when the file is closed). Not
    /// counted as evictions; tiles handed out stay valid.
    void forgetFile(std::uint64_t file);

    std::size_t budget() const;
    void setBudget(std::size_t budgetBytes);
    TileCacheStats stats() const;
    void resetStats();
    void clear();

private:
    struct State;
    std::unique_ptr<State> state_;
};

DSM_NAMESPACE_END
