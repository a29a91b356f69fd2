// e^x inline, for the Gaussian pixel filter (internal). A build weighs each
// sample for every pixel whose filter reaches it (about four times a sample
// at the default width): through libm's exp() that was 4.7 % of a build's
// instructions, a third of it in the wrapper that checks for overflow.
#pragma once

#include <array>
#include <bit>
#include <cmath>
#include <cstdint>

namespace dsm::detail {

namespace exponential_table {

inline constexpr int kBits = 6;
inline constexpr int kSize = 1 << kBits;

// e^a for |a| < 1 by its Taylor series in long double (where long double has
// a 64-bit significand, far more than the rounding to double needs).
constexpr long double taylorExp(long double a) {
    long double sum = 1.0L, term = 1.0L;
    for (int n = 1; n < 30; ++n) {
        term *= a / n;
        sum += term;
    }
    return sum;
}

// 2^(j / 64) for j in [0, 64), made by the compiler.
inline constexpr std::array<double, kSize> kPowersOfTwo = [] {
    constexpr long double kLn2 = 0.693147180559945309417232121458176568L;
    std::array<double, kSize> table{};
    for (int j = 0; j < kSize; ++j) table[j] = static_cast<double>(taylorExp(kLn2 * j / kSize));
    return table;
}();

}  // namespace exponential_table

/// e^x within two units in the last place (against the exact value) for any
/// x. Arguments outside (-708, 709), where the result nears the smallest
/// normal double or overflows, and NaN, take std::exp.
inline double exponential(double x) {
    if (!(x > -708.0 && x < 709.0)) return std::exp(x);
    using exponential_table::kBits;
    // x = (64 e + j) ln 2 / 64 + r with |r| <= ln 2 / 128, so e^x = 2^e 2^(j/64) e^r. The
    // multiple k = 64 e + j is x 64 / ln 2 rounded to nearest by adding and subtracting
    // 1.5 * 2^52 (in the default rounding mode; -ffast-math would fold the two away).
    // ln 2 / 64 is split so that k times its upper part, of 36 bits, is exact for |k| < 2^17.
    constexpr double k64OverLn2 = 92.33248261689366;
    constexpr double kLn2Over64High = 0x1.62e42fefa0000p-7;
    constexpr double kLn2Over64Low = 0x1.cf79abc9e3b3ap-46;
    constexpr double kRoundingShift = 6755399441055744.0;  // 1.5 * 2^52
    const double kf = (x * k64OverLn2 + kRoundingShift) - kRoundingShift;
    const double r = (x - kf * kLn2Over64High) - kf * kLn2Over64Low;
    const auto k = static_cast<std::int64_t>(kf);
    const double t = exponential_table::kPowersOfTwo[static_cast<std::size_t>(k & (exponential_table::kSize - 1))];
    // e^r - 1 to r^5: the first term left out, r^6 / 720, is below 2^-54.
    const double p = r + r * r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0))));
    // 2^e from its bits: x in (-708, 709) puts e = floor(k / 64) in [-1022, 1022].
    const double scale = std::bit_cast<double>(std::uint64_t((k >> kBits) + 1023) << 52);
    return (t + t * p) * scale;
}

}  // namespace dsm::detail
