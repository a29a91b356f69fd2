// A tile cache bounded by bytes, shared by any number of open deep shadow maps
// and threads (Lokovic & Veach 2000, §5.4; in the spirit of Ptex's and
// OpenImageIO's caches).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

class ImplAccess;

/// Counters of a TileCache. Plain values, copied out by TileCache::stats().
/// Every request for a tile is counted once, as a hit or a miss.
struct TileCacheStats {
    std::uint64_t budgetBytes = 0;     ///< the byte budget the cache keeps to
    std::uint64_t bytesInUse = 0;      ///< decoded tile bytes held by the cache now
    std::uint64_t peakBytesInUse = 0;  ///< largest bytesInUse since creation or resetStats()
    std::uint64_t tilesInUse = 0;      ///< tiles held by the cache now
    std::uint64_t peakTilesInUse = 0;  ///< largest tilesInUse since creation or resetStats()
    std::uint64_t hits = 0;            ///< requests answered without reading (waits included)
    std::uint64_t misses = 0;          ///< requests that read the tile themselves
    std::uint64_t waits = 0;           ///< hits that waited for another thread's read of the tile
    std::uint64_t tilesRead = 0;       ///< tiles read and decoded successfully
    std::uint64_t bytesRead = 0;       ///< stored (file) bytes read for those tiles
    std::uint64_t evictions = 0;       ///< tiles dropped to stay within budget (not by clear())
    /// Reads of a tile that was held or being read at the time: 0 by design
    /// (concurrent requests for one tile share one read), kept as a check.
    std::uint64_t duplicateReads = 0;
};

/// Holds decoded tiles of any number of files, so that the bytes it holds never
/// exceed the budget by more than the one tile being added. Fully thread-safe:
/// a tile is read once however many threads ask for it at the same time, and
/// threads asking for different tiles do not wait for one another. Eviction
/// resists scans and loops: tiles that keep being reused are protected from a
/// stream of tiles that are not (see tile_cache.cpp). A tile handed out stays
/// valid for as long as its holder keeps it, even if the cache evicts it.
///
/// Create one with TileCache::create() and pass it to every map you open;
/// maps opened without one share a process-wide cache (see defaultCache()).
class DSM_API TileCache {
public:
    /// A cache that keeps at most `budgetBytes` of decoded tiles (plus one tile).
    static std::shared_ptr<TileCache> create(std::size_t budgetBytes);
    /// The process-wide cache used when none is given: 256 MiB.
    static std::shared_ptr<TileCache> defaultCache();

    ~TileCache();
    TileCache(const TileCache&) = delete;
    TileCache& operator=(const TileCache&) = delete;

    std::size_t budget() const;
    /// Changes the budget; evicts at once if the cache holds more. A budget of
    /// 0 keeps only the most recently read tile.
    void setBudget(std::size_t budgetBytes);
    TileCacheStats stats() const;
    /// Zeroes the counters (hits, misses, waits, tilesRead, bytesRead,
    /// evictions, duplicateReads); peakBytesInUse and peakTilesInUse restart
    /// from the current bytesInUse and tilesInUse. The budget and the tiles
    /// held are unchanged.
    void resetStats();
    /// Drops every tile the cache holds (tiles handed out stay valid; tiles
    /// being read are kept when their read completes).
    void clear();

private:
    friend class ImplAccess;
    /// What the map reader uses: src/tile_cache_impl.h.
    struct Impl;
    explicit TileCache(std::size_t budgetBytes);
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
