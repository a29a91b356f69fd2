// Small helpers for building dsm::Error messages (internal).
#pragma once

#include <sstream>
#include <string>
#include <utility>

namespace dsm::detail {

/// Concatenates its arguments with an ostream; floating-point values get 9
/// significant digits so the reported value round-trips a float exactly.
template <typename... Args>
std::string concat(Args&&... args) {
    std::ostringstream out;
    out.precision(9);
    (out << ... << std::forward<Args>(args));
    return out.str();
}

}  // namespace dsm::detail
