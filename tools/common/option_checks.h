// Checks of numeric option values shared by the dsm-* tools. CLI11's own
// Range, PositiveNumber and NonNegativeNumber let NaN through (every
// comparison with NaN is false) and its unsigned conversions clamp values
// above the type's range; these refuse both, so no value is ever silently
// replaced by a default or a different number. Tools only.
#pragma once

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <limits>
#include <string>
#include <string_view>
#include <system_error>

#include <CLI/CLI.hpp>

#include "dsm/threads.h"

namespace dsm::tools {

/// Whether the lower end of a range belongs to it.
enum class LowerBound { Inclusive, Exclusive };

/// %g text of a bound for messages ("1e-06", "65536").
inline std::string boundText(double value) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%g", value);
    return buffer;
}

/// A finite decimal number filling all of `text`, or false.
inline bool parseFiniteNumber(std::string_view text, double& value) {
    if (!text.empty() && text.front() == '+') text.remove_prefix(1);
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    return error == std::errc() && end == text.data() + text.size() && !text.empty() && std::isfinite(value);
}

/// A non-negative decimal integer filling all of `text` that fits 64 bits, or false.
inline bool parseUnsigned(std::string_view text, std::uint64_t& value) {
    if (!text.empty() && text.front() == '+') text.remove_prefix(1);
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    return error == std::errc() && end == text.data() + text.size() && !text.empty();
}

/// CLI11 check: a finite number in [min, max] (or (min, max] with
/// LowerBound::Exclusive). NaN, infinities and out-of-range values are usage
/// errors.
inline CLI::Validator finiteNumberIn(double min, double max, LowerBound lower = LowerBound::Inclusive) {
    const std::string range = (lower == LowerBound::Inclusive ? "[" : "(") + boundText(min) + ", " +
                              boundText(max) + "]";
    return CLI::Validator(
        [=](std::string& text) {
            double value = 0.0;
            if (!parseFiniteNumber(text, value) || !(lower == LowerBound::Inclusive ? value >= min : value > min) ||
                !(value <= max))
                return "expects a finite number in " + range + ", got '" + text.substr(0, 32) + "'";
            return std::string();
        },
        "NUMBER in " + range, "finite number in " + range);
}

/// CLI11 check: an integer in [min, max], written in decimal digits (no sign,
/// so "-1" never wraps around to a huge unsigned value, and nothing beyond
/// 2^64 - 1 is clamped).
inline CLI::Validator integerIn(std::uint64_t min, std::uint64_t max) {
    const std::string range = "[" + std::to_string(min) + ", " + std::to_string(max) + "]";
    return CLI::Validator(
        [=](std::string& text) {
            std::uint64_t value = 0;
            if (!parseUnsigned(text, value) || value < min || value > max)
                return "expects an integer in " + range + ", got '" + text.substr(0, 32) + "'";
            return std::string();
        },
        "INTEGER in " + range, "integer in " + range);
}

/// CLI11 check: "auto", or a value `check` accepts.
inline CLI::Validator autoOr(const CLI::Validator& check) {
    return CLI::Validator(
        [check](std::string& text) { return text == "auto" ? std::string() : check(text); },
        "auto or " + check.get_description(), "auto or " + check.get_name());
}

/// The worker threads for a --threads request (0 = all cores): at most the
/// cores this process may use (dsm::usableThreads, which the library applies
/// too). A request above them is clamped, and one line on standard error says
/// so unless `quiet`.
inline unsigned usableThreadsNoted(std::string_view tool, unsigned requested, bool quiet) {
    const unsigned used = dsm::usableThreads(requested);
    if (requested > used && !quiet)
        std::cerr << tool << ": --threads " << requested << " is more than the " << used
                  << (used == 1 ? " core" : " cores") << " this process may use; using " << used << '\n';
    return used;
}

}  // namespace dsm::tools
