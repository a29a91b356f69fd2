// Unsigned LEB128 values (spec §7's integers) read four at a time with one
// byte shuffle, for the long runs of a tile whose lengths vary from value to
// value in no order a branch predictor learns (internal).
#pragma once

#include <cstddef>
#include <cstdint>

namespace dsm::detail {

/// Whether this processor can run readVarintGroups() (x86-64 with SSSE3);
/// where not, callers read value by value.
bool varintGroupsSupported();

/// The bytes readVarintGroups() needs left before the end: a window of 64
/// whose value ends it finds at once, and 16 to spare for a group's load.
inline constexpr std::size_t kVarintGroupBytes = 80;

/// Reads values into `out` four at a time while at least 4 are still wanted
/// (of `count`), kVarintGroupBytes remain before `end`, and each of the next
/// four values takes 1 to 4 bytes; moves `at` past what it read. Returns how
/// many it read, a multiple of 4: the values and position value-by-value
/// reading gives. The value that stops it (longer, or beyond 32 bits) is the
/// caller's to read. Only where varintGroupsSupported().
std::size_t readVarintGroups(const std::uint8_t*& at, const std::uint8_t* end, std::uint32_t* out,
                             std::size_t count);

}  // namespace dsm::detail
