// The bitonic sort of event_keys.h, compiled for AVX-512 (this file alone is
// built with -mavx512f; event_keys.cpp hands it out only on processors that
// have it). The keys are padded with the largest key to 8 * 2^m, held as
// vectors of eight lanes: each vector is sorted by a network inside it, then
// sorted runs of vectors are merged pairwise, the second run reversed so that
// the pair is bitonic, until one run holds them all.
#if defined(__GNUC__) && !defined(__clang__)
// GCC 12 takes the undefined vector that the unmasked AVX-512 minimum,
// maximum and permutation pass to their masked builtins for an uninitialised
// read.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif

#include <immintrin.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "event_keys.h"

namespace dsm::detail {

namespace {

constexpr std::size_t kLanes = 8;
constexpr std::size_t kMostVectors = kVectorSortLimit / kLanes;
static_assert(kMostVectors == 64, "sortKeysAvx512() names each count of vectors below the most");

// Lane i's partner at distance j (lane i ^ j), for j = 1, 2, 4; and the lanes reversed.
alignas(64) constexpr std::int64_t kPartner1[kLanes] = {1, 0, 3, 2, 5, 4, 7, 6};
alignas(64) constexpr std::int64_t kPartner2[kLanes] = {2, 3, 0, 1, 6, 7, 4, 5};
alignas(64) constexpr std::int64_t kPartner4[kLanes] = {4, 5, 6, 7, 0, 1, 2, 3};
alignas(64) constexpr std::int64_t kReversed[kLanes] = {7, 6, 5, 4, 3, 2, 1, 0};

// The lanes that keep the larger of themselves and their partner at distance
// j, in blocks of k lanes sorted alternately up and down (a bitonic sort's
// step): the upper lane of a pair in a rising block, the lower in a falling one.
constexpr __mmask8 takesLarger(unsigned k, unsigned j) {
    unsigned mask = 0;
    for (unsigned lane = 0; lane < kLanes; ++lane)
        if (((lane & j) != 0) != ((lane & k) != 0)) mask |= 1u << lane;
    return static_cast<__mmask8>(mask);
}

__m512i load(const std::int64_t* lanes) { return _mm512_load_si512(lanes); }

// Each lane and its partner (at `partners`) ordered: `larger` lanes keep the larger key.
__m512i exchange(__m512i v, __m512i partners, __mmask8 larger) {
    const __m512i other = _mm512_permutexvar_epi64(partners, v);
    return _mm512_mask_blend_epi64(larger, _mm512_min_epu64(v, other), _mm512_max_epu64(v, other));
}

// The eight lanes sorted upward.
__m512i sortLanes(__m512i v) {
    const __m512i p1 = load(kPartner1), p2 = load(kPartner2), p4 = load(kPartner4);
    v = exchange(v, p1, takesLarger(2, 1));
    v = exchange(v, p2, takesLarger(4, 2));
    v = exchange(v, p1, takesLarger(4, 1));
    v = exchange(v, p4, takesLarger(8, 4));
    v = exchange(v, p2, takesLarger(8, 2));
    return exchange(v, p1, takesLarger(8, 1));
}

// A bitonic vector's lanes sorted upward.
__m512i mergeLanes(__m512i v) {
    v = exchange(v, load(kPartner4), takesLarger(8, 4));
    v = exchange(v, load(kPartner2), takesLarger(8, 2));
    return exchange(v, load(kPartner1), takesLarger(8, 1));
}

// Vectors a[0, Count) hold a bitonic sequence: sorted upward afterwards.
template <std::size_t Count>
void mergeBitonic(__m512i* a) {
    for (std::size_t stride = Count / 2; stride > 0; stride /= 2)
        for (std::size_t block = 0; block < Count; block += 2 * stride)
            for (std::size_t t = block; t < block + stride; ++t) {
                const __m512i low = _mm512_min_epu64(a[t], a[t + stride]);
                a[t + stride] = _mm512_max_epu64(a[t], a[t + stride]);
                a[t] = low;
            }
    for (std::size_t t = 0; t < Count; ++t) a[t] = mergeLanes(a[t]);
}

// Runs of Run sorted vectors merged in pairs, then runs twice as long, until
// one run holds all Vectors: the second run of a pair read backwards against
// the first, the smaller keys kept in the first, leaves two bitonic runs, each
// key of the first no larger than any of the second.
template <std::size_t Run, std::size_t Vectors>
void mergeRuns(__m512i* v) {
    if constexpr (Run < Vectors) {
        const __m512i reversed = load(kReversed);
        for (std::size_t first = 0; first < Vectors; first += 2 * Run) {
            __m512i* a = v + first;
            __m512i* b = a + Run;
            __m512i backwards[Run];
            for (std::size_t t = 0; t < Run; ++t) backwards[t] = _mm512_permutexvar_epi64(reversed, b[Run - 1 - t]);
            for (std::size_t t = 0; t < Run; ++t) {
                b[t] = _mm512_max_epu64(a[t], backwards[t]);
                a[t] = _mm512_min_epu64(a[t], backwards[t]);
            }
            mergeBitonic<Run>(a);
            mergeBitonic<Run>(b);
        }
        mergeRuns<2 * Run, Vectors>(v);
    }
}

// Sorts the Vectors * 8 keys at `keys` (aligned to 64 bytes), in vectors
// whose count is a constant, so that small sorts stay in registers.
template <std::size_t Vectors>
void sortVectors(std::uint64_t* keys) {
    __m512i v[Vectors];
    for (std::size_t t = 0; t < Vectors; ++t) v[t] = sortLanes(_mm512_load_si512(keys + t * kLanes));
    mergeRuns<1, Vectors>(v);
    for (std::size_t t = 0; t < Vectors; ++t) _mm512_store_si512(keys + t * kLanes, v[t]);
}

}  // namespace

void sortKeysAvx512(std::uint64_t* keys, std::size_t n) {
    std::size_t vectors = 1;
    while (vectors * kLanes < n) vectors *= 2;
    alignas(64) std::uint64_t padded[kVectorSortLimit];
    std::copy(keys, keys + n, padded);
    std::fill(padded + n, padded + vectors * kLanes, std::numeric_limits<std::uint64_t>::max());
    switch (vectors) {
        case 1: sortVectors<1>(padded); break;
        case 2: sortVectors<2>(padded); break;
        case 4: sortVectors<4>(padded); break;
        case 8: sortVectors<8>(padded); break;
        case 16: sortVectors<16>(padded); break;
        case 32: sortVectors<32>(padded); break;
        default: sortVectors<kMostVectors>(padded); break;
    }
    std::copy(padded, padded + n, keys);
}

}  // namespace dsm::detail
