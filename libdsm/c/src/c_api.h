// The inside of the C API (internal): the handles and the one place where C++
// exceptions become dsm_result codes.
#pragma once

#include <array>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "dsm/dsm_c.h"
#include "dsm/error.h"
#include "dsm/lookup.h"
#include "dsm/reader.h"
#include "dsm/shadow_system.h"
#include "dsm/soft_shadow.h"
#include "dsm/tile_cache.h"

struct dsm_cache {
    std::shared_ptr<dsm::TileCache> cache;
};

struct dsm_map {
    std::shared_ptr<const dsm::DeepShadowMap> map;
};

struct dsm_pixel {
    dsm::PixelFunction function;
};

struct dsm_lookup_context {
    std::unique_ptr<dsm::LookupContext> context;
    std::string mapPath;  ///< what the map's failures name (dsm_last_error_file)
};

struct dsm_shadow_system {
    std::shared_ptr<dsm::ShadowSystem> system;
};

struct dsm_shadow_thread {
    std::shared_ptr<dsm::ShadowSystem> system;  // kept alive while the thread state is
    std::unique_ptr<dsm::ShadowThread> thread;
    std::vector<std::array<double, 3>> points;  // one chunk of a batch, reused
    std::vector<dsm::LookupResult> results;
};

struct dsm_soft_light {
    std::shared_ptr<const dsm::SoftShadowTracer> tracer;
};

struct dsm_soft_context {
    std::unique_ptr<dsm::SoftShadowContext> context;
};

namespace dsm::c {

/// The dsm_result of an ErrorCode.
dsm_result resultOf(ErrorCode code) noexcept;

/// Records a failure about `file` (dsm_last_error_file; NULL: none) for the
/// calling thread and the error callback; returns `result`.
dsm_result failNaming(dsm_result result, const char* message, const char* file) noexcept;
/// failNaming() naming no file.
dsm_result fail(dsm_result result, const char* message) noexcept;
/// failNaming() with the code, message and file of a dsm::Error.
dsm_result fail(const Error& error) noexcept;
inline dsm_result fail(ErrorCode code, const char* message) noexcept { return fail(resultOf(code), message); }

/// Runs `body` (which returns dsm_result); any exception becomes a result and
/// a message, so none crosses the C boundary.
template <class Body>
dsm_result guarded(Body&& body) noexcept {
    try {
        return body();
    } catch (const Error& e) {
        return fail(e);
    } catch (const std::bad_alloc&) {
        return fail(DSM_ERROR_LIMIT, "out of memory");
    } catch (const std::exception& e) {
        return fail(DSM_ERROR_INTERNAL, e.what());
    } catch (...) {
        return fail(DSM_ERROR_INTERNAL, "unknown failure");
    }
}

/// fail() with the message "<function>: <what>".
dsm_result fail(dsm_result result, const char* function, const char* what) noexcept;
inline dsm_result fail(ErrorCode code, const char* function, const char* what) noexcept {
    return fail(resultOf(code), function, what);
}

/// A failure of a NULL required argument, naming the function and the argument.
dsm_result missing(const char* function, const char* argument) noexcept;

/// Fills dsm_map_info (a versioned struct) from a map.
dsm_result mapInfo(const DeepShadowMap& map, dsm_map_info* info, const char* function) noexcept;

/// Reads dsm_lookup_options (NULL: the defaults) into the C++ options and
/// space; reports a bad field as `function`'s failure.
dsm_result lookupOptions(const dsm_lookup_options* options, const char* function, LookupOptions& lookup,
                         LookupSpace& space) noexcept;

/// Copies a caller's struct that starts with its own size into `out` (which
/// holds this library's defaults): the fields the caller knows replace the
/// defaults. A struct smaller than its size field, or larger than this library
/// knows with non-zero bytes beyond, is refused.
template <class Struct>
dsm_result readVersioned(const Struct* in, Struct& out, const char* function) noexcept {
    if (!in) return DSM_OK;
    const std::size_t given = in->size;
    if (given < sizeof(std::size_t)) return fail(DSM_ERROR_ARGUMENT, function, "the struct's size field is not set");
    const auto* bytes = reinterpret_cast<const unsigned char*>(in);
    for (std::size_t i = sizeof(Struct); i < given; ++i)
        if (bytes[i] != 0)
            return fail(DSM_ERROR_UNSUPPORTED, function, "the struct has fields this version of libdsm does not know");
    std::memcpy(static_cast<void*>(&out), in, given < sizeof(Struct) ? given : sizeof(Struct));
    out.size = sizeof(Struct);
    return DSM_OK;
}

/// Copies `full` into the caller's struct up to its size field (at least the size field itself).
template <class Struct>
dsm_result writeVersioned(const Struct& full, Struct* out, const char* function) noexcept {
    const std::size_t wanted = out->size;
    if (wanted < sizeof(std::size_t)) return fail(DSM_ERROR_ARGUMENT, function, "the struct's size field is not set");
    std::memcpy(static_cast<void*>(out), &full, wanted < sizeof(Struct) ? wanted : sizeof(Struct));
    out->size = wanted;
    return DSM_OK;
}

}  // namespace dsm::c
