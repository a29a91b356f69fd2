// The vector sort of a pixel's sweep events (libdsm/core/src/key_sort.h):
// for every count it takes, the same order as std::sort, over random keys,
// keys shaped like the sweep's (a depth's bits above an event's index),
// repeated keys, the extremes, and keys already in order or reversed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "key_sort.h"

namespace {

using dsm::detail::kVectorSortLimit;

void expectSortedAsStdSort(dsm::detail::VectorKeySort sort, std::vector<std::uint64_t> keys, const char* kind) {
    std::vector<std::uint64_t> expected = keys;
    std::sort(expected.begin(), expected.end());
    sort(keys.data(), keys.size());
    ASSERT_EQ(keys, expected) << kind << ", " << keys.size() << " keys";
}

TEST(KeySort, Avx512SortsAsStdSortForEveryCount) {
    const dsm::detail::VectorKeySort sort = dsm::detail::avx512KeySort();
    if (sort == nullptr) GTEST_SKIP() << "no AVX-512 in this build or on this processor";
    std::mt19937_64 random(3);
    std::uniform_int_distribution<std::uint32_t> fewValues(0, 5);
    std::uniform_int_distribution<std::uint32_t> nearbyDepths(0x3F800000u, 0x3F80FFFFu);
    constexpr std::uint64_t kLargest = std::numeric_limits<std::uint64_t>::max();
    for (std::size_t n = 1; n <= kVectorSortLimit; ++n) {
        for (int round = 0; round < 4; ++round) {
            std::vector<std::uint64_t> keys(n);
            for (std::uint64_t& k : keys) k = random();
            expectSortedAsStdSort(sort, keys, "random");
            for (std::size_t i = 0; i < n; ++i) keys[i] = std::uint64_t{nearbyDepths(random)} << 32 | i;
            expectSortedAsStdSort(sort, keys, "depths and indices");
            for (std::uint64_t& k : keys) k = fewValues(random);
            expectSortedAsStdSort(sort, keys, "repeated");
        }
        std::vector<std::uint64_t> keys(n);
        for (std::size_t i = 0; i < n; ++i) keys[i] = i % 3 == 0 ? kLargest : i % 3 == 1 ? 0 : kLargest - i;
        expectSortedAsStdSort(sort, keys, "extremes");
        for (std::size_t i = 0; i < n; ++i) keys[i] = i;
        expectSortedAsStdSort(sort, keys, "in order");
        std::reverse(keys.begin(), keys.end());
        expectSortedAsStdSort(sort, keys, "reversed");
    }
}

}  // namespace
