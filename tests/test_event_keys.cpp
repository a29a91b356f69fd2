// The sweep's sorts of a pixel's event keys (libdsm/core/src/event_keys.h):
// the radix sort and the dispatch between it and the AVX-512 sort put event
// keys (numbered in array order, as the sweep makes them) in the order
// std::sort does, for every count to past the vector sort's limit, over
// depths close together, spread out, few, one, extreme, in order and
// reversed; the AVX-512 and AVX2 sorts do so for any keys (random, repeated,
// the extremes, in order, reversed); the dispatch prefers the wider vectors;
// and event keys order depths as floats do.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <functional>
#include <limits>
#include <random>
#include <vector>

#include "event_keys.h"

namespace {

using dsm::detail::eventKey;
using dsm::detail::kVectorSortLimit;

using Sort = std::function<std::vector<std::uint64_t>(std::vector<std::uint64_t>)>;

constexpr std::uint64_t kLargest = std::numeric_limits<std::uint64_t>::max();

void expectSortedAsStdSort(const Sort& sort, const std::vector<std::uint64_t>& keys, const char* kind) {
    std::vector<std::uint64_t> expected = keys;
    std::sort(expected.begin(), expected.end());
    ASSERT_EQ(sort(keys), expected) << kind << ", " << keys.size() << " keys";
}

// Event keys of every count in [1, most], numbered in array order as the
// sweep numbers them, over depths of several shapes.
void expectEventKeysSortedAsStdSort(const Sort& sort, std::size_t most) {
    std::mt19937_64 random(3);
    std::uniform_real_distribution<float> nearby(1.0f, 1.001f), spread(-1.0e6f, 1.0e6f);
    std::uniform_int_distribution<int> few(0, 5);
    const float inf = std::numeric_limits<float>::infinity();
    const float extremes[] = {inf, -inf, 0.0f, -0.0f, std::numeric_limits<float>::max(), 1.0e-30f, -2.0f};
    for (std::size_t n = 1; n <= most; ++n) {
        std::vector<std::uint64_t> keys(n);
        const auto numbered = [&](auto depthOf) {
            for (std::size_t i = 0; i < n; ++i) keys[i] = eventKey(depthOf(i), static_cast<std::uint32_t>(i));
        };
        for (int round = 0; round < 2; ++round) {
            numbered([&](std::size_t) { return nearby(random); });
            expectSortedAsStdSort(sort, keys, "nearby depths");
            numbered([&](std::size_t) { return spread(random); });
            expectSortedAsStdSort(sort, keys, "spread depths");
            numbered([&](std::size_t) { return 1.0f + 0.25f * static_cast<float>(few(random)); });
            expectSortedAsStdSort(sort, keys, "few depths");
        }
        // Depths whose bits differ only in their lowest 8, 16 or 24, and depths
        // bunched in a few values of their highest differing bits (the radix
        // sort's branches: one pass, two, the highest 12 bits then insertion,
        // and an exact sort where insertion would move keys too far).
        for (const std::uint32_t spreadBits : {8u, 16u, 24u}) {
            std::uniform_int_distribution<std::uint32_t> low(0, (1u << spreadBits) - 1);
            numbered([&](std::size_t) { return std::bit_cast<float>(0x3F800000u + low(random)); });
            expectSortedAsStdSort(sort, keys, "depths within a few bits");
        }
        for (const std::uint32_t jump : {1u << 20, 1u << 27}) {
            std::uniform_int_distribution<std::uint32_t> low(0, 4095);
            numbered([&](std::size_t) {
                return std::bit_cast<float>(0x30000000u + low(random) + (few(random) < 3 ? jump : 0u));
            });
            expectSortedAsStdSort(sort, keys, "bunched depths");
        }
        numbered([](std::size_t) { return 2.0f; });
        expectSortedAsStdSort(sort, keys, "one depth");
        numbered([&](std::size_t i) { return extremes[i % std::size(extremes)]; });
        expectSortedAsStdSort(sort, keys, "extremes");
        numbered([](std::size_t i) { return static_cast<float>(i); });
        expectSortedAsStdSort(sort, keys, "depths in order");
        numbered([&](std::size_t i) { return static_cast<float>(n - i); });
        expectSortedAsStdSort(sort, keys, "depths reversed");
    }
}

// Any keys of every count in [1, most]: random, repeated, the extremes, in
// order and reversed.
void expectAnyKeysSortedAsStdSort(const Sort& sort, std::size_t most) {
    std::mt19937_64 random(5);
    std::uniform_int_distribution<std::uint32_t> fewValues(0, 5);
    for (std::size_t n = 1; n <= most; ++n) {
        std::vector<std::uint64_t> keys(n);
        for (int round = 0; round < 2; ++round) {
            for (std::uint64_t& k : keys) k = random();
            expectSortedAsStdSort(sort, keys, "random");
            for (std::uint64_t& k : keys) k = fewValues(random);
            expectSortedAsStdSort(sort, keys, "repeated");
        }
        for (std::size_t i = 0; i < n; ++i) keys[i] = i % 3 == 0 ? kLargest : i % 3 == 1 ? 0 : kLargest - i;
        expectSortedAsStdSort(sort, keys, "extremes");
        for (std::size_t i = 0; i < n; ++i) keys[i] = i;
        expectSortedAsStdSort(sort, keys, "in order");
        std::reverse(keys.begin(), keys.end());
        expectSortedAsStdSort(sort, keys, "reversed");
    }
}

// Through a sort that may leave the keys in the scratch array.
Sort withScratch(std::uint64_t* (*sort)(std::uint64_t*, std::uint64_t*, std::size_t)) {
    return [sort](std::vector<std::uint64_t> keys) {
        std::vector<std::uint64_t> scratch(keys.size());
        const std::uint64_t* sorted = sort(keys.data(), scratch.data(), keys.size());
        return std::vector<std::uint64_t>(sorted, sorted + keys.size());
    };
}

TEST(EventKeys, RadixSortsAsStdSort) {
    expectEventKeysSortedAsStdSort(withScratch(&dsm::detail::sortEventKeysWithoutVectors), kVectorSortLimit + 300);
}

TEST(EventKeys, DispatchSortsAsStdSort) {
    expectEventKeysSortedAsStdSort(withScratch(&dsm::detail::sortEventKeys), kVectorSortLimit + 300);
}

// A vector sort, for any keys up to kVectorSortLimit and event keys up to
// the same, past the limit of runs the sweep gives it.
void expectVectorSortSortsAsStdSort(const dsm::detail::VectorKeySort& vector) {
    ASSERT_GT(vector.limit, 0u);
    ASSERT_LE(vector.limit, kVectorSortLimit);
    const Sort inPlace = [&vector](std::vector<std::uint64_t> keys) {
        vector.sort(keys.data(), keys.size());
        return keys;
    };
    expectAnyKeysSortedAsStdSort(inPlace, kVectorSortLimit);
    expectEventKeysSortedAsStdSort(inPlace, kVectorSortLimit);
}

TEST(EventKeys, Avx512SortsAsStdSort) {
    const dsm::detail::VectorKeySort vector = dsm::detail::avx512KeySort();
    if (vector.sort == nullptr) GTEST_SKIP() << "no AVX-512 in this build or on this processor";
    expectVectorSortSortsAsStdSort(vector);
}

TEST(EventKeys, Avx2SortsAsStdSort) {
    const dsm::detail::VectorKeySort vector = dsm::detail::avx2KeySort();
    if (vector.sort == nullptr) GTEST_SKIP() << "no AVX2 in this build or on this processor";
    expectVectorSortSortsAsStdSort(vector);
}

// The sweep's choice: the widest vectors the processor has.
TEST(EventKeys, DispatchPrefersAvx512ThenAvx2) {
    const dsm::detail::VectorKeySort chosen = dsm::detail::vectorKeySort();
    const dsm::detail::VectorKeySort avx512 = dsm::detail::avx512KeySort(), avx2 = dsm::detail::avx2KeySort();
    const dsm::detail::VectorKeySort expected = avx512.sort != nullptr ? avx512 : avx2;
    EXPECT_EQ(chosen.sort, expected.sort);
    EXPECT_EQ(chosen.limit, expected.limit);
    if (chosen.sort == nullptr) {
        EXPECT_EQ(chosen.limit, 0u);
    }
}

TEST(EventKeys, OrderDepthsAsFloatsAndTiesByIndex) {
    const float depths[] = {-std::numeric_limits<float>::infinity(), -3.5f, -1.0e-30f, -0.0f, 0.0f, 1.0e-30f,
                            0.25f, 7.0f, std::numeric_limits<float>::max(), std::numeric_limits<float>::infinity()};
    for (std::size_t a = 0; a < std::size(depths); ++a)
        for (std::size_t b = 0; b < std::size(depths); ++b) {
            const bool floatsBefore = depths[a] < depths[b] || (depths[a] == depths[b] && a < b);
            const auto keyOf = [&](std::size_t i) { return eventKey(depths[i], static_cast<std::uint32_t>(i)); };
            EXPECT_EQ(keyOf(a) < keyOf(b), floatsBefore)
                << depths[a] << " (" << a << ") against " << depths[b] << " (" << b << ")";
        }
}

}  // namespace
