// How many worker threads a parallel computation of libdsm runs on.
#pragma once

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// The cores this process may run on: the CPU affinity mask and cgroup quota
/// as TBB sees them (at least 1).
DSM_API unsigned availableCores() noexcept;

/// The worker threads used for a request of `requested`: 0 means all
/// available cores, and a larger request is clamped to them. Threads beyond
/// the cores only add overhead, and TBB's arenas fail at huge counts. Every
/// parallel part of libdsm (builds, depth maps) and the tools count threads
/// through this function; a caller that wants to say a request was clamped
/// compares the two.
DSM_API unsigned usableThreads(unsigned requested) noexcept;

DSM_NAMESPACE_END
