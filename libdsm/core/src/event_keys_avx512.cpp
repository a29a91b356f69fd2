// The bitonic sort of event_keys.h for AVX-512 (bitonic_key_sort.h): eight
// keys a vector. This file alone is built with -mavx512f; event_keys.cpp
// hands it out only on processors that have it.
#if defined(__GNUC__) && !defined(__clang__)
// GCC 12 takes the undefined vector that the unmasked AVX-512 minimum,
// maximum and permutation pass to their masked builtins for an uninitialised
// read.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif

#include <immintrin.h>

#include <cstddef>
#include <cstdint>

#include "bitonic_key_sort.h"
#include "event_keys.h"

namespace dsm::detail {

namespace {

// The lanes that keep the larger of themselves and their partner at distance
// j, in blocks of k lanes sorted alternately up and down (a bitonic sort's
// step): the upper lane of a pair in a rising block, the lower in a falling one.
constexpr unsigned takesLarger(unsigned lanes, unsigned k, unsigned j) {
    unsigned mask = 0;
    for (unsigned lane = 0; lane < lanes; ++lane)
        if (((lane & j) != 0) != ((lane & k) != 0)) mask |= 1u << lane;
    return mask;
}

struct Avx512Lanes {
    using Vector = __m512i;
    static constexpr std::size_t kLanes = 8;

    static Vector load(const std::uint64_t* keys) { return _mm512_load_si512(keys); }
    static void store(std::uint64_t* keys, Vector v) { _mm512_store_si512(keys, v); }
    static Vector min(Vector a, Vector b) { return _mm512_min_epu64(a, b); }
    static Vector max(Vector a, Vector b) { return _mm512_max_epu64(a, b); }

    // Lane i's partner at distance j (lane i ^ j), for j = 1, 2, 4; and the lanes reversed.
    static Vector partners1() { return _mm512_set_epi64(6, 7, 4, 5, 2, 3, 0, 1); }
    static Vector partners2() { return _mm512_set_epi64(5, 4, 7, 6, 1, 0, 3, 2); }
    static Vector partners4() { return _mm512_set_epi64(3, 2, 1, 0, 7, 6, 5, 4); }
    static Vector reversed(Vector v) { return _mm512_permutexvar_epi64(_mm512_set_epi64(0, 1, 2, 3, 4, 5, 6, 7), v); }

    // Each lane and its partner (at `partners`) ordered: `larger` lanes keep the larger key.
    static Vector exchange(Vector v, Vector partners, unsigned larger) {
        const Vector other = _mm512_permutexvar_epi64(partners, v);
        return _mm512_mask_blend_epi64(static_cast<__mmask8>(larger), min(v, other), max(v, other));
    }

    static Vector mergeLanes(Vector v) {
        v = exchange(v, partners4(), takesLarger(kLanes, 8, 4));
        v = exchange(v, partners2(), takesLarger(kLanes, 8, 2));
        return exchange(v, partners1(), takesLarger(kLanes, 8, 1));
    }
    static Vector sortLanes(Vector v) {
        v = exchange(v, partners1(), takesLarger(kLanes, 2, 1));
        v = exchange(v, partners2(), takesLarger(kLanes, 4, 2));
        v = exchange(v, partners1(), takesLarger(kLanes, 4, 1));
        return mergeLanes(v);
    }
    // Eight lanes fill a vector's network: a pair shares nothing.
    static void mergeLanes(Vector& a, Vector& b) { a = mergeLanes(a), b = mergeLanes(b); }
    static void sortLanes(Vector& a, Vector& b) { a = sortLanes(a), b = sortLanes(b); }
};

}  // namespace

void sortKeysAvx512(std::uint64_t* keys, std::size_t n) { bitonicSortKeys<Avx512Lanes>(keys, n); }

}  // namespace dsm::detail
