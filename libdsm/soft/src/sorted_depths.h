// Searching a layer's sorted vertex depths (internal).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace dsm::detail {

// The first of the sorted depths z[begin, end) at or beyond lo. Most layers
// are short: there, the count of depths before lo, a loop without branches
// that the compiler vectorises (a binary search mispredicts about half its
// steps); a binary search for long ones.
inline std::size_t firstAtOrBeyond(const float* z, std::size_t begin, std::size_t end, double lo) {
    constexpr std::size_t kCounted = 32;
    if (end - begin > kCounted || !(std::abs(lo) <= std::numeric_limits<float>::max()))
        return static_cast<std::size_t>(
            std::lower_bound(z + begin, z + end, lo, [](float zk, double q) { return zk < q; }) - z);
    // A float is below lo exactly when it is below the least float >= lo:
    // the count then compares floats, four or eight to an instruction.
    float least = static_cast<float>(lo);
    if (static_cast<double>(least) < lo) least = std::nextafter(least, std::numeric_limits<float>::infinity());
    std::uint32_t before = 0;
    for (std::size_t k = begin; k < end; ++k) before += z[k] < least ? 1u : 0u;
    return begin + before;
}

}  // namespace dsm::detail
