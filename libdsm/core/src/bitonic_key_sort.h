// The bitonic sort of event_keys.h (internal), written once for each vector
// instruction set it is built for: event_keys_avx512.cpp and
// event_keys_avx2.cpp each include it, compiled with their own flags, and
// give it a `Lanes` type of their own (in an unnamed namespace, so that
// every use below is instantiated in that file alone). The keys are padded
// with the largest key to Lanes::kLanes * 2^m and held as vectors: each
// vector is sorted by a network inside it, then sorted runs of vectors are
// merged pairwise, the second run reversed so that the pair is bitonic,
// until one run holds them all.
//
// A Lanes type provides:
//   Vector, kLanes                    a register of kLanes 64-bit keys;
//   load(p), store(p, v)              from and to memory aligned to 64 bytes;
//   min(a, b), max(a, b)              lane by lane, in the keys' unsigned order;
//   sortLanes(a, b), mergeLanes(a, b) each of two vectors' lanes sorted upward,
//                                     from any order or from a bitonic one
//                                     (two at once: a pair can share shuffles);
//   reversed(v)                       the lanes in reverse order.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "event_keys.h"

namespace dsm::detail {
namespace {

// Calls f on the vectors a[0, Count) two at a time (one and a copy, if only one).
template <std::size_t Count, class Vector, class F>
void eachPair(Vector* a, F&& f) {
    if constexpr (Count == 1) {
        Vector copy = a[0];
        f(a[0], copy);
    } else {
        for (std::size_t t = 0; t < Count; t += 2) f(a[t], a[t + 1]);
    }
}

// Vectors a[0, Count) hold a bitonic sequence: sorted upward afterwards.
template <class Lanes, std::size_t Count>
void mergeBitonic(typename Lanes::Vector* a) {
    for (std::size_t stride = Count / 2; stride > 0; stride /= 2)
        for (std::size_t block = 0; block < Count; block += 2 * stride)
            for (std::size_t t = block; t < block + stride; ++t) {
                const typename Lanes::Vector low = Lanes::min(a[t], a[t + stride]);
                a[t + stride] = Lanes::max(a[t], a[t + stride]);
                a[t] = low;
            }
    eachPair<Count>(a, [](auto& first, auto& second) { Lanes::mergeLanes(first, second); });
}

// Runs of Run sorted vectors merged in pairs, then runs twice as long, until
// one run holds all Vectors: the second run of a pair read backwards against
// the first, the smaller keys kept in the first, leaves two bitonic runs, each
// key of the first no larger than any of the second.
template <class Lanes, std::size_t Run, std::size_t Vectors>
void mergeRuns(typename Lanes::Vector* v) {
    if constexpr (Run < Vectors) {
        for (std::size_t first = 0; first < Vectors; first += 2 * Run) {
            typename Lanes::Vector* a = v + first;
            typename Lanes::Vector* b = a + Run;
            typename Lanes::Vector backwards[Run];
            for (std::size_t t = 0; t < Run; ++t) backwards[t] = Lanes::reversed(b[Run - 1 - t]);
            for (std::size_t t = 0; t < Run; ++t) {
                b[t] = Lanes::max(a[t], backwards[t]);
                a[t] = Lanes::min(a[t], backwards[t]);
            }
            mergeBitonic<Lanes, Run>(a);
            mergeBitonic<Lanes, Run>(b);
        }
        mergeRuns<Lanes, 2 * Run, Vectors>(v);
    }
}

// Sorts the Vectors * kLanes keys at `keys`, in vectors whose count is a
// constant, so that small sorts stay in registers.
template <class Lanes, std::size_t Vectors>
void sortVectors(std::uint64_t* keys) {
    typename Lanes::Vector v[Vectors];
    for (std::size_t t = 0; t < Vectors; ++t) v[t] = Lanes::load(keys + t * Lanes::kLanes);
    eachPair<Vectors>(v, [](auto& first, auto& second) { Lanes::sortLanes(first, second); });
    mergeRuns<Lanes, 1, Vectors>(v);
    for (std::size_t t = 0; t < Vectors; ++t) Lanes::store(keys + t * Lanes::kLanes, v[t]);
}

// sortVectors() for the count of vectors given, a power of two.
template <class Lanes, std::size_t Vectors = 1>
void sortPadded(std::uint64_t* keys, std::size_t vectors) {
    if constexpr (Vectors * Lanes::kLanes < kVectorSortLimit) {
        if (vectors > Vectors) return sortPadded<Lanes, 2 * Vectors>(keys, vectors);
    }
    sortVectors<Lanes, Vectors>(keys);
}

// Sorts any keys[0, n) in ascending order, for 0 < n <= kVectorSortLimit.
template <class Lanes>
void bitonicSortKeys(std::uint64_t* keys, std::size_t n) {
    static_assert(kVectorSortLimit % Lanes::kLanes == 0, "the limit fills whole vectors");
    std::size_t vectors = 1;
    while (vectors * Lanes::kLanes < n) vectors *= 2;
    alignas(64) std::uint64_t padded[kVectorSortLimit];
    std::copy(keys, keys + n, padded);
    std::fill(padded + n, padded + vectors * Lanes::kLanes, std::numeric_limits<std::uint64_t>::max());
    sortPadded<Lanes>(padded, vectors);
    std::copy(padded, padded + n, keys);
}

}  // namespace
}  // namespace dsm::detail
