// The part of TileCache that the map reader uses (internal).
#pragma once

#include <concepts>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>

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

/// A loader: reads and decodes one tile from what `context` points to. A plain
/// function pointer and a context, so that a miss allocates nothing to call it.
using TileLoadFunction = LoadedTile (*)(const void* context);

struct DSM_TESTED_INTERNAL TileCache::Impl {
    explicit Impl(std::size_t budgetBytes);
    ~Impl();

    /// The cached tile for `key`, or the result of `load(context)` (then
    /// cached). `load` runs without any cache lock held and may throw; the
    /// exception propagates and nothing is cached. While one thread loads a
    /// tile, other threads asking for it wait and receive the same tile (or the
    /// same exception); a tile is never loaded twice at once. A loader that
    /// returns null data, or asks the cache for the very tile it is loading,
    /// is a bug: get() throws dsm::Error (internal).
    std::shared_ptr<const void> get(const TileKey& key, TileLoadFunction load, const void* context);

    /// get() with any callable `load()` (a lambda capturing what it needs):
    /// the callable is passed by address, so nothing is allocated.
    template <typename F>
        requires std::invocable<F&>
    std::shared_ptr<const void> get(const TileKey& key, F&& load) {
        using Callable = std::remove_reference_t<F>;
        return get(
            key, [](const void* context) -> LoadedTile { return (*static_cast<Callable*>(const_cast<void*>(context)))(); },
            static_cast<const void*>(std::addressof(load)));
    }

    /// Typed convenience: the tile as T (what the loader stored).
    template <typename T, typename F>
        requires std::invocable<F&>
    std::shared_ptr<const T> get(const TileKey& key, F&& load) {
        return std::static_pointer_cast<const T>(get(key, std::forward<F>(load)));
    }

    /// The cached tile for `key`, or null if it is not resident (never loads
    /// and never waits for a tile being loaded). Counts a hit when found.
    std::shared_ptr<const void> find(const TileKey& key);

    /// A fresh id for a newly opened file.
    std::uint64_t newFileId();
    /// Drops every resident tile of one file (called when the file is closed).
    /// Not counted as evictions; tiles handed out stay valid.
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
