// Tests for TileCache: counting, the eviction policy (scan and loop
// resistance, measured against LRU and Belady's optimum), the byte bound,
// lifetime of tiles handed out, failing loaders, one read per tile however many
// threads ask, forgetFile/clear/setBudget/resetStats/find, and concurrent use.
#include <gtest/gtest.h>

#include <dsm/error.h>
#include <dsm/tile_cache.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <iterator>
#include <latch>
#include <limits>
#include <list>
#include <memory>
#include <random>
#include <set>
#include <stdexcept>
#include <thread>
#include <unordered_map>
#include <vector>

#include "impl_access.h"
#include "tile_cache_impl.h"

namespace {

using dsm::ImplAccess;
using dsm::LoadedTile;
using dsm::TileCache;
using dsm::TileCacheStats;
using dsm::TileKey;

// A decoded tile as far as the cache is concerned: its key and a payload whose
// every word is derived from the key, so a tile can be checked for damage.
struct TestTile {
    TileKey key;
    std::vector<std::uint64_t> payload;
};

std::uint64_t word(const TileKey& k, std::size_t i) {
    std::uint64_t h = (k.file * 0x9E3779B97F4A7C15ull) ^ (std::uint64_t(k.level) << 40) ^ (std::uint64_t(k.tile) << 8) ^ i;
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    return h ^ (h >> 29);
}

LoadedTile makeTile(const TileKey& key, std::size_t memoryBytes) {
    auto t = std::make_shared<TestTile>();
    t->key = key;
    t->payload.resize(std::max<std::size_t>(1, memoryBytes / 64));
    for (std::size_t i = 0; i < t->payload.size(); ++i) t->payload[i] = word(key, i);
    return LoadedTile{t, memoryBytes, memoryBytes / 2};
}

// A loader for `key` claiming `memoryBytes` of memory and `memoryBytes / 2`
// bytes read from the file. `calls`, if given, counts invocations.
auto loaderFor(TileKey key, std::size_t memoryBytes, int* calls = nullptr) {
    return [=]() {
        if (calls) ++*calls;
        return makeTile(key, memoryBytes);
    };
}

bool intact(const std::shared_ptr<const TestTile>& t, const TileKey& key) {
    if (!t || !(t->key == key) || t->payload.empty()) return false;
    for (std::size_t i = 0; i < t->payload.size(); ++i)
        if (t->payload[i] != word(key, i)) return false;
    return true;
}

std::shared_ptr<const TestTile> get(TileCache& cache, const TileKey& key, std::size_t bytes, int* calls = nullptr) {
    return ImplAccess::of(cache).get<TestTile>(key, loaderFor(key, bytes, calls));
}

bool resident(TileCache& cache, const TileKey& key) { return ImplAccess::of(cache).find(key) != nullptr; }

// Waits (up to 20 s) until `count` requests are waiting for another thread's
// read: what a loader does to hold its read open until the others queue up.
void awaitWaiters(TileCache& cache, std::uint64_t count) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (cache.stats().waits < count && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

// The reference for what LRU would read: a plain LRU list (drop least recently
// used tiles until the new one fits; never drop the new one).
class ModelLru {
public:
    explicit ModelLru(std::uint64_t budget) : budget_(budget) {}
    // Returns true on a hit.
    bool access(const TileKey& key, std::uint64_t bytes) {
        for (auto it = lru_.begin(); it != lru_.end(); ++it) {
            if (it->first == key) {
                lru_.splice(lru_.begin(), lru_, it);
                return true;
            }
        }
        while (!lru_.empty() && bytesInUse + bytes > budget_) {
            bytesInUse -= lru_.back().second;
            lru_.pop_back();
        }
        lru_.emplace_front(key, bytes);
        bytesInUse += bytes;
        ++reads;
        return false;
    }
    std::uint64_t bytesInUse = 0;
    std::uint64_t reads = 0;

private:
    std::uint64_t budget_;
    std::list<std::pair<TileKey, std::uint64_t>> lru_;
};

// Traces of tile numbers, all tiles of one size: what the policy tests replay.
using Trace = std::vector<std::uint32_t>;
constexpr std::size_t kTraceTileBytes = 1000;

// Belady's MIN: the fewest reads any cache holding `capacity` tiles can do for
// `trace` (on a miss, evict the tile whose next use is furthest away).
std::uint64_t optimalReads(const Trace& trace, std::size_t capacity) {
    constexpr std::size_t never = std::numeric_limits<std::size_t>::max();
    std::vector<std::size_t> nextUse(trace.size());
    std::unordered_map<std::uint32_t, std::size_t> following;
    for (std::size_t i = trace.size(); i-- > 0;) {
        auto it = following.find(trace[i]);
        nextUse[i] = it == following.end() ? never : it->second;
        following[trace[i]] = i;
    }
    std::set<std::pair<std::size_t, std::uint32_t>> byNextUse;
    std::unordered_map<std::uint32_t, std::size_t> held;  // tile -> its next use
    std::uint64_t reads = 0;
    for (std::size_t i = 0; i < trace.size(); ++i) {
        const std::uint32_t t = trace[i];
        if (auto it = held.find(t); it != held.end()) {
            byNextUse.erase({it->second, t});
        } else {
            ++reads;
            if (held.size() == capacity) {
                const auto furthest = std::prev(byNextUse.end());
                held.erase(furthest->second);
                byNextUse.erase(furthest);
            }
        }
        held[t] = nextUse[i];
        byNextUse.insert({nextUse[i], t});
    }
    return reads;
}

std::uint64_t lruReads(const Trace& trace, std::size_t capacity) {
    ModelLru lru(capacity * kTraceTileBytes);
    for (std::uint32_t t : trace) lru.access(TileKey{1, 0, t}, kTraceTileBytes);
    return lru.reads;
}

// Replays `trace` through a TileCache holding `capacity` tiles; returns the
// tiles it read.
std::uint64_t cacheReads(const Trace& trace, std::size_t capacity) {
    auto cache = TileCache::create(capacity * kTraceTileBytes);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t t : trace) {
        const TileKey k{f, 0, t};
        if (!intact(get(*cache, k, kTraceTileBytes), k)) ADD_FAILURE() << "tile " << t;
    }
    const TileCacheStats s = cache->stats();
    EXPECT_LE(s.peakBytesInUse, capacity * kTraceTileBytes);
    return s.tilesRead;
}

// Bilinear lookups in scanline order over a map of tilesX x tilesY tiles of
// tileSize² pixels: the tiles each lookup's four pixels fall in, repeats of
// the previous tile left out (a lookup context keeps its last tile).
Trace rowScan(std::uint32_t tilesX, std::uint32_t tilesY, std::uint32_t tileSize) {
    const std::uint32_t width = tilesX * tileSize, height = tilesY * tileSize;
    Trace trace;
    const auto touch = [&](std::uint32_t x, std::uint32_t y) {
        const std::uint32_t t = std::min(y, height - 1) / tileSize * tilesX + std::min(x, width - 1) / tileSize;
        if (trace.empty() || trace.back() != t) trace.push_back(t);
    };
    for (std::uint32_t y = 0; y < height; ++y)
        for (std::uint32_t x = 0; x < width; ++x) {
            touch(x, y);
            touch(x + 1, y);
            touch(x, y + 1);
            touch(x + 1, y + 1);
        }
    return trace;
}

TEST(TileCache, CountsHitsMissesAndBytesRead) {
    auto cache = TileCache::create(1 << 20);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    int calls = 0;
    const TileKey a{f, 0, 1}, b{f, 0, 2}, c{f, 1, 1};

    EXPECT_TRUE(intact(get(*cache, a, 1000, &calls), a));
    EXPECT_TRUE(intact(get(*cache, b, 2000, &calls), b));
    EXPECT_TRUE(intact(get(*cache, a, 1000, &calls), a));
    EXPECT_TRUE(intact(get(*cache, c, 4000, &calls), c));
    EXPECT_TRUE(intact(get(*cache, b, 2000, &calls), b));
    EXPECT_TRUE(intact(get(*cache, a, 1000, &calls), a));
    EXPECT_EQ(calls, 3);

    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.budgetBytes, 1u << 20);
    EXPECT_EQ(s.hits, 3u);
    EXPECT_EQ(s.misses, 3u);
    EXPECT_EQ(s.waits, 0u);
    EXPECT_EQ(s.tilesRead, 3u);
    EXPECT_EQ(s.bytesRead, 500u + 1000u + 2000u);  // fileBytes, not memoryBytes
    EXPECT_EQ(s.bytesInUse, 7000u);
    EXPECT_EQ(s.peakBytesInUse, 7000u);
    EXPECT_EQ(s.tilesInUse, 3u);
    EXPECT_EQ(s.peakTilesInUse, 3u);
    EXPECT_EQ(s.evictions, 0u);
    EXPECT_EQ(s.duplicateReads, 0u);

    // The public and internal views agree.
    const TileCacheStats t = ImplAccess::of(*cache).stats();
    EXPECT_EQ(t.hits, s.hits);
    EXPECT_EQ(t.bytesInUse, s.bytesInUse);
    EXPECT_EQ(cache->budget(), ImplAccess::of(*cache).budget());
}

TEST(TileCache, DistinguishesFileLevelAndTile) {
    auto cache = TileCache::create(1 << 20);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    const std::uint64_t g = ImplAccess::of(*cache).newFileId();
    EXPECT_NE(f, g);
    const TileKey keys[] = {{f, 0, 0}, {f, 0, 1}, {f, 1, 0}, {g, 0, 0}, {f, 1, 1}, {g, 1, 0}};
    for (const TileKey& k : keys) EXPECT_TRUE(intact(get(*cache, k, 100), k));
    for (const TileKey& k : keys) EXPECT_TRUE(intact(get(*cache, k, 100), k));
    EXPECT_EQ(cache->stats().misses, 6u);
    EXPECT_EQ(cache->stats().hits, 6u);
}

TEST(TileCache, FindReturnsOnlyResidentTilesAndNeverLoads) {
    auto cache = TileCache::create(1 << 20);
    auto& inside = ImplAccess::of(*cache);
    const TileKey k{inside.newFileId(), 0, 4};
    EXPECT_EQ(inside.find(k), nullptr);
    EXPECT_EQ(cache->stats().hits + cache->stats().misses, 0u) << "a failed find is not a request";
    std::shared_ptr<const void> duringLoad = std::make_shared<int>(0);
    const auto held = inside.get(k, [&] {
        duringLoad = inside.find(k);  // in flight: not resident yet, and find does not wait
        return makeTile(k, 100);
    });
    EXPECT_EQ(duringLoad, nullptr);
    EXPECT_EQ(inside.find(k), held);
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.misses, 1u);
    EXPECT_EQ(s.hits, 1u);
    EXPECT_EQ(s.tilesRead, 1u);
}

TEST(TileCache, ProbationGoesFirstThenProtectedTilesInClockOrder) {
    // New tiles are protected while probation keeps room for two tiles like
    // them (0..7 here); later tiles are on probation and leave first.
    auto cache = TileCache::create(100);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t i = 0; i < 11; ++i) get(*cache, {f, 0, i}, 10);  // 10 evicts 8
    EXPECT_EQ(cache->stats().evictions, 1u);
    EXPECT_EQ(cache->stats().bytesInUse, 100u);

    // One large tile needs 35 bytes: probation goes (9, 10), then the clock
    // hand takes protected tiles in the order they came (0, 1).
    get(*cache, {f, 1, 0}, 35);
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.evictions, 5u);
    EXPECT_EQ(s.bytesInUse, 95u);
    EXPECT_EQ(s.tilesInUse, 7u);
    for (std::uint32_t i : {0u, 1u, 8u, 9u, 10u}) EXPECT_FALSE(resident(*cache, {f, 0, i})) << i;
    for (std::uint32_t i = 2; i < 8; ++i) EXPECT_TRUE(resident(*cache, {f, 0, i})) << i;
    EXPECT_TRUE(resident(*cache, {f, 1, 0}));
}

TEST(TileCache, AStreamOfNewTilesDoesNotFlushTilesInUse) {
    // Eight tiles in use, touched after every five new ones, in a cache of ten
    // tiles: LRU evicts tiles in use whenever the stream passes them by; here
    // the newcomers only replace one another on probation.
    constexpr std::size_t kBytes = 10;
    constexpr std::uint32_t kInUse = 8, kStream = 300;
    auto cache = TileCache::create(10 * kBytes);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    ModelLru lru(10 * kBytes);
    std::vector<int> inUseReads(kInUse, 0);
    for (std::uint32_t stream = 0; stream < kStream; ++stream) {
        if (stream % 5 == 0)
            for (std::uint32_t h = 0; h < kInUse; ++h) {
                ASSERT_TRUE(intact(get(*cache, {f, 0, h}, kBytes, &inUseReads[h]), (TileKey{f, 0, h})));
                lru.access({f, 0, h}, kBytes);
            }
        get(*cache, {f, 1, stream}, kBytes);
        lru.access({f, 1, stream}, kBytes);
    }
    for (std::uint32_t h = 0; h < kInUse; ++h) EXPECT_EQ(inUseReads[h], 1) << "tile in use " << h << " was read again";
    EXPECT_EQ(cache->stats().tilesRead, kInUse + kStream);
    EXPECT_GT(lru.reads, kInUse + kStream + 100) << "the trace should defeat LRU";
}

TEST(TileCache, CyclicScanLongerThanTheBudgetKeepsAProtectedSet) {
    // A loop over N tiles, K times, in a cache of C < N tiles. The first pass
    // reads N and protects the first P = C - 2 tiles (probation keeps room for
    // two). In every later pass the protected tiles are all hit: a re-read
    // tile displaces a protected one only if that one has been idle longer than
    // the newcomer's reuse distance, and in a loop every protected tile was used
    // after the newcomer last was. The other N - P tiles cycle through the C - P
    // probation places, first in first out, each gone before its turn comes
    // round: N - P reads per pass. Hence reads = N + (K - 1)(N - P).
    constexpr std::size_t N = 40, K = 16, C = 36, P = C - 2;
    Trace loop;
    for (std::size_t pass = 0; pass < K; ++pass)
        for (std::uint32_t t = 0; t < N; ++t) loop.push_back(t);
    const std::uint64_t ours = cacheReads(loop, C);
    const std::uint64_t optimum = optimalReads(loop, C);
    const std::uint64_t lru = lruReads(loop, C);
    std::printf("[ cyclic scan ] %zu tiles x %zu passes, cache of %zu tiles: reads %llu (%.2f x tiles), "
                "LRU %llu (%.2f x), optimum %llu (%.2f x)\n",
                N, K, C, static_cast<unsigned long long>(ours), double(ours) / N,
                static_cast<unsigned long long>(lru), double(lru) / N, static_cast<unsigned long long>(optimum),
                double(optimum) / N);
    EXPECT_LE(ours, N + (K - 1) * (N - P));
    EXPECT_GE(ours, optimum);
    EXPECT_EQ(lru, N * K) << "LRU reads every tile every pass";
}

TEST(TileCache, RowScanBelowOneTileRowAgainstTheOptimum) {
    // Bilinear lookups in scanline order over a 512² map of 32² tiles (16 x 16
    // tiles) with budgets around one tile row: tiles read / tiles in the map for
    // this cache, LRU and Belady's optimum (no demand cache can read less).
    const std::uint32_t tilesX = 16, tilesY = 16, tileSize = 32;
    const Trace scan = rowScan(tilesX, tilesY, tileSize);
    const double tiles = double(tilesX) * tilesY;
    for (const double rows : {0.5, 0.9, 1.2, 2.5}) {
        const auto capacity = static_cast<std::size_t>(rows * tilesX);
        const std::uint64_t ours = cacheReads(scan, capacity);
        const std::uint64_t optimum = optimalReads(scan, capacity);
        const std::uint64_t lru = lruReads(scan, capacity);
        std::printf("[ row scan ] budget %.1f tile rows (%zu tiles): reads / tiles %.2f, LRU %.2f, optimum %.2f\n",
                    rows, capacity, double(ours) / tiles, double(lru) / tiles, double(optimum) / tiles);
        EXPECT_GE(ours, optimum);
        if (rows == 0.9) {
            // Within a tile row the protected set (P = C - 2 tiles) stays, as in
            // the cyclic test: each pixel row reads the tilesX - P others. The
            // first pixel row of a tile row reads every tile, the last one (its
            // footprint interleaves the next row's tiles) up to two rows' worth:
            // per tile row at most 3 tilesX + (tileSize - 1)(tilesX - P).
            const std::uint64_t P = capacity - 2;
            EXPECT_LE(ours, tilesY * (3 * tilesX + (tileSize - 1) * (tilesX - P)));
            EXPECT_LT(3 * ours, lru) << "LRU reads each tile once per pixel row";
        } else if (rows > 1.0) {
            // The working set moves on row by row: at most one more read per
            // tile than LRU (see tile_cache.cpp).
            EXPECT_LE(ours, lru + tilesX * tilesY) << rows;
        }
    }
}

TEST(TileCache, StaysWithinBudgetUnderRandomAccess) {
    const std::uint64_t budget = 64 * 1024;
    const std::size_t sizes[] = {512, 4096, 16384, 1000};
    const std::uint64_t largest = 16384;
    auto cache = TileCache::create(budget);
    const std::uint64_t files[] = {ImplAccess::of(*cache).newFileId(), ImplAccess::of(*cache).newFileId()};

    // A key space ten times the budget; each key has a fixed size.
    struct KeyAndSize {
        TileKey key;
        std::size_t bytes;
    };
    std::vector<KeyAndSize> space;
    std::uint64_t total = 0;
    std::mt19937_64 rng(12345);
    for (std::uint32_t i = 0; total < 10 * budget; ++i) {
        const std::size_t bytes = sizes[rng() % std::size(sizes)];
        space.push_back({TileKey{files[i % 2], i % 3, i}, bytes});
        total += bytes;
    }

    std::uint64_t maxSeen = 0;
    std::uint64_t requests = 0;
    for (int r = 0; r < 20000; ++r) {
        // Half the requests go to a small hot set, so there are hits as well as
        // misses and evictions.
        const std::size_t i = (r % 2) ? rng() % 8 : rng() % space.size();
        const KeyAndSize& k = space[i];
        auto tile = get(*cache, k.key, k.bytes);
        ++requests;
        ASSERT_TRUE(intact(tile, k.key)) << "request " << r;

        TileCacheStats s = cache->stats();
        ASSERT_LE(s.bytesInUse, budget + largest) << "request " << r;
        ASSERT_LE(s.peakBytesInUse, budget + largest) << "request " << r;
        ASSERT_GE(s.peakBytesInUse, s.bytesInUse) << "request " << r;
        ASSERT_EQ(s.hits + s.misses, requests) << "request " << r;
        maxSeen = std::max(maxSeen, s.bytesInUse);
        if (r % 1000 == 999) {
            // The counts agree with what is actually resident.
            std::uint64_t bytes = 0, count = 0;
            for (const KeyAndSize& x : space)
                if (resident(*cache, x.key)) {
                    bytes += x.bytes;
                    ++count;
                }
            s = cache->stats();
            ASSERT_EQ(s.bytesInUse, bytes) << "request " << r;
            ASSERT_EQ(s.tilesInUse, count) << "request " << r;
            requests += count;  // find() counted its hits
        }
    }
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.tilesRead, s.misses);
    EXPECT_GE(s.peakBytesInUse, maxSeen);
    EXPECT_GT(s.hits, 5000u);
    EXPECT_GT(s.evictions, 1000u);
    EXPECT_EQ(s.duplicateReads, 0u);
}

TEST(TileCache, LoaderMayUseTheCacheButNotAskForItsOwnTile) {
    auto cache = TileCache::create(1000);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    const TileKey k{f, 0, 0}, other{f, 0, 1};
    std::shared_ptr<const TestTile> inner;
    bool ownTileRefused = false;
    // The loader calls back into the cache (it would deadlock were a lock
    // held): another tile loads; its own tile, being read, is refused.
    const auto outer = [&]() {
        (void)cache->stats();
        inner = get(*cache, other, 100);
        try {
            get(*cache, k, 100);
        } catch (const dsm::Error& e) {
            ownTileRefused = e.code() == dsm::ErrorCode::internal;
        }
        return makeTile(k, 100);
    };
    auto got = ImplAccess::of(*cache).get<TestTile>(k, outer);
    EXPECT_TRUE(ownTileRefused);
    EXPECT_TRUE(intact(inner, other));
    EXPECT_TRUE(intact(got, k));
    EXPECT_EQ(get(*cache, k, 100).get(), got.get());
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.tilesRead, 2u);
    EXPECT_EQ(s.tilesInUse, 2u);
    EXPECT_EQ(s.waits, 0u);
}

TEST(TileCache, ManyThreadsMissingOneTileReadItOnce) {
    constexpr int kThreads = 8;
    auto cache = TileCache::create(1 << 20);
    const TileKey k{ImplAccess::of(*cache).newFileId(), 3, 9};
    std::atomic<int> loads{0};
    std::vector<std::shared_ptr<const TestTile>> got(kThreads);
    std::latch start(kThreads);
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([&, t] {
            start.arrive_and_wait();
            got[t] = ImplAccess::of(*cache).get<TestTile>(k, [&] {
                ++loads;
                awaitWaiters(*cache, kThreads - 1);  // hold the read until every other thread waits
                return makeTile(k, 4096);
            });
        });
    for (auto& t : threads) t.join();
    EXPECT_EQ(loads.load(), 1);
    for (int t = 0; t < kThreads; ++t) {
        EXPECT_TRUE(intact(got[t], k));
        EXPECT_EQ(got[t].get(), got[0].get()) << "every thread receives the one tile read";
    }
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.misses, 1u);
    EXPECT_EQ(s.hits, kThreads - 1u);
    EXPECT_EQ(s.waits, kThreads - 1u);
    EXPECT_EQ(s.tilesRead, 1u);
    EXPECT_EQ(s.duplicateReads, 0u);
}

TEST(TileCache, FailedReadReachesEveryWaiterAndALaterRequestRetries) {
    constexpr int kThreads = 6;
    auto cache = TileCache::create(1 << 20);
    const TileKey k{ImplAccess::of(*cache).newFileId(), 0, 2};
    std::atomic<int> loads{0}, failures{0};
    std::latch start(kThreads);
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([&] {
            start.arrive_and_wait();
            try {
                ImplAccess::of(*cache).get<TestTile>(k, [&]() -> LoadedTile {
                    ++loads;
                    awaitWaiters(*cache, kThreads - 1);
                    throw dsm::Error(dsm::ErrorCode::io, "tile 2: read failed");
                });
            } catch (const dsm::Error& e) {
                if (e.code() == dsm::ErrorCode::io && std::string(e.what()).find("tile 2") != std::string::npos)
                    ++failures;
            }
        });
    for (auto& t : threads) t.join();
    EXPECT_EQ(loads.load(), 1);
    EXPECT_EQ(failures.load(), kThreads) << "every waiter receives the reader's exception";
    TileCacheStats s = cache->stats();
    EXPECT_EQ(s.tilesInUse, 0u);
    EXPECT_EQ(s.tilesRead, 0u);
    EXPECT_EQ(s.waits, kThreads - 1u);

    int calls = 0;
    EXPECT_TRUE(intact(get(*cache, k, 100, &calls), k));
    EXPECT_EQ(calls, 1) << "a failed read is not remembered";
    s = cache->stats();
    EXPECT_EQ(s.tilesRead, 1u);
    EXPECT_EQ(s.tilesInUse, 1u);
}

TEST(TileCache, EightThreadsHammeringOneMapNeverReadATileTwiceAtOnce) {
    // 8 threads, random order over 400 tiles of 1..4 KiB, a budget of 5 % of
    // them: zero duplicate reads, every tile intact, the peak within budget plus
    // one tile.
    constexpr int kThreads = 8;
    constexpr int kRequests = 3000;
    constexpr std::uint32_t kTiles = 400;
    const auto sizeOf = [](std::uint32_t tile) -> std::size_t { return 1024 * (1 + tile % 4); };
    std::uint64_t total = 0;
    for (std::uint32_t t = 0; t < kTiles; ++t) total += sizeOf(t);
    const std::uint64_t budget = total / 20, largest = 4096;
    auto cache = TileCache::create(budget);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();

    std::vector<std::atomic<int>> reading(kTiles);  // reads of each tile in progress
    std::atomic<std::uint64_t> loads{0}, overlapping{0}, damaged{0};
    const auto worker = [&](int id) {
        std::mt19937 rng(77 + id);
        for (int r = 0; r < kRequests; ++r) {
            const std::uint32_t tile = rng() % kTiles;
            const TileKey k{f, 0, tile};
            auto t = ImplAccess::of(*cache).get<TestTile>(k, [&] {
                if (reading[tile].fetch_add(1) != 0) ++overlapping;
                ++loads;
                LoadedTile lt = makeTile(k, sizeOf(tile));
                reading[tile].fetch_sub(1);
                return lt;
            });
            if (!intact(t, k)) ++damaged;
        }
    };
    std::vector<std::thread> threads;
    for (int i = 0; i < kThreads; ++i) threads.emplace_back(worker, i);
    for (auto& t : threads) t.join();

    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.duplicateReads, 0u);
    EXPECT_EQ(overlapping.load(), 0u) << "two threads read one tile at once";
    EXPECT_EQ(damaged.load(), 0u);
    EXPECT_LE(s.peakBytesInUse, budget + largest);
    EXPECT_LE(s.bytesInUse, budget);
    EXPECT_EQ(s.hits + s.misses, std::uint64_t(kThreads) * kRequests);
    EXPECT_EQ(s.misses, loads.load());
    EXPECT_EQ(s.tilesRead, loads.load());
    EXPECT_GT(s.evictions, 0u);
    std::printf("[ hammer ] %d threads x %d requests, budget %llu of %llu bytes: hits %llu (waits %llu), "
                "reads %llu, duplicate reads %llu, peak %llu bytes\n",
                kThreads, kRequests, static_cast<unsigned long long>(budget), static_cast<unsigned long long>(total),
                static_cast<unsigned long long>(s.hits), static_cast<unsigned long long>(s.waits),
                static_cast<unsigned long long>(s.tilesRead), static_cast<unsigned long long>(s.duplicateReads),
                static_cast<unsigned long long>(s.peakBytesInUse));
}

TEST(TileCache, TileHeldByCallerSurvivesEviction) {
    auto cache = TileCache::create(1000);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    const TileKey a{f, 0, 0};
    auto held = get(*cache, a, 800);
    std::weak_ptr<const TestTile> weak = held;
    get(*cache, {f, 0, 1}, 800);  // evicts a
    EXPECT_EQ(cache->stats().evictions, 1u);
    EXPECT_EQ(cache->stats().tilesInUse, 1u);
    EXPECT_TRUE(intact(held, a));
    EXPECT_EQ(held.use_count(), 1) << "the cache should hold no reference any more";
    cache->clear();
    cache.reset();  // even the cache itself going away leaves the tile valid
    EXPECT_TRUE(intact(held, a));
    held.reset();
    EXPECT_TRUE(weak.expired());
}

TEST(TileCache, TileLargerThanBudgetIsReturnedAndCachedAlone) {
    auto cache = TileCache::create(100);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    get(*cache, {f, 0, 0}, 40);
    get(*cache, {f, 0, 1}, 40);
    const TileKey big{f, 1, 0};
    int calls = 0;
    EXPECT_TRUE(intact(get(*cache, big, 500, &calls), big));
    TileCacheStats s = cache->stats();
    EXPECT_EQ(s.tilesInUse, 1u);
    EXPECT_EQ(s.bytesInUse, 500u);
    EXPECT_EQ(s.peakBytesInUse, 500u);
    EXPECT_EQ(s.evictions, 2u);
    EXPECT_TRUE(intact(get(*cache, big, 500, &calls), big));
    EXPECT_EQ(calls, 1) << "the large tile should be cached until the next insertion";
    get(*cache, {f, 0, 2}, 40);
    s = cache->stats();
    EXPECT_EQ(s.tilesInUse, 1u);
    EXPECT_EQ(s.bytesInUse, 40u);
    EXPECT_EQ(s.evictions, 3u);
}

TEST(TileCache, ZeroBudgetKeepsOnlyTheLastTile) {
    auto cache = TileCache::create(0);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    int calls = 0;
    for (std::uint32_t i = 0; i < 5; ++i) {
        const TileKey k{f, 0, i};
        EXPECT_TRUE(intact(get(*cache, k, 64, &calls), k));
        EXPECT_TRUE(intact(get(*cache, k, 64, &calls), k));
        EXPECT_EQ(cache->stats().tilesInUse, 1u);
        EXPECT_EQ(cache->stats().bytesInUse, 64u);
    }
    EXPECT_EQ(calls, 5);
    EXPECT_EQ(cache->stats().hits, 5u);
    EXPECT_EQ(cache->stats().evictions, 4u);
}

TEST(TileCache, LoaderExceptionPropagatesAndCachesNothing) {
    auto cache = TileCache::create(1000);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    const TileKey k{f, 2, 7};
    get(*cache, {f, 0, 0}, 100);
    const auto failing = []() -> LoadedTile { throw dsm::Error(dsm::ErrorCode::corrupt, "bad tile"); };
    EXPECT_THROW(ImplAccess::of(*cache).get<TestTile>(k, failing), dsm::Error);
    EXPECT_THROW(ImplAccess::of(*cache).get<TestTile>(k, [] () -> LoadedTile { throw std::runtime_error("io"); }),
                 std::runtime_error);
    TileCacheStats s = cache->stats();
    EXPECT_EQ(s.tilesRead, 1u);
    EXPECT_EQ(s.bytesRead, 50u);
    EXPECT_EQ(s.tilesInUse, 1u);
    EXPECT_EQ(s.bytesInUse, 100u);
    EXPECT_EQ(s.misses, 3u);

    int calls = 0;
    EXPECT_TRUE(intact(get(*cache, k, 100, &calls), k));
    EXPECT_EQ(calls, 1) << "a failed load must not leave anything cached";
    EXPECT_TRUE(intact(get(*cache, k, 100, &calls), k));
    EXPECT_EQ(calls, 1);
    s = cache->stats();
    EXPECT_EQ(s.tilesRead, 2u);
    EXPECT_EQ(s.tilesInUse, 2u);
}

TEST(TileCache, LoaderReturningNoDataIsAnError) {
    auto cache = TileCache::create(1000);
    const TileKey k{ImplAccess::of(*cache).newFileId(), 0, 0};
    EXPECT_THROW(ImplAccess::of(*cache).get<TestTile>(k, [] { return LoadedTile{nullptr, 10, 10}; }), dsm::Error);
    EXPECT_EQ(cache->stats().tilesInUse, 0u);
    EXPECT_EQ(cache->stats().tilesRead, 0u);
}

TEST(TileCache, ForgetFileDropsOnlyThatFile) {
    auto cache = TileCache::create(1 << 20);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    const std::uint64_t g = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t i = 0; i < 4; ++i) {
        get(*cache, {f, i % 2, i}, 100);
        get(*cache, {g, i % 2, i}, 30);
    }
    auto held = get(*cache, {f, 0, 0}, 100);
    ImplAccess::of(*cache).forgetFile(f);
    TileCacheStats s = cache->stats();
    EXPECT_EQ(s.tilesInUse, 4u);
    EXPECT_EQ(s.bytesInUse, 120u);
    EXPECT_EQ(s.evictions, 0u) << "forgetting is not evicting";
    EXPECT_TRUE(intact(held, TileKey{f, 0, 0}));

    int calls = 0;
    for (std::uint32_t i = 0; i < 4; ++i) get(*cache, {g, i % 2, i}, 30, &calls);
    EXPECT_EQ(calls, 0);
    for (std::uint32_t i = 0; i < 4; ++i) get(*cache, {f, i % 2, i}, 100, &calls);
    EXPECT_EQ(calls, 4);
    ImplAccess::of(*cache).forgetFile(12345678);  // unknown file: nothing happens
    EXPECT_EQ(cache->stats().tilesInUse, 8u);
}

TEST(TileCache, ClearDropsEverything) {
    auto cache = TileCache::create(1 << 20);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t i = 0; i < 10; ++i) get(*cache, {f, 0, i}, 100);
    auto held = get(*cache, {f, 0, 3}, 100);
    cache->clear();
    TileCacheStats s = cache->stats();
    EXPECT_EQ(s.tilesInUse, 0u);
    EXPECT_EQ(s.bytesInUse, 0u);
    EXPECT_EQ(s.peakBytesInUse, 1000u);
    EXPECT_EQ(s.evictions, 0u);
    EXPECT_EQ(s.hits, 1u);
    EXPECT_TRUE(intact(held, TileKey{f, 0, 3}));
    int calls = 0;
    get(*cache, {f, 0, 3}, 100, &calls);
    EXPECT_EQ(calls, 1);
}

TEST(TileCache, SetBudgetShrinkingEvictsAtOnce) {
    auto cache = TileCache::create(100);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t i = 0; i < 5; ++i) get(*cache, {f, 0, i}, 20);  // 0..2 protected, 3 and 4 on probation
    get(*cache, {f, 0, 0}, 20);                                          // 0 is used again
    cache->setBudget(45);
    EXPECT_EQ(cache->budget(), 45u);
    TileCacheStats s = cache->stats();
    EXPECT_EQ(s.budgetBytes, 45u);
    EXPECT_EQ(s.tilesInUse, 2u);
    EXPECT_EQ(s.bytesInUse, 40u);
    EXPECT_EQ(s.evictions, 3u);
    // The protected tiles exceed the smaller budget: the clock spares 0 (used
    // since) and takes 1; then probation goes (3, 4).
    EXPECT_TRUE(resident(*cache, {f, 0, 0}));
    EXPECT_TRUE(resident(*cache, {f, 0, 2}));

    cache->setBudget(1000);  // growing evicts nothing
    EXPECT_EQ(cache->stats().tilesInUse, 2u);
    cache->setBudget(0);
    EXPECT_EQ(cache->stats().tilesInUse, 0u);
    EXPECT_EQ(cache->stats().bytesInUse, 0u);
    EXPECT_EQ(cache->stats().evictions, 5u);
}

TEST(TileCache, ResetStatsZeroesCountersAndRestartsPeaks) {
    auto cache = TileCache::create(100);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t i = 0; i < 8; ++i) get(*cache, {f, 0, i}, 30);  // 0 protected, 6 and 7 on probation
    get(*cache, {f, 0, 7}, 30);
    cache->setBudget(50);  // probation goes
    TileCacheStats s = cache->stats();
    ASSERT_EQ(s.peakBytesInUse, 90u);
    ASSERT_EQ(s.peakTilesInUse, 3u);
    ASSERT_EQ(s.bytesInUse, 30u);
    ASSERT_GT(s.evictions, 0u);
    ASSERT_GT(s.hits, 0u);

    cache->resetStats();
    s = cache->stats();
    EXPECT_EQ(s.hits, 0u);
    EXPECT_EQ(s.misses, 0u);
    EXPECT_EQ(s.waits, 0u);
    EXPECT_EQ(s.tilesRead, 0u);
    EXPECT_EQ(s.bytesRead, 0u);
    EXPECT_EQ(s.evictions, 0u);
    EXPECT_EQ(s.duplicateReads, 0u);
    EXPECT_EQ(s.peakBytesInUse, 30u);
    EXPECT_EQ(s.peakTilesInUse, 1u);
    EXPECT_EQ(s.bytesInUse, 30u);  // current use and budget untouched
    EXPECT_EQ(s.tilesInUse, 1u);
    EXPECT_EQ(s.budgetBytes, 50u);

    int calls = 0;
    get(*cache, {f, 0, 0}, 30, &calls);  // the one protected tile
    EXPECT_EQ(calls, 0) << "resetting the counters keeps the tiles";
    get(*cache, {f, 1, 0}, 40);
    s = cache->stats();
    EXPECT_EQ(s.hits, 1u);
    EXPECT_EQ(s.misses, 1u);
    EXPECT_EQ(s.evictions, 1u);
    EXPECT_EQ(s.peakBytesInUse, 40u);
    EXPECT_EQ(s.peakTilesInUse, 1u);
}

TEST(TileCache, ConcurrentGetsAreConsistent) {
    constexpr int kThreads = 8;
    constexpr int kRequests = 4000;
    const std::uint64_t budget = 32 * 1024;
    const std::uint64_t largest = 8192;
    auto cache = TileCache::create(budget);
    auto& inside = ImplAccess::of(*cache);
    const std::uint64_t files[] = {inside.newFileId(), inside.newFileId(), inside.newFileId()};

    std::atomic<std::uint64_t> loads{0}, loadedFileBytes{0}, loaderFailures{0}, failures{0}, bad{0}, overBudget{0};
    const auto sizeOf = [&](const TileKey& k) -> std::size_t { return (k.tile % 3 == 0) ? largest : 1024; };
    const auto worker = [&](int id) {
        std::mt19937 rng(1000 + id);
        for (int r = 0; r < kRequests; ++r) {
            const TileKey k{files[rng() % 3], std::uint32_t(rng() % 2), std::uint32_t(rng() % 48)};
            const bool fails = (k.level == 1 && k.tile % 11 == 5);
            const std::size_t bytes = sizeOf(k);
            try {
                auto t = ImplAccess::of(*cache).get<TestTile>(k, [&, k, bytes, fails]() {
                    if (fails) {
                        ++loaderFailures;
                        throw dsm::Error(dsm::ErrorCode::corrupt, "unreadable tile");
                    }
                    LoadedTile lt = makeTile(k, bytes);
                    ++loads;
                    loadedFileBytes += lt.fileBytes;
                    return lt;
                });
                if (!intact(t, k)) ++bad;
            } catch (const dsm::Error&) {
                ++failures;
            }
            if (r % 16 == 0 && cache->stats().bytesInUse > budget + largest) ++overBudget;
            // One thread also changes the budget and drops tiles now and then.
            if (id == 0 && r % 500 == 250) cache->setBudget(r % 1000 == 250 ? budget / 2 : budget);
            if (id == 1 && r % 1000 == 999) ImplAccess::of(*cache).forgetFile(files[2]);
            if (id == 2 && r % 1500 == 1499) cache->clear();
            if (id == 3 && r % 700 == 0) (void)ImplAccess::of(*cache).find(k);
        }
    };
    std::vector<std::thread> threads;
    for (int i = 0; i < kThreads; ++i) threads.emplace_back(worker, i);
    for (auto& t : threads) t.join();

    const TileCacheStats s = cache->stats();
    EXPECT_EQ(bad.load(), 0u);
    EXPECT_EQ(overBudget.load(), 0u);
    EXPECT_GE(s.hits + s.misses, std::uint64_t(kThreads) * kRequests);  // find() hits too
    EXPECT_EQ(s.tilesRead, loads.load());
    EXPECT_EQ(s.bytesRead, loadedFileBytes.load());
    EXPECT_EQ(s.misses, loads.load() + loaderFailures.load()) << "every miss runs the loader exactly once";
    EXPECT_GE(failures.load(), loaderFailures.load()) << "waiters receive failures too";
    EXPECT_GT(loaderFailures.load(), 0u);
    EXPECT_GT(s.hits, 0u);
    EXPECT_LE(s.bytesInUse, budget + largest);
    EXPECT_LE(s.peakBytesInUse, budget + largest);
    EXPECT_GT(s.evictions, 0u);
    EXPECT_EQ(s.duplicateReads, 0u);
}

TEST(TileCache, HitCostIsPrinted) {
    // The cost of a hit, every tile resident, one thread and two threads each
    // cycling over the tiles (figures only: timing depends on the machine).
    constexpr std::uint32_t kTiles = 4096;
    constexpr int kRequests = 200000;
    auto cache = TileCache::create(std::size_t(1) << 30);
    auto& inside = ImplAccess::of(*cache);
    const std::uint64_t f = inside.newFileId();
    for (std::uint32_t t = 0; t < kTiles; ++t) get(*cache, {f, 0, t}, 1000);
    for (const int threadCount : {1, 2}) {
        cache->resetStats();
        std::atomic<std::uint64_t> sum{0};
        const auto start = std::chrono::steady_clock::now();
        std::vector<std::thread> threads;
        for (int i = 0; i < threadCount; ++i)
            threads.emplace_back([&, i] {
                std::uint64_t local = 0;
                std::uint32_t t = static_cast<std::uint32_t>(i) * 977;
                for (int r = 0; r < kRequests; ++r) {
                    t = (t + 613) % kTiles;
                    // Captures like the map reader's loader (by reference).
                    const std::uint32_t level = t >> 30, tx = t, ty = t >> 29;
                    local += inside.get<TestTile>(TileKey{f, level, tx}, [&] {
                        return makeTile(TileKey{f, level, tx + ty}, 1000);
                    })->key.tile;
                }
                sum += local;
            });
        for (auto& th : threads) th.join();
        const double ns =
            std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start).count() / kRequests;
        std::printf("[ hit cost ] %d thread(s): %.1f ns per hit per thread (wall)\n", threadCount, ns);
        const TileCacheStats s = cache->stats();
        EXPECT_EQ(s.hits, std::uint64_t(threadCount) * kRequests);
        EXPECT_EQ(s.misses, 0u);
        EXPECT_GT(sum.load(), 0u);
    }
}

TEST(TileCache, DefaultCacheIsOneProcessWideInstance) {
    auto a = TileCache::defaultCache();
    auto b = TileCache::defaultCache();
    ASSERT_TRUE(a);
    EXPECT_EQ(a.get(), b.get());
    EXPECT_EQ(a->budget(), std::size_t(256) << 20);

    std::shared_ptr<TileCache> fromThreads[4];
    std::vector<std::thread> threads;
    for (auto& p : fromThreads) threads.emplace_back([&p] { p = TileCache::defaultCache(); });
    for (auto& t : threads) t.join();
    for (auto& p : fromThreads) EXPECT_EQ(p.get(), a.get());
}

}  // namespace
