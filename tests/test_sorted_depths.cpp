// The first of a layer's sorted depths at or beyond a query depth
// (sorted_depths.h, internal): the same index as std::lower_bound for short
// layers (counted) and long ones (searched), for query depths between floats,
// on them, and beyond float range.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "sorted_depths.h"

namespace {

std::size_t reference(const std::vector<float>& z, std::size_t begin, std::size_t end, double lo) {
    return static_cast<std::size_t>(
        std::lower_bound(z.begin() + static_cast<std::ptrdiff_t>(begin), z.begin() + static_cast<std::ptrdiff_t>(end),
                         lo, [](float zk, double q) { return zk < q; }) -
        z.begin());
}

TEST(SortedDepths, FirstAtOrBeyondIsTheLowerBound) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<float> depth(0.01f, 100.0f);
    const double inf = std::numeric_limits<double>::infinity();
    int checked = 0;
    for (int trial = 0; trial < 4000; ++trial) {
        const std::size_t n = 1 + rng() % 80;  // both sides of the counted length
        std::vector<float> z(n);
        for (float& d : z) d = depth(rng);
        if (trial % 3 == 0)  // runs of equal depths (steps)
            for (std::size_t k = 1; k < n; ++k)
                if (rng() % 2) z[k] = z[k - 1];
        std::sort(z.begin(), z.end());
        const std::size_t begin = rng() % n, end = begin + rng() % (n - begin + 1);
        const float pick = z[rng() % n];
        const std::vector<double> queries = {
            pick,                                                        // on a depth
            std::nextafter(double(pick), -inf),                          // just below it, between floats
            std::nextafter(double(pick), inf),                           // just above it, between floats
            std::nextafter(double(std::nextafter(pick, -1.0f)), inf),    // just above the float below
            double(depth(rng)), -1.0, 0.0, 1e300, -1e300, inf, -inf};
        for (const double lo : queries) {
            ASSERT_EQ(dsm::detail::firstAtOrBeyond(z.data(), begin, end, lo), reference(z, begin, end, lo))
                << "n " << n << ", [" << begin << ", " << end << "), lo " << lo;
            ++checked;
        }
    }
    EXPECT_GT(checked, 40000);
}

}  // namespace
