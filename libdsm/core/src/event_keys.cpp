#include "event_keys.h"

#include <functional>
#include <utility>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "insertion_sort.h"

namespace dsm::detail {

namespace {

// Runs this short are sorted by insertion (the keys are distinct).
constexpr std::size_t kInsertionLimit = 24;

// Turns the counts of `digits` digits (a multiple of 4) into where each
// digit's keys start (an exclusive prefix sum). A pixel sorts about a hundred
// keys, so these additions are much of a pass: with SSE2, four digits at a
// time.
void startsOfDigits(std::uint32_t* offset, int digits) {
#ifdef __SSE2__
    __m128i carried = _mm_setzero_si128();  // the sum of the digits before, in every lane
    for (int d = 0; d < digits; d += 4) {
        const __m128i counts = _mm_loadu_si128(reinterpret_cast<const __m128i*>(offset + d));
        __m128i through = _mm_add_epi32(counts, _mm_slli_si128(counts, 4));
        through = _mm_add_epi32(_mm_add_epi32(through, _mm_slli_si128(through, 8)), carried);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(offset + d), _mm_sub_epi32(through, counts));
        carried = _mm_shuffle_epi32(through, 0xFF);
    }
#else
    std::uint32_t sum = 0;
    for (int d = 0; d < digits; ++d) sum += std::exchange(offset[d], sum);
#endif
}

// One stable radix pass per `Bits` bits of the depth, bits [low, low + Bits
// Passes), lowest first, from `keys` through `scratch`: returns where the
// sorted keys are.
template <int Passes, int Bits = 8>
std::uint64_t* radixSortByDepth(std::uint64_t* keys, std::uint64_t* scratch, std::size_t n, int low) {
    constexpr int kDigits = 1 << Bits;
    constexpr std::uint32_t kMask = kDigits - 1;
    std::uint32_t offsets[Passes][kDigits] = {};
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t depth = depthOf(keys[i]) >> low;
        for (int b = 0; b < Passes; ++b) ++offsets[b][(depth >> (Bits * b)) & kMask];
    }
    std::uint64_t* from = keys;
    std::uint64_t* to = scratch;
    for (int b = 0; b < Passes; ++b) {
        std::uint32_t* offset = offsets[b];
        startsOfDigits(offset, kDigits);
        const int shift = 32 + low + Bits * b;
        for (std::size_t i = 0; i < n; ++i) to[offset[(from[i] >> shift) & kMask]++] = from[i];
        std::swap(from, to);
    }
    return from;
}

// Finishes sorting keys[0, n) by insertion, unless that would move them more
// than `budget` places in all: true when sorted.
bool insertionSortWithin(std::uint64_t* keys, std::size_t n, std::size_t budget) {
    for (std::size_t i = 1; i < n; ++i) {
        const std::uint64_t key = keys[i];
        if (!(key < keys[i - 1])) continue;  // most keys are in place already: one comparison
        std::size_t j = i;
        do {
            keys[j] = keys[j - 1];
            --j;
        } while (j > 0 && key < keys[j - 1]);
        keys[j] = key;
        const std::size_t moved = i - j;
        if (moved > budget) return false;
        budget -= moved;
    }
    return true;
}

}  // namespace

// Sorts keys[0, n) into (depth, input) order and returns where they are
// (keys or scratch, room for n each): inputs whose steps are all gathered in
// input order, each key (depth << 32 | event index), so that a stable sort
// on the depth alone keeps ties in input order, the heap's order, and so
// does a sort of the whole keys. Small runs by insertion (keys are unique);
// longer ones by a stable radix sort of the depth's bits in which two keys
// differ (depths within a pixel share their top byte or two): all of them
// when there are at most 16; otherwise the 12 highest, in two passes of 64
// digits, and insertion finishes: each key then lies among the few with the
// same high bits (on the hair ball, 1.1 % fewer instructions in a whole
// build than two passes of 256 digits over the 16 highest, and fewer than a
// third pass). Keys bunched in a few values of those bits would make
// insertion quadratic: past a budget of moves, an exact radix sort of the
// keys as they are finishes instead. Few comparisons that a processor could
// mispredict, unlike the heap's.
std::uint64_t* sortEventKeysWithoutVectors(std::uint64_t* keys, std::uint64_t* scratch, std::size_t n) {
    constexpr std::size_t kMovesPerKey = 4;
    if (n <= kInsertionLimit) {
        insertionSort(keys, n, std::less<>());
        return keys;
    }
    const std::uint32_t first = depthOf(keys[0]);
    std::uint32_t differ = 0;
    for (std::size_t i = 1; i < n; ++i) differ |= depthOf(keys[i]) ^ first;
    const int width = std::bit_width(differ);
    if (width == 0) return keys;  // one depth: in input order already
    if (width <= 8) return radixSortByDepth<1>(keys, scratch, n, 0);
    if (width <= 16) return radixSortByDepth<2>(keys, scratch, n, 0);
    std::uint64_t* sorted = radixSortByDepth<2, 6>(keys, scratch, n, width - 12);
    if (insertionSortWithin(sorted, n, kMovesPerKey * n)) return sorted;
    std::uint64_t* other = sorted == keys ? scratch : keys;
    return width <= 24 ? radixSortByDepth<3>(sorted, other, n, 0) : radixSortByDepth<4>(sorted, other, n, 0);
}

// Where the processor has AVX-512 or AVX2, runs of up to the vector sort's
// limit go to a bitonic sort in its registers instead: the same order (the
// keys are distinct), in about 60 % of the time over the hair ball's pixels
// with AVX-512 and 83 % with AVX2.
std::uint64_t* sortEventKeys(std::uint64_t* keys, std::uint64_t* scratch, std::size_t n) {
    static const VectorKeySort vectorSort = vectorKeySort();
    if (n > kInsertionLimit && n <= vectorSort.limit) {
        vectorSort.sort(keys, n);
        return keys;
    }
    return sortEventKeysWithoutVectors(keys, scratch, n);
}

#ifdef DSM_KEY_SORT_VECTORS
void sortKeysAvx512(std::uint64_t* keys, std::size_t n);  // event_keys_avx512.cpp
void sortKeysAvx2(std::uint64_t* keys, std::size_t n);    // event_keys_avx2.cpp

// The longest runs the sweep gives the AVX2 sort: with four keys a vector it
// lost to the radix sort from 257 keys on over the hair ball's pixels, and a
// limit of 256 gained nothing in all.
constexpr std::size_t kAvx2SortLimit = 128;

VectorKeySort avx512KeySort() {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f") ? VectorKeySort{&sortKeysAvx512, kVectorSortLimit} : VectorKeySort{};
}
VectorKeySort avx2KeySort() {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") ? VectorKeySort{&sortKeysAvx2, kAvx2SortLimit} : VectorKeySort{};
}
#else
VectorKeySort avx512KeySort() { return {}; }
VectorKeySort avx2KeySort() { return {}; }
#endif

VectorKeySort vectorKeySort() {
    const VectorKeySort avx512 = avx512KeySort();
    return avx512.sort != nullptr ? avx512 : avx2KeySort();
}

}  // namespace dsm::detail
