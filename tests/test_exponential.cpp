// The inline e^x of the Gaussian pixel filter (libdsm/core/src/exponential.h):
// within two units in the last place of the exact value over the filter's
// arguments and the whole range it computes itself, exactly 1 at 0, and
// std::exp's own result outside that range.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "exponential.h"

namespace {

using dsm::detail::exponential;

// |exponential(x) - e^x| in units in the last place of the double nearest
// e^x, against e^x in long double (far closer than a double where long double
// has more digits; elsewhere it is libm's double, within about half a unit).
double ulpsFromExact(double x) {
    const long double exact = std::exp(static_cast<long double>(x));
    const double nearest = static_cast<double>(exact);
    const double ulp = std::nextafter(nearest, std::numeric_limits<double>::infinity()) - nearest;
    return static_cast<double>(std::fabs(static_cast<long double>(exponential(x)) - exact) / ulp);
}

// The largest error over a million arguments drawn uniformly from [lo, hi).
double worstOverUniform(unsigned seed, double lo, double hi) {
    std::mt19937_64 random(seed);
    std::uniform_real_distribution<double> argument(lo, hi);
    double worst = 0.0;
    for (int i = 0; i < 1000000; ++i) worst = std::max(worst, ulpsFromExact(argument(random)));
    return worst;
}

constexpr double kBound = std::numeric_limits<long double>::digits > 53 ? 2.0 : 3.0;

TEST(Exponential, WithinTwoUnitsOverTheFiltersArguments) {
    // A Gaussian cut at half-width r on each axis takes e^-x for x in [0, 4].
    EXPECT_LE(worstOverUniform(7, -4.0, 0.0), kBound);
}

TEST(Exponential, WithinTwoUnitsOverItsWholeRange) {
    double worst = worstOverUniform(11, -708.0, 709.0);
    // Near the ends of the range, and at the table's steps of ln 2 / 64.
    for (const double x : {-707.999, -707.5, -1.0e-300, 1.0e-300, 0.5, 708.5, 708.999})
        worst = std::max(worst, ulpsFromExact(x));
    for (int k = -640; k <= 640; ++k) {
        const double x = k * (0.693147180559945309 / 64.0);
        worst = std::max({worst, ulpsFromExact(x), ulpsFromExact(std::nextafter(x, 1.0))});
    }
    EXPECT_LE(worst, kBound);
}

TEST(Exponential, OneAtZero) {
    EXPECT_EQ(exponential(0.0), 1.0);
    EXPECT_EQ(exponential(-0.0), 1.0);
}

TEST(Exponential, OutsideItsRangeIsStdExp) {
    const double inf = std::numeric_limits<double>::infinity();
    for (const double x : {-708.0, -710.0, -745.2, -800.0, -inf, 709.0, 709.7, 710.0, inf})
        EXPECT_EQ(exponential(x), std::exp(x)) << x;
    EXPECT_TRUE(std::isnan(exponential(std::numeric_limits<double>::quiet_NaN())));
}

}  // namespace
