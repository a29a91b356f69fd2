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
/// where the processor has them (vectorKeySort()), else
/// sortEventKeysWithoutVectors().
DSM_TESTED_INTERNAL std::uint64_t* sortEventKeys(std::uint64_t* keys, std::uint64_t* scratch, std::size_t n);

/// The same, with the same precondition, by insertion and radix sorts alone:
/// on processors without AVX2, for runs longer than the vector sort's limit,
/// and in tests.
DSM_TESTED_INTERNAL std::uint64_t* sortEventKeysWithoutVectors(std::uint64_t* keys, std::uint64_t* scratch,
                                                               std::size_t n);

/// The most keys a vector sort takes at once.
inline constexpr std::size_t kVectorSortLimit = 512;

/// A bitonic sort in vector registers (bitonic_key_sort.h): `sort` puts any
/// keys[0, n) in ascending order, for 0 < n <= kVectorSortLimit, and the sweep
/// gives it runs of up to `limit` keys, beyond which its log^2 n steps cost
/// more than the radix sort's passes (over the hair ball's pixels: 512 keys
/// with AVX-512's eight lanes, 128 with AVX2's four). No sort, and a limit of
/// 0, where this build or the processor lacks the instructions.
struct VectorKeySort {
    void (*sort)(std::uint64_t* keys, std::size_t n) = nullptr;
    std::size_t limit = 0;
};

/// The sorts for AVX-512 (event_keys_avx512.cpp) and AVX2 (event_keys_avx2.cpp).
DSM_TESTED_INTERNAL VectorKeySort avx512KeySort();
DSM_TESTED_INTERNAL VectorKeySort avx2KeySort();

/// The sort sortEventKeys() uses: AVX-512's where the processor has it, else
/// AVX2's, else none.
DSM_TESTED_INTERNAL VectorKeySort vectorKeySort();

}  // namespace dsm::detail
