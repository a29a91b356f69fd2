// The shadow system through the C API: one system per renderer, a handle per
// map, a lookup state per thread, batched lookups.
#include <algorithm>

#include "c_api.h"

using dsm::c::fail;
using dsm::c::guarded;
using dsm::c::missing;

// A handle is the library's MapHandle; the C type only names it.
struct dsm_map_handle {};

namespace {

const dsm::MapHandle* toHandle(const dsm_map_handle* h) { return reinterpret_cast<const dsm::MapHandle*>(h); }

// Points per chunk of a batch: the thread's scratch arrays never grow beyond it.
constexpr std::size_t kChunk = 4096;

}  // namespace

extern "C" {

dsm_result dsm_shadow_system_create(const dsm_shadow_system_options* options, dsm_shadow_system** system) {
    return guarded([&] {
        if (!system) return missing("dsm_shadow_system_create", "system");
        dsm_shadow_system_options o = DSM_SHADOW_SYSTEM_OPTIONS_INIT;
        if (const dsm_result r = dsm::c::readVersioned(options, o, "dsm_shadow_system_create"); r != DSM_OK) return r;
        if (o.cache_bytes > SIZE_MAX)
            return fail(DSM_ERROR_ARGUMENT, "dsm_shadow_system_create", "cache_bytes exceeds the address space");
        dsm::ShadowSystemOptions so;
        so.cacheBytes = static_cast<std::size_t>(o.cache_bytes);
        so.maxOpenFiles = o.max_open_files;
        so.threadTiles = o.thread_tiles;
        auto handle = std::make_unique<dsm_shadow_system>();
        handle->system = dsm::ShadowSystem::create(so);
        *system = handle.release();
        return DSM_OK;
    });
}

void dsm_shadow_system_destroy(dsm_shadow_system* system) { delete system; }

dsm_result dsm_shadow_system_open(dsm_shadow_system* system, const char* path, dsm_map_handle** handle) {
    return guarded([&] {
        if (!system) return missing("dsm_shadow_system_open", "system");
        if (!path) return missing("dsm_shadow_system_open", "path");
        if (!handle) return missing("dsm_shadow_system_open", "handle");
        *handle = reinterpret_cast<dsm_map_handle*>(system->system->open(path));
        return DSM_OK;
    });
}

dsm_result dsm_shadow_system_get_map_info(const dsm_shadow_system* system, const dsm_map_handle* handle,
                                          dsm_map_info* info) {
    return guarded([&] {
        if (!system) return missing("dsm_shadow_system_get_map_info", "system");
        if (!handle) return missing("dsm_shadow_system_get_map_info", "handle");
        return dsm::c::mapInfo(*system->system->map(toHandle(handle)), info, "dsm_shadow_system_get_map_info");
    });
}

dsm_result dsm_shadow_system_get_stats(const dsm_shadow_system* system, dsm_shadow_system_stats* stats) {
    return guarded([&] {
        if (!system) return missing("dsm_shadow_system_get_stats", "system");
        if (!stats) return missing("dsm_shadow_system_get_stats", "stats");
        const dsm::ShadowSystemStats s = system->system->stats();
        dsm_shadow_system_stats full{};
        full.size = sizeof(full);
        full.bytes_in_use = s.cache.bytesInUse;
        full.peak_bytes_in_use = s.cache.peakBytesInUse;
        full.tiles_read = s.cache.tilesRead;
        full.hits = s.cache.hits;
        full.misses = s.cache.misses;
        full.evictions = s.cache.evictions;
        full.maps = s.maps;
        full.files_open = s.filesOpen;
        full.peak_files_open = s.peakFilesOpen;
        full.reopens = s.reopens;
        return dsm::c::writeVersioned(full, stats, "dsm_shadow_system_get_stats");
    });
}

dsm_result dsm_shadow_system_reset_stats(dsm_shadow_system* system) {
    return guarded([&] {
        if (!system) return missing("dsm_shadow_system_reset_stats", "system");
        system->system->resetStats();
        return DSM_OK;
    });
}

dsm_result dsm_shadow_thread_create(dsm_shadow_system* system, dsm_shadow_thread** thread) {
    return guarded([&] {
        if (!system) return missing("dsm_shadow_thread_create", "system");
        if (!thread) return missing("dsm_shadow_thread_create", "thread");
        auto handle = std::make_unique<dsm_shadow_thread>();
        handle->system = system->system;
        handle->thread = system->system->createThread();
        *thread = handle.release();
        return DSM_OK;
    });
}

void dsm_shadow_thread_destroy(dsm_shadow_thread* thread) { delete thread; }

dsm_result dsm_shadow_lookup(dsm_shadow_thread* thread, const dsm_map_handle* handle,
                             const dsm_lookup_options* options, size_t count, const double* points,
                             double* visibility, double* error_bounds) {
    return guarded([&] {
        if (!thread) return missing("dsm_shadow_lookup", "thread");
        if (!handle) return missing("dsm_shadow_lookup", "handle");
        if (count > 0 && !points) return missing("dsm_shadow_lookup", "points");
        if (count > 0 && !visibility) return missing("dsm_shadow_lookup", "visibility");
        dsm::LookupOptions lookup;
        dsm::LookupSpace space;
        if (const dsm_result r = dsm::c::lookupOptions(options, "dsm_shadow_lookup", lookup, space); r != DSM_OK)
            return r;
        dsm_result first = DSM_OK;
        for (std::size_t begin = 0; begin < count; begin += kChunk) {
            const std::size_t n = std::min(kChunk, count - begin);
            thread->points.resize(n);
            thread->results.resize(n);
            for (std::size_t i = 0; i < n; ++i) {
                const double* p = points + 3 * (begin + i);
                thread->points[i] = {p[0], p[1], p[2]};
            }
            const std::size_t failures = thread->system->lookup(*thread->thread, toHandle(handle), space,
                                                                thread->points, lookup, thread->results);
            if (failures > 0 && first == DSM_OK) {  // names the map when it is about it, as dsm_lookup
                const dsm::LookupFailure& why = thread->thread->lastFailure();
                first = fail(dsm::Error(why.code, why.message).withFile(thread->system->map(toHandle(handle))->path()));
            }
            for (std::size_t i = 0; i < n; ++i) {
                const dsm::LookupResult& r = thread->results[i];
                for (std::size_t k = 0; k < 3; ++k) visibility[3 * (begin + i) + k] = r.v[k];
                if (error_bounds) error_bounds[begin + i] = r.errorBound;
            }
        }
        return first;
    });
}

}  // extern "C"
