// CRC-32 of the file's sections and tiles (spec/dsm-format.md §2: zlib's
// CRC-32). Tiles are checked on every read, so on x86-64 processors with
// carry-less multiplication the bulk of the bytes is folded 64 at a time
// (Gopal et al., "Fast CRC Computation for Generic Polynomials Using PCLMULQDQ
// Instruction", Intel, 2009: the bit-reflected constants for this polynomial
// from its appendix); zlib takes what remains. Both give the same value.
#include <algorithm>

#include <zlib.h>

#include "format_layout.h"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define DSM_CRC32_FOLDING 1
#endif

namespace dsm::format {

namespace {

// zlib's crc32() over any size (its length argument is 32 bits).
std::uint32_t zlibCrc32(std::uint32_t crc, const std::uint8_t* data, std::size_t size) {
    while (size > 0) {
        const uInt chunk = static_cast<uInt>(std::min<std::size_t>(size, 1u << 30));
        crc = static_cast<std::uint32_t>(::crc32(crc, data, chunk));
        data += chunk;
        size -= chunk;
    }
    return crc;
}

#ifdef DSM_CRC32_FOLDING
#define DSM_CRC32_TARGET __attribute__((target("pclmul,sse2")))

DSM_CRC32_TARGET inline __m128i load(const std::uint8_t* p) {
    return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
}

// x.low * k.low + x.high * k.high onto `next`: a lane moved forwards by the
// distance the constants k encode.
DSM_CRC32_TARGET inline __m128i fold(__m128i x, __m128i k, __m128i next) {
    return _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x, k, 0x00), _mm_clmulepi64_si128(x, k, 0x11)), next);
}

// The CRC register (the running CRC-32 with its bits inverted, as the
// algorithm keeps it) after `size` bytes, `size` a multiple of 16 and at
// least 64: four lanes folded 64 bytes forwards at a time, folded into one,
// then reduced to 32 bits (Barrett).
DSM_CRC32_TARGET std::uint32_t foldCrc32(std::uint32_t state, const std::uint8_t* data, std::size_t size) {
    const __m128i by512 = _mm_set_epi64x(0x01c6e41596, 0x0154442bd4);  // k2, k1
    const __m128i by128 = _mm_set_epi64x(0x00ccaa009e, 0x01751997d0);  // k4, k3
    const __m128i by96 = _mm_set_epi64x(0, 0x0163cd6124);               // k5
    const __m128i polynomial = _mm_set_epi64x(0x01f7011641, 0x01db710641);  // mu, P'
    const __m128i low32 = _mm_set_epi32(0, -1, 0, -1);

    __m128i a = _mm_xor_si128(load(data), _mm_cvtsi32_si128(static_cast<int>(state)));
    __m128i b = load(data + 16), c = load(data + 32), d = load(data + 48);
    data += 64;
    size -= 64;
    for (; size >= 64; data += 64, size -= 64) {
        a = fold(a, by512, load(data));
        b = fold(b, by512, load(data + 16));
        c = fold(c, by512, load(data + 32));
        d = fold(d, by512, load(data + 48));
    }
    a = fold(a, by128, b);
    a = fold(a, by128, c);
    a = fold(a, by128, d);
    for (; size >= 16; data += 16, size -= 16) a = fold(a, by128, load(data));

    // 128 bits to 64, then to 32 by Barrett reduction.
    a = _mm_xor_si128(_mm_srli_si128(a, 8), _mm_clmulepi64_si128(a, by128, 0x10));
    a = _mm_xor_si128(_mm_srli_si128(a, 4), _mm_clmulepi64_si128(_mm_and_si128(a, low32), by96, 0x00));
    __m128i t = _mm_clmulepi64_si128(_mm_and_si128(a, low32), polynomial, 0x10);
    t = _mm_clmulepi64_si128(_mm_and_si128(t, low32), polynomial, 0x00);
    return static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_srli_si128(_mm_xor_si128(a, t), 4)));
}

bool cpuFolds() {
    static const bool folds = [] {
        __builtin_cpu_init();  // may run before libgcc's own initialisation
        return __builtin_cpu_supports("pclmul") != 0;
    }();
    return folds;
}
#endif

}  // namespace

std::uint32_t crc32(const std::uint8_t* data, std::size_t size) {
    std::uint32_t crc = 0;
#ifdef DSM_CRC32_FOLDING
    if (size >= 64 && cpuFolds()) {
        const std::size_t folded = size & ~std::size_t(15);
        crc = ~foldCrc32(~0u, data, folded);
        data += folded;
        size -= folded;
    }
#endif
    return zlibCrc32(crc, data, size);
}

}  // namespace dsm::format
