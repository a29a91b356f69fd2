// Batched shadow lookups through the C API, on the non-throwing lookup path.
#include <array>

#include "c_api.h"

using dsm::c::fail;
using dsm::c::guarded;
using dsm::c::missing;

extern "C" {

dsm_result dsm_lookup_context_create(const dsm_map* map, dsm_lookup_context** context) {
    return guarded([&] {
        if (!map) return missing("dsm_lookup_context_create", "map");
        if (!context) return missing("dsm_lookup_context_create", "context");
        auto handle = std::make_unique<dsm_lookup_context>();
        handle->context = std::make_unique<dsm::LookupContext>(map->map);
        handle->mapPath = map->map->path();
        *context = handle.release();
        return DSM_OK;
    });
}

void dsm_lookup_context_destroy(dsm_lookup_context* context) { delete context; }

dsm_result dsm_lookup(dsm_lookup_context* context, const dsm_lookup_options* options, size_t count,
                      const double* points, double* visibility, double* error_bounds) {
    return guarded([&] {
        if (!context) return missing("dsm_lookup", "context");
        if (count > 0 && !points) return missing("dsm_lookup", "points");
        if (count > 0 && !visibility) return missing("dsm_lookup", "visibility");
        dsm::LookupOptions lookup;
        dsm::LookupSpace space;
        if (const dsm_result r = dsm::c::lookupOptions(options, "dsm_lookup", lookup, space); r != DSM_OK) return r;

        dsm::LookupContext& c = *context->context;
        dsm_result first = DSM_OK;
        dsm::LookupResult result;
        for (std::size_t i = 0; i < count; ++i) {
            const double* p = points + 3 * i;
            bool ok = false;
            switch (space) {
            case dsm::LookupSpace::world:
                ok = c.tryWorld({p[0], p[1], p[2]}, lookup, result);
                break;
            case dsm::LookupSpace::light:
                ok = c.tryLight({p[0], p[1], p[2]}, lookup, result);
                break;
            case dsm::LookupSpace::raster:
                ok = c.tryRaster(p[0], p[1], p[2], lookup, result);
                break;
            }
            if (!ok && first == DSM_OK)  // the failure names the map when it is about it (a tile that cannot be read)
                first = fail(dsm::Error(c.lastFailure().code, c.lastFailure().message).withFile(context->mapPath));
            for (std::size_t k = 0; k < 3; ++k) visibility[3 * i + k] = result.v[k];
            if (error_bounds) error_bounds[i] = result.errorBound;
        }
        return first;
    });
}

}  // extern "C"

namespace dsm::c {

dsm_result lookupOptions(const dsm_lookup_options* options, const char* function, LookupOptions& lookup,
                         LookupSpace& space) noexcept {
    dsm_lookup_options o = DSM_LOOKUP_OPTIONS_INIT;
    if (const dsm_result r = readVersioned(options, o, function); r != DSM_OK) return r;
    if (o.space < DSM_SPACE_WORLD || o.space > DSM_SPACE_RASTER)
        return fail(DSM_ERROR_ARGUMENT, function, "space is not DSM_SPACE_WORLD, _LIGHT or _RASTER");
    if (o.filter < DSM_FILTER_BOX || o.filter > DSM_FILTER_GAUSSIAN)
        return fail(DSM_ERROR_ARGUMENT, function, "filter is not DSM_FILTER_BOX, _TRIANGLE or _GAUSSIAN");
    if (o.level < DSM_LEVEL_AUTO)
        return fail(DSM_ERROR_ARGUMENT, function, "level is neither DSM_LEVEL_AUTO nor >= 0");
    lookup.filter = static_cast<PixelFilter>(o.filter);
    lookup.filterWidth = o.filter_width;
    if (o.level != DSM_LEVEL_AUTO) lookup.level = static_cast<unsigned>(o.level);
    if (o.bias != DSM_BIAS_AUTO) lookup.bias = o.bias;
    space = o.space == DSM_SPACE_WORLD ? LookupSpace::world
            : o.space == DSM_SPACE_LIGHT ? LookupSpace::light
                                         : LookupSpace::raster;
    return DSM_OK;
}

}  // namespace dsm::c
