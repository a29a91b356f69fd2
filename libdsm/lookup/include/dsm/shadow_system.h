// One shadow lookup system per renderer: the tile cache, the open files and
// the maps, shared by every thread (in the spirit of OpenImageIO's
// TextureSystem).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "dsm/lookup.h"
#include "dsm/map_input.h"
#include "dsm/reader.h"
#include "dsm/span.h"
#include "dsm/tile_cache.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

struct ShadowSystemOptions {
    /// Budget of the tile cache, in bytes of decoded tiles (TileCache), unless
    /// `cache` is given.
    std::size_t cacheBytes = std::size_t(256) << 20;
    /// Most map files kept open at once (at least 1). A file closed to stay
    /// within the cap is reopened when one of its tiles is next read, after
    /// checking that it is the same file (same device, inode, size and
    /// modification time); if it is not, that read fails (ErrorCode::io).
    unsigned maxOpenFiles = 100;
    /// Tiles each ShadowThread keeps at hand (rounded up to a power of two):
    /// a lookup whose tiles are there touches no lock and no shared counter.
    /// Each slot keeps its tile alive, so up to threads x threadTiles tiles may
    /// live outside the cache's budget; lower it when many threads share a
    /// small budget.
    unsigned threadTiles = kDefaultThreadTiles;
    /// Limits for untrusted files (its `cache` member is ignored).
    ReaderOptions limits;
    /// The tile cache to use, shared with other systems or maps; null (the
    /// default) makes one of cacheBytes for this system alone, and cacheBytes
    /// is then ignored.
    std::shared_ptr<TileCache> cache;
};

/// Counters of a ShadowSystem (plain values, copied out by stats()).
struct ShadowSystemStats {
    TileCacheStats cache;
    std::uint64_t maps = 0;           ///< maps opened (handles)
    std::uint64_t filesOpen = 0;      ///< map files open now
    std::uint64_t peakFilesOpen = 0;  ///< most open at once since creation or resetStats()
    std::uint64_t fileOpens = 0;      ///< files opened, counting reopens
    std::uint64_t reopens = 0;        ///< reopens of files closed to stay within maxOpenFiles
};

class ShadowSystem;
class ImplAccess;

/// A map opened in a ShadowSystem. Owned by the system and valid for its
/// lifetime; compare and pass by pointer. Opaque.
class MapHandle;

/// Per-thread lookup state for every map of one ShadowSystem: the tiles the
/// thread touched last, scratch space, the last failure. Not thread-safe: one
/// per thread (or per task that runs on one thread at a time). Its size does
/// not depend on the number of maps. The system must outlive it.
class DSM_API ShadowThread {
public:
    ~ShadowThread();
    ShadowThread(const ShadowThread&) = delete;
    ShadowThread& operator=(const ShadowThread&) = delete;

    /// Why the last failed lookup on this thread failed.
    const LookupFailure& lastFailure() const noexcept;
    /// Bytes this state uses itself (not counting the tiles it keeps alive).
    std::size_t memoryBytes() const noexcept;

private:
    friend class ImplAccess;
    friend class ShadowSystem;
    struct Impl;
    explicit ShadowThread(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

/// The maps, files and tile cache of one renderer. Thread-safe: any number of
/// threads may open maps and look up at once, each with its own ShadowThread.
///
/// Lookups never throw: on failure (a point or option out of range, a tile
/// that cannot be read or is corrupt, memory) they return false, set the
/// result to the documented failure value (lit with no confidence: v = {1, 1,
/// 1}, errorBound = 1, pixelsUsed = 0) and the thread's lastFailure() says why.
/// Results are the same, to the bit, as LookupContext's.
class DSM_API ShadowSystem {
public:
    static std::shared_ptr<ShadowSystem> create(const ShadowSystemOptions& options = {});
    ~ShadowSystem();
    ShadowSystem(const ShadowSystem&) = delete;
    ShadowSystem& operator=(const ShadowSystem&) = delete;

    /// Opens the map at `path`, or returns the handle it already has (the path
    /// as given is the key). Reads and checks the header and directories now
    /// (see DeepShadowMap::open); throws dsm::Error naming the file on failure.
    MapHandle* open(const std::string& path);
    /// Opens a map from memory or the caller's reads; `name` is what messages
    /// quote. Each call opens a new map (inputs are not compared).
    MapHandle* open(std::shared_ptr<const MapInput> input, const std::string& name);

    /// The map behind a handle (for its info(), pixels, tiles); it stays open
    /// while the system or the returned pointer lives. Throws dsm::Error
    /// (argument) for a null handle.
    std::shared_ptr<const DeepShadowMap> map(const MapHandle* handle) const;

    /// A new per-thread state.
    std::unique_ptr<ShadowThread> createThread();

    /// Visibility at one point of `space` (see LookupSpace) in map `handle`.
    bool lookup(ShadowThread& thread, const MapHandle* handle, LookupSpace space, const std::array<double, 3>& point,
                const LookupOptions& options, LookupResult& result) const noexcept;
    /// Visibility at many points: results[i] answers points[i] (the shorter of
    /// the two spans sets the count). The points are visited tile by tile, so
    /// a batch of scattered points costs less than the same lookups one by
    /// one. Returns the number of points that failed (each holds the failure
    /// value; lastFailure() is the last of them).
    std::size_t lookup(ShadowThread& thread, const MapHandle* handle, LookupSpace space,
                       Span<const std::array<double, 3>> points, const LookupOptions& options,
                       Span<LookupResult> results) const noexcept;

    /// The shared tile cache (its budget can be changed, its counters read).
    TileCache& cache() const;
    ShadowSystemStats stats() const;
    /// Zeroes the counters of the cache and the files; peaks restart from the
    /// current values.
    void resetStats();

private:
    friend class ImplAccess;
    struct Impl;
    explicit ShadowSystem(const ShadowSystemOptions& options);
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
