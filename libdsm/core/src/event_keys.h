// A pixel's sweep events as 64-bit keys, and their sorting (internal): the
// sweep (sweep.cpp) numbers a pixel's events, about a hundred, and sorts
// them by depth before summing them in that order.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>

#include "tested_internal.h"

namespace dsm::detail {

// A key ordering events as (depth, index): the depth's float bits mapped to
// an unsigned order (-0 as +0, so that equal depths give equal keys) above
// the index of the input (in the heap) or of the event, numbered in input
// order (in the flat path). Ties between inputs at one depth are thus taken
// in input order, and the order of floating-point updates is fixed; one
// integer comparison orders two events.
inline std::uint64_t eventKey(float z, std::uint32_t input) {
    std::uint32_t bits = std::bit_cast<std::uint32_t>(z);
    if (bits == 0x80000000u) bits = 0;
    bits = (bits & 0x80000000u) ? ~bits : bits | 0x80000000u;
    return std::uint64_t{bits} << 32 | input;
}
inline std::uint32_t depthOf(std::uint64_t key) { return static_cast<std::uint32_t>(key >> 32); }
inline std::uint32_t inputOf(std::uint64_t key) { return static_cast<std::uint32_t>(key); }

/// Sorts keys[0, n) in ascending order and returns where they are (keys or
/// scratch, room for n each). Each keys[i] must hold i in its low 32 bits
/// (events numbered in array order, as the sweep makes them): the radix sort
/// orders by depth alone, keeping ties in array order. Vector instructions
/// where the processor has them (avx512KeySort()), else
/// sortEventKeysWithoutVectors().
DSM_TESTED_INTERNAL std::uint64_t* sortEventKeys(std::uint64_t* keys, std::uint64_t* scratch, std::size_t n);

/// The same, with the same precondition, by insertion and radix sorts alone:
/// on processors without AVX-512, for runs longer than kVectorSortLimit, and
/// in tests.
DSM_TESTED_INTERNAL std::uint64_t* sortEventKeysWithoutVectors(std::uint64_t* keys, std::uint64_t* scratch,
                                                               std::size_t n);

/// The most keys the vector sort takes at once: beyond about 512 a bitonic
/// network's log^2 n steps cost more than the radix sort's passes.
inline constexpr std::size_t kVectorSortLimit = 512;

/// Sorts any keys[0, n) in ascending order, for 0 < n <= kVectorSortLimit.
using VectorKeySort = void (*)(std::uint64_t* keys, std::size_t n);

/// The AVX-512 sort (a bitonic network, event_keys_avx512.cpp) where this
/// build has it and the processor runs it; null otherwise.
DSM_TESTED_INTERNAL VectorKeySort avx512KeySort();

}  // namespace dsm::detail
