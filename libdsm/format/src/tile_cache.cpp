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
// cache's own bookkeeping (an entry, a hash node and a remembered key per tile,
// ~200 bytes) is not counted. Before a tile is added, tiles are evicted until it
// fits; the new tile itself is never dropped, so a tile larger than the whole
// budget is still returned and stays cached alone until the next insertion.
// Accounting and eviction happen under one mutex, so the bound holds however
// many threads insert at once: bytesInUse <= max(budget, newest tile).
//
// Threading: a renderer asks from many threads at once, mostly for tiles the
// cache holds, so a hit must not serialise them. Resident and in-flight tiles
// are indexed by 64 shards, each a mutex and a hash map; a hit takes one shard
// lock, one hash find, at most one relaxed atomic store (the entry's last-use
// epoch, written only when it changes) and one shared_ptr copy. A miss inserts
// an in-flight entry and runs the loader with no lock held; other threads
// asking for that tile meanwhile wait on the shard's condition variable and
// receive the same tile, or the same exception (the failed entry is removed, so
// a later request reads again). Loads are plain function pointers with a
// context, so a miss allocates no std::function. Lock order: the eviction
// mutex, then a shard mutex, never the reverse. Tiles dropped by eviction,
// clear() or forgetFile() are released after unlocking.
//
// Eviction policy: a coherent scan over a map (a renderer's scanlines) reuses
// each tile row once per row of pixels. When the budget is slightly below what
// one such loop touches, LRU and plain CLOCK evict every tile just before its
// reuse and read everything every time. Here tiles are protected or on
// probation (LIRS's argument in CLOCK-Pro's shape, with ARC's adaptation):
// - Time is the epoch, the number of tiles read so far; a hit stamps the
//   entry's lastUse with it. Requests with no read in between (a lookup
//   touching the same tiles again) thus count as one use.
// - While protected tiles stay within their target share of the budget (and
//   leave probation room for two tiles like the new one: a lookup's footprint
//   straddles two tiles, which must not evict each other), a new tile is
//   protected. Otherwise it goes on probation (first in, first out), unless it
//   was evicted recently (keys and lastUse of evicted tiles are remembered) and
//   its previous use came after the last use of the protected tile under the
//   clock hand: its reuse distance is shorter than that tile's idle time, so
//   it takes that tile's place (the other goes on probation).
// - To make room, the oldest probation tile goes, unless it was reused at a
//   later epoch than it arrived: then it replaces the protected tile at the
//   hand if that one has been idle since, or gets a second pass. When nothing
//   is on probation, or the protected tiles exceed their target, the hand
//   sweeps the protected tiles instead, sparing those used since it last
//   passed (CLOCK).
// - The target (10 % to 100 % of the budget) shrinks by a tile each time a
//   remembered tile displaces a protected one (the working set is moving on:
//   probation needs the room) and grows by a tile each time one fails to (a
//   loop longer than the cache: protect more of it).
// In a loop longer than the budget every protected tile is reused before a
// newcomer's reuse distance comes round, so the protected set stays and only
// the rest is re-read each pass. The price: when a scan's working set moves on
// while the budget is between one and two loops, it is read up to twice where
// LRU reads it once. Figures with Belady's optimum of the same traces:
// tests/test_tile_cache.cpp (CyclicScan*, RowScan*).
//
// Lifetime: the cache is shared by shared_ptr among the maps that use it;
// defaultCache() is a function-local static created on first use, and maps
// keep their own reference, so it outlives any map that uses it.

#include "tile_cache_impl.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include "dsm/error.h"
#include "splitmix64.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

constexpr std::size_t kShardBits = 6;
constexpr std::size_t kShardCount = std::size_t(1) << kShardBits;
// Room kept on probation, in tiles: a bilinear footprint straddles two tiles in
// a row, and two tiles touched in turn must not evict each other.
constexpr std::uint64_t kProbationTiles = 2;

std::uint64_t hashKey(const TileKey& k) noexcept {
    return detail::mix64(k.file * 0x9E3779B97F4A7C15ull ^ ((std::uint64_t(k.level) << 32) | k.tile));
}

struct TileKeyHash {
    std::size_t operator()(const TileKey& k) const noexcept { return static_cast<std::size_t>(hashKey(k)); }
};

enum class Segment : std::uint8_t { loading, probation, protectedSet };

struct Entry {
    Entry(const TileKey& k, std::thread::id by) : key(k), loader(by) {}
    const TileKey key;

    // Guarded by the shard's mutex.
    std::shared_ptr<const void> data;  // set once, when the load succeeds
    std::exception_ptr error;          // set once, when the load fails
    std::thread::id loader;            // the thread reading it, while in flight

    // The epoch of the last request; hits store it without a lock.
    std::atomic<std::uint64_t> lastUse{0};

    // Guarded by the eviction mutex.
    std::size_t memoryBytes = 0;
    // On probation: when it was read or last put back on probation; protected:
    // when it was protected or the clock hand last passed it.
    std::uint64_t since = 0;
    Segment segment = Segment::loading;
    Entry* prev = nullptr;
    Entry* next = nullptr;

    std::uint64_t used() const { return lastUse.load(std::memory_order_relaxed); }
};

/// An intrusive doubly linked list of entries (the entries are owned by the
/// shards' maps).
class EntryList {
public:
    Entry* front() const { return head_; }
    std::uint64_t bytes() const { return bytes_; }
    /// The entry after `e`, wrapping round to the front.
    Entry* after(const Entry* e) const { return e->next ? e->next : head_; }

    /// Inserts `e` before `position` (at the back if null).
    void insert(Entry* e, Entry* position) {
        e->next = position;
        e->prev = position ? position->prev : tail_;
        (e->prev ? e->prev->next : head_) = e;
        (position ? position->prev : tail_) = e;
        bytes_ += e->memoryBytes;
    }
    void remove(Entry* e) {
        (e->prev ? e->prev->next : head_) = e->next;
        (e->next ? e->next->prev : tail_) = e->prev;
        e->prev = e->next = nullptr;
        bytes_ -= e->memoryBytes;
    }

private:
    Entry* head_ = nullptr;
    Entry* tail_ = nullptr;
    std::uint64_t bytes_ = 0;
};

/// Keys of recently evicted tiles with their last use, oldest first out.
class Ghosts {
public:
    void remember(const TileKey& key, std::uint64_t lastUse, std::size_t capacity) {
        order_.emplace_back(key, lastUse);
        lastUse_[key] = lastUse;
        // Records of keys taken back or remembered again stay in order_ until
        // they reach its front; bounding order_ too keeps memory bounded.
        while (lastUse_.size() > capacity || order_.size() > 2 * capacity) {
            const auto& [oldKey, oldUse] = order_.front();
            if (auto it = lastUse_.find(oldKey); it != lastUse_.end() && it->second == oldUse) lastUse_.erase(it);
            order_.pop_front();
        }
    }
    std::optional<std::uint64_t> take(const TileKey& key) {
        auto it = lastUse_.find(key);
        if (it == lastUse_.end()) return std::nullopt;
        const std::uint64_t lastUse = it->second;
        lastUse_.erase(it);
        return lastUse;
    }
    void clear() {
        lastUse_.clear();
        order_.clear();
    }

private:
    std::unordered_map<TileKey, std::uint64_t, TileKeyHash> lastUse_;
    std::deque<std::pair<TileKey, std::uint64_t>> order_;
};

// A hit writes only the mutex and the counters, which come first so that they
// share a cache line (with another thread's hits that line moves between
// cores; the map's own lines are only read).
struct alignas(64) Shard {
    std::mutex mutex;
    std::uint64_t hits = 0;
    std::uint64_t waits = 0;
    std::uint64_t misses = 0;
    std::condition_variable settled;  // an in-flight entry of this shard got its data or error
    std::unordered_map<TileKey, std::shared_ptr<Entry>, TileKeyHash> entries;
};

}  // namespace

struct TileCache::Impl::State {
    std::array<Shard, kShardCount> shards;
    alignas(64) std::atomic<std::uint64_t> epoch{0};
    std::atomic<std::uint64_t> nextFileId{1};

    // Everything below is guarded by evictionMutex.
    alignas(64) std::mutex evictionMutex;
    EntryList probation;
    EntryList protectedSet;
    Entry* hand = nullptr;  // the clock hand over protectedSet
    Ghosts ghosts;
    TileCacheStats stats;  // hits, misses and waits are kept by the shards

    Shard& shardOf(const TileKey& key) { return shards[hashKey(key) >> (64 - kShardBits)]; }

    void touch(Entry& e) const {
        const std::uint64_t now = epoch.load(std::memory_order_relaxed);
        if (e.used() != now) e.lastUse.store(now, std::memory_order_relaxed);
    }

    // The protected tiles' share of the budget adapts between 10 % and 100 %.
    std::uint64_t protectedTarget = 0;
    std::uint64_t leastProtected() const { return stats.budgetBytes / 10; }
    std::uint64_t mostProtected() const { return stats.budgetBytes; }
    void setBudget(std::uint64_t budgetBytes) {
        stats.budgetBytes = budgetBytes;
        protectedTarget = mostProtected();
    }

    void advanceHand() { hand = protectedSet.after(hand); }

    void unlink(Entry* e) {
        if (e->segment == Segment::protectedSet) {
            if (e == hand) {
                advanceHand();
                if (hand == e) hand = nullptr;  // it was the only one
            }
            protectedSet.remove(e);
        } else {
            probation.remove(e);
        }
    }

    void protect(Entry* e, std::uint64_t now) {
        e->segment = Segment::protectedSet;
        e->since = now;
        protectedSet.insert(e, hand);  // just behind the hand: examined last
        if (!hand) hand = e;
    }

    void putOnProbation(Entry* e, std::uint64_t now) {
        e->segment = Segment::probation;
        e->since = now;
        probation.insert(e, nullptr);
    }

    // Removes a resident entry; its reference goes to `dropped` (released after
    // unlocking). Anything that may throw happens before anything changes.
    void drop(Entry* e, bool isEviction, std::vector<std::shared_ptr<Entry>>& dropped) {
        if (isEviction) ghosts.remember(e->key, e->used(), 2 * stats.tilesInUse + 64);
        Shard& shard = shardOf(e->key);
        {
            std::lock_guard lock(shard.mutex);
            auto it = shard.entries.find(e->key);
            dropped.push_back(it->second);
            shard.entries.erase(it);
        }
        unlink(e);
        stats.bytesInUse -= e->memoryBytes;
        --stats.tilesInUse;
        if (isEviction) ++stats.evictions;
    }

    // The next step towards freeing memory: either evicts one tile or moves
    // one between the segments (bounded per call by `moves`).
    void evictOne(std::uint64_t now, std::size_t& moves, std::vector<std::shared_ptr<Entry>>& dropped) {
        Entry* oldest = probation.front();
        if (oldest && protectedSet.bytes() <= protectedTarget) {
            if (oldest->used() > oldest->since && moves > 0) {
                --moves;
                probation.remove(oldest);
                if (hand && hand->used() < oldest->since) {
                    Entry* idle = hand;
                    unlink(idle);
                    putOnProbation(idle, now);
                    protect(oldest, now);
                } else {
                    putOnProbation(oldest, oldest->used());
                }
                return;
            }
            return drop(oldest, true, dropped);
        }
        // Protected tiles above their target share, or nothing on probation: a
        // clock sweep sparing the tiles used since the hand last passed them (at
        // most one turn: it stamps them `now`).
        while (hand->used() > hand->since) {
            hand->since = now;
            advanceHand();
        }
        drop(hand, true, dropped);
    }

    void makeRoom(std::uint64_t incoming, std::vector<std::shared_ptr<Entry>>& dropped) {
        const std::uint64_t now = epoch.load(std::memory_order_relaxed);
        std::size_t moves = stats.tilesInUse;
        while (stats.bytesInUse + incoming > stats.budgetBytes && stats.tilesInUse > 0)
            evictOne(now, moves, dropped);
    }

    // Places a newly read entry (see the policy above).
    void admit(Entry* e, std::optional<std::uint64_t> previousUse, std::uint64_t now) {
        // Probation keeps room for kProbationTiles tiles like this one.
        const std::uint64_t probationRoom = kProbationTiles * std::uint64_t(e->memoryBytes);
        const auto limit = [&] {
            return std::min(protectedTarget, stats.budgetBytes > probationRoom ? stats.budgetBytes - probationRoom : 0);
        };
        if (protectedSet.bytes() + e->memoryBytes <= limit()) return protect(e, now);
        if (previousUse && hand && hand->used() < *previousUse) {
            // The working set is moving: give probation more room.
            protectedTarget -= std::min(protectedTarget - leastProtected(), std::uint64_t(e->memoryBytes));
            while (hand && protectedSet.bytes() + e->memoryBytes > limit()) {
                Entry* idle = hand;
                unlink(idle);
                putOnProbation(idle, now);
            }
            return protect(e, now);
        }
        if (previousUse && hand) {
            // A loop longer than the cache: protect more of it.
            protectedTarget = std::min(mostProtected(), protectedTarget + e->memoryBytes);
            advanceHand();  // compare with another protected tile next time
        }
        putOnProbation(e, now);
    }

    void notePeaks() {
        stats.peakBytesInUse = std::max(stats.peakBytesInUse, stats.bytesInUse);
        stats.peakTilesInUse = std::max(stats.peakTilesInUse, stats.tilesInUse);
    }

    // Makes a loaded entry resident and hands its data to the waiters.
    void complete(Shard& shard, const std::shared_ptr<Entry>& entry, LoadedTile& loaded) {
        std::vector<std::shared_ptr<Entry>> dropped;  // released after unlocking
        {
            std::lock_guard evictionLock(evictionMutex);
            const std::optional<std::uint64_t> previousUse = ghosts.take(entry->key);
            makeRoom(loaded.memoryBytes, dropped);
            std::lock_guard lock(shard.mutex);  // the last step that may throw
            ++stats.tilesRead;
            stats.bytesRead += loaded.fileBytes;
            entry->data = loaded.data;
            entry->loader = {};
            auto it = shard.entries.find(entry->key);
            if (it != shard.entries.end() && it->second == entry) {
                const std::uint64_t now = epoch.load(std::memory_order_relaxed) + 1;
                epoch.store(now, std::memory_order_relaxed);
                entry->memoryBytes = loaded.memoryBytes;
                entry->lastUse.store(now, std::memory_order_relaxed);
                admit(entry.get(), previousUse, now);
                stats.bytesInUse += loaded.memoryBytes;
                ++stats.tilesInUse;
                notePeaks();
            } else {
                ++stats.duplicateReads;  // never: an in-flight entry leaves only through its reader
            }
        }
        shard.settled.notify_all();
    }

    // Hands a failed load's exception to the waiters and forgets the entry.
    void fail(Shard& shard, const std::shared_ptr<Entry>& entry, std::exception_ptr error) {
        {
            std::lock_guard lock(shard.mutex);
            entry->error = std::move(error);
            entry->loader = {};
            if (auto it = shard.entries.find(entry->key); it != shard.entries.end() && it->second == entry)
                shard.entries.erase(it);
        }
        shard.settled.notify_all();
    }

    void dropAll(bool (*selected)(const Entry&, std::uint64_t), std::uint64_t file,
                 std::vector<std::shared_ptr<Entry>>& dropped) {
        for (EntryList* list : {&probation, &protectedSet}) {
            for (Entry* e = list->front(); e;) {
                Entry* next = e->next;
                if (selected(*e, file)) drop(e, false, dropped);
                e = next;
            }
        }
    }
};

TileCache::Impl::Impl(std::size_t budgetBytes) : state_(std::make_unique<State>()) { state_->setBudget(budgetBytes); }

TileCache::Impl::~Impl() = default;

std::shared_ptr<const void> TileCache::Impl::get(const TileKey& key, TileLoadFunction load, const void* context) {
    State& s = *state_;
    Shard& shard = s.shardOf(key);
    std::shared_ptr<Entry> entry;
    {
        std::unique_lock lock(shard.mutex);
        if (auto found = shard.entries.find(key); found != shard.entries.end()) {
            Entry& e = *found->second;
            ++shard.hits;
            if (e.data) {
                s.touch(e);
                return e.data;
            }
            if (e.loader == std::this_thread::get_id())
                throw Error(ErrorCode::internal, detail::concat("tile cache: the loader of file ", key.file, " level ",
                                                                key.level, " tile ", key.tile, " asked for that tile"));
            ++shard.waits;
            const std::shared_ptr<Entry> awaited = found->second;
            shard.settled.wait(lock, [&] { return awaited->data || awaited->error; });
            if (awaited->error) std::rethrow_exception(awaited->error);
            return awaited->data;
        }
        entry = std::make_shared<Entry>(key, std::this_thread::get_id());
        shard.entries.emplace(key, entry);
        ++shard.misses;
    }

    try {
        LoadedTile loaded = load(context);  // no lock held
        if (!loaded.data)
            throw Error(ErrorCode::internal, detail::concat("tile cache: the loader of file ", key.file, " level ",
                                                            key.level, " tile ", key.tile, " returned no data"));
        s.complete(shard, entry, loaded);
        return std::move(loaded.data);
    } catch (...) {
        // Whatever throws (the loader, or complete() before it changes
        // anything) leaves the entry in flight: fail it.
        s.fail(shard, entry, std::current_exception());
        throw;
    }
}

std::shared_ptr<const void> TileCache::Impl::find(const TileKey& key) {
    State& s = *state_;
    Shard& shard = s.shardOf(key);
    std::lock_guard lock(shard.mutex);
    auto found = shard.entries.find(key);
    if (found == shard.entries.end() || !found->second->data) return nullptr;
    ++shard.hits;
    s.touch(*found->second);
    return found->second->data;
}

std::uint64_t TileCache::Impl::newFileId() { return state_->nextFileId.fetch_add(1, std::memory_order_relaxed); }

void TileCache::Impl::forgetFile(std::uint64_t file) {
    State& s = *state_;
    std::vector<std::shared_ptr<Entry>> dropped;  // released after unlocking
    std::lock_guard lock(s.evictionMutex);
    s.dropAll([](const Entry& e, std::uint64_t f) { return e.key.file == f; }, file, dropped);
}

std::size_t TileCache::Impl::budget() const {
    std::lock_guard lock(state_->evictionMutex);
    return static_cast<std::size_t>(state_->stats.budgetBytes);
}

void TileCache::Impl::setBudget(std::size_t budgetBytes) {
    State& s = *state_;
    std::vector<std::shared_ptr<Entry>> dropped;  // released after unlocking
    std::lock_guard lock(s.evictionMutex);
    s.setBudget(budgetBytes);
    s.makeRoom(0, dropped);
}

TileCacheStats TileCache::Impl::stats() const {
    State& s = *state_;
    std::lock_guard lock(s.evictionMutex);
    TileCacheStats out = s.stats;
    for (Shard& shard : s.shards) {
        std::lock_guard shardLock(shard.mutex);
        out.hits += shard.hits;
        out.waits += shard.waits;
        out.misses += shard.misses;
    }
    return out;
}

void TileCache::Impl::resetStats() {
    State& s = *state_;
    std::lock_guard lock(s.evictionMutex);
    s.stats.tilesRead = 0;
    s.stats.bytesRead = 0;
    s.stats.evictions = 0;
    s.stats.duplicateReads = 0;
    s.stats.peakBytesInUse = s.stats.bytesInUse;
    s.stats.peakTilesInUse = s.stats.tilesInUse;
    for (Shard& shard : s.shards) {
        std::lock_guard shardLock(shard.mutex);
        shard.hits = shard.waits = shard.misses = 0;
    }
}

void TileCache::Impl::clear() {
    State& s = *state_;
    std::vector<std::shared_ptr<Entry>> dropped;  // released after unlocking
    std::lock_guard lock(s.evictionMutex);
    s.dropAll([](const Entry&, std::uint64_t) { return true; }, 0, dropped);
    s.ghosts.clear();
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
