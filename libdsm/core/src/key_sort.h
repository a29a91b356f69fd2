// Sorting a pixel's sweep events with vector instructions (internal). The
// sweep sorts about a hundred 64-bit keys a pixel (sweep.cpp, sortEvents);
// with AVX-512 a bitonic network sorts them in registers, eight keys a
// comparison, without the radix sort's passes through memory or the
// insertion that finishes it.
#pragma once

#include <cstddef>
#include <cstdint>

#include "tested_internal.h"

namespace dsm::detail {

/// The most keys a vector sort takes at once: beyond about 512 a bitonic
/// network's log^2 n steps cost more than the radix sort's passes.
inline constexpr std::size_t kVectorSortLimit = 512;

/// Sorts keys[0, n) in ascending order, for 0 < n <= kVectorSortLimit.
using VectorKeySort = void (*)(std::uint64_t* keys, std::size_t n);

/// The AVX-512 sort where this build has it and the processor runs it;
/// null otherwise.
DSM_TESTED_INTERNAL VectorKeySort avx512KeySort();

}  // namespace dsm::detail
