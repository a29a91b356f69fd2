// Four LEB128 values of 1 to 4 bytes at a time (after Plaisance, Kurz and
// Lemire's masked VByte decoding): the bytes that end a value (high bit
// clear) are found for 64 bytes at once, which gives each value's length;
// the four lengths pick a byte shuffle that moves each value's bytes into a
// 32-bit lane of its own, whose 7-bit groups are then joined lane by lane.
// No branch depends on a single value's length.
#include "varint_groups.h"

#include <array>
#include <bit>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define DSM_VARINT_GROUPS 1
#endif

namespace dsm::detail {

#ifdef DSM_VARINT_GROUPS
namespace {

#define DSM_VARINT_TARGET __attribute__((target("ssse3")))

// For each four lengths 1..4 (two bits each, the first lowest, less one):
// the shuffle that puts value k's bytes in the low bytes of lane k and
// zeroes the rest of the lane (a control byte with its high bit set).
using Shuffle = std::array<std::uint8_t, 16>;
constexpr std::array<Shuffle, 256> makeShuffles() {
    std::array<Shuffle, 256> shuffles{};
    for (unsigned index = 0; index < 256; ++index) {
        unsigned start = 0;
        for (unsigned k = 0; k < 4; ++k) {
            const unsigned length = ((index >> (2 * k)) & 3) + 1;
            for (unsigned j = 0; j < 4; ++j)
                shuffles[index][4 * k + j] = j < length ? static_cast<std::uint8_t>(start + j) : 0x80;
            start += length;
        }
    }
    return shuffles;
}
alignas(16) constexpr std::array<Shuffle, 256> kShuffles = makeShuffles();

DSM_VARINT_TARGET inline std::uint64_t valueEnds(const std::uint8_t* p) {
    std::uint64_t ends = 0;
    for (int k = 0; k < 4; ++k) {
        const __m128i bytes = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + 16 * k));
        ends |= static_cast<std::uint64_t>(static_cast<std::uint16_t>(~_mm_movemask_epi8(bytes))) << (16 * k);
    }
    return ends;
}

}  // namespace

DSM_VARINT_TARGET std::size_t readVarintGroups(const std::uint8_t*& at, const std::uint8_t* end, std::uint32_t* out,
                                               std::size_t count) {
    const __m128i low7 = _mm_set1_epi32(0x7F);
    const __m128i second = _mm_set1_epi32(0x3F80);
    const __m128i third = _mm_set1_epi32(0x1FC000);
    const __m128i fourth = _mm_set1_epi32(0xFE00000);
    const std::uint8_t* p = at;
    std::size_t n = 0;
    while (count - n >= 4 && static_cast<std::size_t>(end - p) >= kVarintGroupBytes) {
        std::uint64_t ends = valueEnds(p);
        unsigned start = 0;  // the next value's first byte in the window
        for (;;) {
            const unsigned e0 = static_cast<unsigned>(std::countr_zero(ends));
            ends &= ends - 1;
            const unsigned e1 = static_cast<unsigned>(std::countr_zero(ends));
            ends &= ends - 1;
            const unsigned e2 = static_cast<unsigned>(std::countr_zero(ends));
            ends &= ends - 1;
            const unsigned e3 = static_cast<unsigned>(std::countr_zero(ends));  // 64: not in the window
            ends &= ends - 1;
            // Lengths less one; e3 beyond the window makes the last one large.
            const unsigned l0 = e0 - start, l1 = e1 - e0 - 1, l2 = e2 - e1 - 1, l3 = e3 - e2 - 1;
            if ((l0 | l1 | l2 | l3) > 3 || e3 >= 64) break;
            const __m128i bytes = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + start));
            const __m128i lanes = _mm_shuffle_epi8(
                bytes, _mm_load_si128(reinterpret_cast<const __m128i*>(kShuffles[l0 | l1 << 2 | l2 << 4 | l3 << 6].data())));
            const __m128i values = _mm_or_si128(
                _mm_or_si128(_mm_and_si128(lanes, low7), _mm_and_si128(_mm_srli_epi32(lanes, 1), second)),
                _mm_or_si128(_mm_and_si128(_mm_srli_epi32(lanes, 2), third),
                             _mm_and_si128(_mm_srli_epi32(lanes, 3), fourth)));
            _mm_storeu_si128(reinterpret_cast<__m128i*>(out + n), values);
            n += 4;
            start = e3 + 1;
            if (count - n < 4) break;
        }
        if (start == 0) break;  // a value longer than 4 bytes comes first
        p += start;
    }
    at = p;
    return n;
}

bool varintGroupsSupported() {
    static const bool supported = [] {
        __builtin_cpu_init();  // may run before libgcc's own initialisation
        return __builtin_cpu_supports("ssse3") != 0;
    }();
    return supported;
}

#else

bool varintGroupsSupported() { return false; }

std::size_t readVarintGroups(const std::uint8_t*&, const std::uint8_t*, std::uint32_t*, std::size_t) {
    return 0;  // never called: varintGroupsSupported() is false
}

#endif

}  // namespace dsm::detail
