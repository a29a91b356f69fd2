// The bitonic sort of event_keys.h for AVX2 (bitonic_key_sort.h): four keys
// a vector. AVX2 compares 64-bit integers as signed only, so the keys are
// held with their top bit flipped, which turns their unsigned order into the
// signed one. This file alone is built with -mavx2; event_keys.cpp hands it
// out only on processors that have AVX2, and the sweep takes it where they
// lack AVX-512.
#include <immintrin.h>

#include <cstddef>
#include <cstdint>

#include "bitonic_key_sort.h"
#include "event_keys.h"

namespace dsm::detail {

namespace {

struct Avx2Lanes {
    using Vector = __m256i;
    static constexpr std::size_t kLanes = 4;

    static Vector topBit() { return _mm256_set1_epi64x(static_cast<long long>(0x8000000000000000ull)); }
    static Vector load(const std::uint64_t* keys) {
        return _mm256_xor_si256(_mm256_load_si256(reinterpret_cast<const __m256i*>(keys)), topBit());
    }
    static void store(std::uint64_t* keys, Vector v) {
        _mm256_store_si256(reinterpret_cast<__m256i*>(keys), _mm256_xor_si256(v, topBit()));
    }
    static Vector min(Vector a, Vector b) { return _mm256_blendv_epi8(a, b, _mm256_cmpgt_epi64(a, b)); }
    static Vector max(Vector a, Vector b) { return _mm256_blendv_epi8(b, a, _mm256_cmpgt_epi64(a, b)); }
    static Vector reversed(Vector v) { return _mm256_permute4x64_epi64(v, 0x1B); }

    // A step of the network inside two vectors at once: their pairs of lanes
    // gathered into two vectors, the first of each pair in one and the second
    // in the other, so that one minimum and one maximum serve both. Pairs at
    // distance 2 are the vectors' halves; at distance 1, the lanes that
    // unpacking interleaves.
    static void mergeLanes(Vector& a, Vector& b) {
        const Vector low = _mm256_permute2x128_si256(a, b, 0x20), high = _mm256_permute2x128_si256(a, b, 0x31);
        const Vector lesser = min(low, high), greater = max(low, high);
        // Each half of `lesser` and of `greater` now holds a pair at distance 1.
        const Vector first = _mm256_unpacklo_epi64(lesser, greater), second = _mm256_unpackhi_epi64(lesser, greater);
        const Vector lesser1 = min(first, second), greater1 = max(first, second);
        const Vector even = _mm256_unpacklo_epi64(lesser1, greater1), odd = _mm256_unpackhi_epi64(lesser1, greater1);
        a = _mm256_permute2x128_si256(even, odd, 0x20);
        b = _mm256_permute2x128_si256(even, odd, 0x31);
    }
    // Pairs of lanes sorted, up in each vector's lower half and down in its
    // upper half, then each bitonic vector merged.
    static void sortLanes(Vector& a, Vector& b) {
        const Vector first = _mm256_unpacklo_epi64(a, b), second = _mm256_unpackhi_epi64(a, b);
        const Vector lesser = min(first, second), greater = max(first, second);
        const Vector lower = _mm256_blend_epi32(lesser, greater, 0xF0);
        const Vector upper = _mm256_blend_epi32(greater, lesser, 0xF0);
        a = _mm256_unpacklo_epi64(lower, upper);
        b = _mm256_unpackhi_epi64(lower, upper);
        mergeLanes(a, b);
    }
};

}  // namespace

void sortKeysAvx2(std::uint64_t* keys, std::size_t n) { bitonicSortKeys<Avx2Lanes>(keys, n); }

}  // namespace dsm::detail
