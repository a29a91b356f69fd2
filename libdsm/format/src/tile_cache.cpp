// TileCache: decoded tiles of any number of open maps, bounded by bytes.
//
// Ownership: tiles are held by shared_ptr. The cache keeps one reference per
// cached tile; every caller of get() receives its own. Eviction only drops the
// cache's reference, so a tile handed out stays valid (and unchanged: tiles are
// const) for as long as its holder keeps it, whatever the cache does meanwhile.
//
// Resource tracking: what counts against the budget is LoadedTile::memoryBytes,
// the decoded size the loader reports, for the tiles the cache references. Tiles
// already evicted but still held by callers are the callers' memory, and the
// cache's own bookkeeping (a list node and a hash node per tile, ~100 bytes) is
// not counted. Before a tile is added, least recently used tiles are dropped
// until it fits; the new tile itself is never dropped, so a tile larger than the
// whole budget is still returned and stays cached alone until the next
// insertion. Hence bytesInUse <= max(budget, newest tile) <= budget + one tile.
//
// Eviction policy: strict LRU, a doubly linked list (most recent at the front)
// indexed by a hash map. A hit costs one lookup and one O(1) splice under the
// lock. Reads of a map are spatially coherent (neighbouring pixels, the same
// few tiles over and over), which LRU serves well; a clock would save the splice
// but lose the exact order that makes the cache's behaviour easy to predict.
//
// Threading: one mutex guards everything. Loaders run with no lock held, so
// file I/O and decoding of different tiles proceed in parallel; two threads
// missing the same tile may both load it, which is harmless (the first to
// finish is kept, the other copy is dropped when its caller lets go). Tiles
// dropped by eviction, clear() or forgetFile() are released after unlocking,
// so freeing them never holds up other threads.
//
// Lifetime: the cache is shared by shared_ptr among the maps that use it;
// defaultCache() is a function-local static created on first use, and maps
// keep their own reference, so it outlives any map that uses it.

#include "tile_cache_impl.h"

#include <algorithm>
#include <atomic>
#include <iterator>
#include <list>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include "dsm/error.h"
#include "splitmix64.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

struct TileKeyHash {
    std::size_t operator()(const TileKey& k) const noexcept {
        return static_cast<std::size_t>(
            detail::mix64(k.file * 0x9E3779B97F4A7C15ull ^ ((std::uint64_t(k.level) << 32) | k.tile)));
    }
};

struct Entry {
    TileKey key;
    std::shared_ptr<const void> data;
    std::size_t memoryBytes = 0;
};

}  // namespace

struct TileCache::Impl::State {
    mutable std::mutex mutex;
    std::list<Entry> lru;  // most recently used first
    std::unordered_map<TileKey, std::list<Entry>::iterator, TileKeyHash> index;
    TileCacheStats stats;  // budgetBytes, bytesInUse and tilesInUse kept current
    std::atomic<std::uint64_t> nextFileId{1};

    void notePeak() { stats.peakBytesInUse = std::max(stats.peakBytesInUse, stats.bytesInUse); }

    // Removes one entry, handing its data to `dropped` (released after unlocking).
    void remove(std::list<Entry>::iterator it, std::vector<std::shared_ptr<const void>>& dropped) {
        dropped.push_back(std::move(it->data));
        stats.bytesInUse -= it->memoryBytes;
        --stats.tilesInUse;
        index.erase(it->key);
        lru.erase(it);
    }

    // Evicts least recently used tiles until `incoming` more bytes fit within
    // the budget, or nothing is left.
    void evictFor(std::uint64_t incoming, std::vector<std::shared_ptr<const void>>& dropped) {
        while (!lru.empty() && stats.bytesInUse + incoming > stats.budgetBytes) {
            remove(std::prev(lru.end()), dropped);
            ++stats.evictions;
        }
    }
};

TileCache::Impl::Impl(std::size_t budgetBytes) : state_(std::make_unique<State>()) {
    state_->stats.budgetBytes = budgetBytes;
}

TileCache::Impl::~Impl() = default;

std::shared_ptr<const void> TileCache::Impl::get(const TileKey& key, const std::function<LoadedTile()>& load) {
    State& s = *state_;
    {
        std::lock_guard lock(s.mutex);
        if (auto found = s.index.find(key); found != s.index.end()) {
            s.lru.splice(s.lru.begin(), s.lru, found->second);
            ++s.stats.hits;
            return found->second->data;
        }
        ++s.stats.misses;
    }

    LoadedTile loaded = load();  // no lock held; may throw
    if (!loaded.data)
        throw Error(ErrorCode::internal, detail::concat("tile cache: the loader of file ", key.file, " level ",
                                                        key.level, " tile ", key.tile, " returned no data"));

    std::vector<std::shared_ptr<const void>> dropped;  // released after unlocking
    std::lock_guard lock(s.mutex);
    ++s.stats.tilesRead;
    s.stats.bytesRead += loaded.fileBytes;
    if (auto found = s.index.find(key); found != s.index.end()) {
        // Another thread loaded it meanwhile: keep theirs, drop ours.
        s.lru.splice(s.lru.begin(), s.lru, found->second);
        dropped.push_back(std::move(loaded.data));
        return found->second->data;
    }
    s.evictFor(loaded.memoryBytes, dropped);
    s.lru.push_front(Entry{key, loaded.data, loaded.memoryBytes});
    try {
        s.index.emplace(key, s.lru.begin());
    } catch (...) {
        s.lru.pop_front();
        throw;
    }
    s.stats.bytesInUse += loaded.memoryBytes;
    ++s.stats.tilesInUse;
    s.notePeak();
    return std::move(loaded.data);
}

std::uint64_t TileCache::Impl::newFileId() { return state_->nextFileId.fetch_add(1, std::memory_order_relaxed); }

void TileCache::Impl::forgetFile(std::uint64_t file) {
    State& s = *state_;
    std::vector<std::shared_ptr<const void>> dropped;
    std::lock_guard lock(s.mutex);
    for (auto it = s.lru.begin(); it != s.lru.end();) {
        auto next = std::next(it);
        if (it->key.file == file) s.remove(it, dropped);
        it = next;
    }
}

std::size_t TileCache::Impl::budget() const {
    std::lock_guard lock(state_->mutex);
    return static_cast<std::size_t>(state_->stats.budgetBytes);
}

void TileCache::Impl::setBudget(std::size_t budgetBytes) {
    State& s = *state_;
    std::vector<std::shared_ptr<const void>> dropped;
    std::lock_guard lock(s.mutex);
    s.stats.budgetBytes = budgetBytes;
    s.evictFor(0, dropped);
}

TileCacheStats TileCache::Impl::stats() const {
    std::lock_guard lock(state_->mutex);
    return state_->stats;
}

void TileCache::Impl::resetStats() {
    State& s = *state_;
    std::lock_guard lock(s.mutex);
    s.stats.hits = 0;
    s.stats.misses = 0;
    s.stats.tilesRead = 0;
    s.stats.bytesRead = 0;
    s.stats.evictions = 0;
    s.stats.peakBytesInUse = s.stats.bytesInUse;
}

void TileCache::Impl::clear() {
    State& s = *state_;
    std::list<Entry> dropped;  // released after unlocking
    std::lock_guard lock(s.mutex);
    s.index.clear();
    dropped.swap(s.lru);
    s.stats.bytesInUse = 0;
    s.stats.tilesInUse = 0;
}

// ---------------------------------------------------------------------------

std::shared_ptr<TileCache> TileCache::create(std::size_t budgetBytes) {
    return std::shared_ptr<TileCache>(new TileCache(budgetBytes));
}

std::shared_ptr<TileCache> TileCache::defaultCache() {
    static const std::shared_ptr<TileCache> cache = create(std::size_t(256) << 20);
    return cache;
}

TileCache::TileCache(std::size_t budgetBytes) : impl_(std::make_unique<Impl>(budgetBytes)) {}

TileCache::~TileCache() = default;

std::size_t TileCache::budget() const { return impl_->budget(); }
void TileCache::setBudget(std::size_t budgetBytes) { impl_->setBudget(budgetBytes); }
TileCacheStats TileCache::stats() const { return impl_->stats(); }
void TileCache::resetStats() { impl_->resetStats(); }
void TileCache::clear() { impl_->clear(); }

DSM_NAMESPACE_END
