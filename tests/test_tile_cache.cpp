// Tests for TileCache: counting, LRU order, the byte bound, lifetime of tiles
// handed out, failing loaders, forgetFile/clear/setBudget/resetStats, and
// concurrent use.
#include <gtest/gtest.h>

#include <dsm/error.h>
#include <dsm/tile_cache.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <iterator>
#include <list>
#include <memory>
#include <random>
#include <stdexcept>
#include <thread>
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

// A loader for `key` claiming `memoryBytes` of memory and `memoryBytes / 2`
// bytes read from the file. `calls`, if given, counts invocations.
std::function<LoadedTile()> loaderFor(TileKey key, std::size_t memoryBytes, int* calls = nullptr) {
    return [=]() {
        if (calls) ++*calls;
        auto t = std::make_shared<TestTile>();
        t->key = key;
        t->payload.resize(std::max<std::size_t>(1, memoryBytes / 64));
        for (std::size_t i = 0; i < t->payload.size(); ++i) t->payload[i] = word(key, i);
        return LoadedTile{t, memoryBytes, memoryBytes / 2};
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

// The reference: a plain LRU list under the documented rule (drop least
// recently used tiles until the new one fits; never drop the new one).
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
            ++evictions;
        }
        lru_.emplace_front(key, bytes);
        bytesInUse += bytes;
        return false;
    }
    std::size_t size() const { return lru_.size(); }
    std::uint64_t bytesInUse = 0;
    std::uint64_t evictions = 0;

private:
    std::uint64_t budget_;
    std::list<std::pair<TileKey, std::uint64_t>> lru_;
};

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
    EXPECT_EQ(s.tilesRead, 3u);
    EXPECT_EQ(s.bytesRead, 500u + 1000u + 2000u);  // fileBytes, not memoryBytes
    EXPECT_EQ(s.bytesInUse, 7000u);
    EXPECT_EQ(s.peakBytesInUse, 7000u);
    EXPECT_EQ(s.tilesInUse, 3u);
    EXPECT_EQ(s.evictions, 0u);

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

TEST(TileCache, EvictsLeastRecentlyUsedFirst) {
    auto cache = TileCache::create(30);  // three tiles of 10 bytes
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    const TileKey a{f, 0, 0}, b{f, 0, 1}, c{f, 0, 2}, d{f, 0, 3};
    get(*cache, a, 10);
    get(*cache, b, 10);
    get(*cache, c, 10);
    get(*cache, a, 10);  // a is now the most recent; b the least
    get(*cache, d, 10);  // evicts b
    EXPECT_EQ(cache->stats().evictions, 1u);
    EXPECT_EQ(cache->stats().tilesInUse, 3u);
    EXPECT_EQ(cache->stats().bytesInUse, 30u);

    int calls = 0;
    get(*cache, a, 10, &calls);
    get(*cache, c, 10, &calls);
    get(*cache, d, 10, &calls);
    EXPECT_EQ(calls, 0) << "a, c and d should have stayed";
    get(*cache, b, 10, &calls);  // miss; evicts a (least recent of a, c, d)
    EXPECT_EQ(calls, 1);
    get(*cache, c, 10, &calls);
    get(*cache, d, 10, &calls);
    get(*cache, b, 10, &calls);
    EXPECT_EQ(calls, 1);
    get(*cache, a, 10, &calls);
    EXPECT_EQ(calls, 2) << "a should have been evicted";
    EXPECT_EQ(cache->stats().evictions, 3u);
}

TEST(TileCache, EvictsSeveralSmallTilesForOneLarge) {
    auto cache = TileCache::create(100);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t i = 0; i < 10; ++i) get(*cache, {f, 0, i}, 10);
    EXPECT_EQ(cache->stats().bytesInUse, 100u);
    get(*cache, {f, 1, 0}, 35);  // needs four of the small tiles gone
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.evictions, 4u);
    EXPECT_EQ(s.bytesInUse, 95u);
    EXPECT_EQ(s.tilesInUse, 7u);
    int calls = 0;
    for (std::uint32_t i = 4; i < 10; ++i) get(*cache, {f, 0, i}, 10, &calls);
    EXPECT_EQ(calls, 0);
    get(*cache, {f, 0, 3}, 10, &calls);
    EXPECT_EQ(calls, 1);
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

    ModelLru model(budget);
    std::uint64_t maxSeen = 0;
    std::uint64_t hits = 0;
    for (int r = 0; r < 20000; ++r) {
        // Half the requests go to a small hot set, so there are hits as well as
        // misses and evictions.
        const std::size_t i = (r % 2) ? rng() % 8 : rng() % space.size();
        const KeyAndSize& k = space[i];
        const std::uint64_t missesBefore = cache->stats().misses;
        auto tile = get(*cache, k.key, k.bytes);
        ASSERT_TRUE(intact(tile, k.key)) << "request " << r;

        const bool modelHit = model.access(k.key, k.bytes);
        const TileCacheStats s = cache->stats();
        ASSERT_EQ(s.misses - missesBefore, modelHit ? 0u : 1u) << "request " << r;
        ASSERT_LE(s.bytesInUse, budget + largest) << "request " << r;
        ASSERT_LE(s.peakBytesInUse, budget + largest) << "request " << r;
        ASSERT_GE(s.peakBytesInUse, s.bytesInUse) << "request " << r;
        ASSERT_EQ(s.bytesInUse, model.bytesInUse) << "request " << r;
        ASSERT_EQ(s.tilesInUse, model.size()) << "request " << r;
        ASSERT_EQ(s.evictions, model.evictions) << "request " << r;
        maxSeen = std::max(maxSeen, s.bytesInUse);
        hits += modelHit;
    }
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.hits, hits);
    EXPECT_EQ(s.hits + s.misses, 20000u);
    EXPECT_EQ(s.tilesRead, s.misses);
    EXPECT_GE(s.peakBytesInUse, maxSeen);
    EXPECT_GT(s.hits, 1000u);
    EXPECT_GT(s.evictions, 1000u);
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

TEST(TileCache, LoaderRunsWithoutTheLockAndFirstFinishedLoadIsKept) {
    auto cache = TileCache::create(1000);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    const TileKey k{f, 0, 0};
    std::shared_ptr<const TestTile> inner;
    // The outer loader calls back into the cache (it would deadlock were a lock
    // held) and loads the same tile itself, as a second thread could: the inner
    // load finishes first and is the one kept.
    const auto outer = [&]() {
        (void)cache->stats();
        inner = get(*cache, k, 100);
        return loaderFor(k, 100)();
    };
    auto got = ImplAccess::of(*cache).get<TestTile>(k, outer);
    ASSERT_TRUE(inner);
    EXPECT_EQ(got.get(), inner.get());
    EXPECT_TRUE(intact(got, k));
    EXPECT_EQ(get(*cache, k, 100).get(), inner.get());
    const TileCacheStats s = cache->stats();
    EXPECT_EQ(s.misses, 2u);
    EXPECT_EQ(s.hits, 1u);
    EXPECT_EQ(s.tilesRead, 2u);  // both loads did read the file
    EXPECT_EQ(s.bytesRead, 100u);
    EXPECT_EQ(s.tilesInUse, 1u);
    EXPECT_EQ(s.bytesInUse, 100u);
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
    for (std::uint32_t i = 0; i < 5; ++i) get(*cache, {f, 0, i}, 20);
    get(*cache, {f, 0, 0}, 20);  // 0 becomes the most recent
    cache->setBudget(45);
    EXPECT_EQ(cache->budget(), 45u);
    TileCacheStats s = cache->stats();
    EXPECT_EQ(s.budgetBytes, 45u);
    EXPECT_EQ(s.tilesInUse, 2u);
    EXPECT_EQ(s.bytesInUse, 40u);
    EXPECT_EQ(s.evictions, 3u);
    int calls = 0;
    get(*cache, {f, 0, 0}, 20, &calls);
    get(*cache, {f, 0, 4}, 20, &calls);
    EXPECT_EQ(calls, 0) << "the two most recent tiles should remain";

    cache->setBudget(1000);  // growing evicts nothing
    EXPECT_EQ(cache->stats().tilesInUse, 2u);
    cache->setBudget(0);
    EXPECT_EQ(cache->stats().tilesInUse, 0u);
    EXPECT_EQ(cache->stats().bytesInUse, 0u);
    EXPECT_EQ(cache->stats().evictions, 5u);
}

TEST(TileCache, ResetStatsZeroesCountersAndRestartsPeak) {
    auto cache = TileCache::create(100);
    const std::uint64_t f = ImplAccess::of(*cache).newFileId();
    for (std::uint32_t i = 0; i < 8; ++i) get(*cache, {f, 0, i}, 30);
    get(*cache, {f, 0, 7}, 30);
    cache->setBudget(50);
    TileCacheStats s = cache->stats();
    ASSERT_EQ(s.peakBytesInUse, 90u);
    ASSERT_EQ(s.bytesInUse, 30u);
    ASSERT_GT(s.evictions, 0u);

    cache->resetStats();
    s = cache->stats();
    EXPECT_EQ(s.hits, 0u);
    EXPECT_EQ(s.misses, 0u);
    EXPECT_EQ(s.tilesRead, 0u);
    EXPECT_EQ(s.bytesRead, 0u);
    EXPECT_EQ(s.evictions, 0u);
    EXPECT_EQ(s.peakBytesInUse, 30u);
    EXPECT_EQ(s.bytesInUse, 30u);  // current use and budget untouched
    EXPECT_EQ(s.tilesInUse, 1u);
    EXPECT_EQ(s.budgetBytes, 50u);

    get(*cache, {f, 0, 7}, 30);
    get(*cache, {f, 1, 0}, 40);
    s = cache->stats();
    EXPECT_EQ(s.hits, 1u);
    EXPECT_EQ(s.misses, 1u);
    EXPECT_EQ(s.evictions, 1u);
    EXPECT_EQ(s.peakBytesInUse, 40u);
}

TEST(TileCache, ConcurrentGetsAreConsistent) {
    constexpr int kThreads = 8;
    constexpr int kRequests = 4000;
    const std::uint64_t budget = 32 * 1024;
    const std::uint64_t largest = 8192;
    auto cache = TileCache::create(budget);
    auto& inside = ImplAccess::of(*cache);
    const std::uint64_t files[] = {inside.newFileId(), inside.newFileId(), inside.newFileId()};

    std::atomic<std::uint64_t> loads{0}, loadedFileBytes{0}, failures{0}, bad{0}, overBudget{0};
    const auto sizeOf = [&](const TileKey& k) -> std::size_t { return (k.tile % 3 == 0) ? largest : 1024; };
    const auto worker = [&](int id) {
        std::mt19937 rng(1000 + id);
        for (int r = 0; r < kRequests; ++r) {
            const TileKey k{files[rng() % 3], std::uint32_t(rng() % 2), std::uint32_t(rng() % 48)};
            const bool fails = (k.level == 1 && k.tile % 11 == 5);
            const std::size_t bytes = sizeOf(k);
            try {
                auto t = ImplAccess::of(*cache).get<TestTile>(k, [&, k, bytes, fails]() {
                    if (fails) throw dsm::Error(dsm::ErrorCode::corrupt, "unreadable tile");
                    LoadedTile lt = loaderFor(k, bytes)();
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
        }
    };
    std::vector<std::thread> threads;
    for (int i = 0; i < kThreads; ++i) threads.emplace_back(worker, i);
    for (auto& t : threads) t.join();

    const TileCacheStats s = cache->stats();
    EXPECT_EQ(bad.load(), 0u);
    EXPECT_EQ(overBudget.load(), 0u);
    EXPECT_EQ(s.hits + s.misses, std::uint64_t(kThreads) * kRequests);
    EXPECT_EQ(s.tilesRead, loads.load());
    EXPECT_EQ(s.bytesRead, loadedFileBytes.load());
    EXPECT_EQ(s.misses, loads.load() + failures.load()) << "every miss runs the loader exactly once";
    EXPECT_GT(failures.load(), 0u);
    EXPECT_GT(s.hits, 0u);
    EXPECT_LE(s.bytesInUse, budget + largest);
    EXPECT_LE(s.peakBytesInUse, budget + largest);
    EXPECT_GT(s.evictions, 0u);
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
