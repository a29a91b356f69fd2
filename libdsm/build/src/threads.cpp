#include "dsm/threads.h"

#include <algorithm>

#include <tbb/info.h>

DSM_NAMESPACE_BEGIN

unsigned availableCores() noexcept {
    return static_cast<unsigned>(std::max(1, tbb::info::default_concurrency()));
}

unsigned usableThreads(unsigned requested) noexcept {
    const unsigned cores = availableCores();
    return requested == 0 ? cores : std::min(requested, cores);
}

DSM_NAMESPACE_END
