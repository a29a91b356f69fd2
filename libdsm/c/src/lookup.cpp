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
        dsm_lookup_options o = DSM_LOOKUP_OPTIONS_INIT;
        if (const dsm_result r = dsm::c::readVersioned(options, o, "dsm_lookup"); r != DSM_OK) return r;
        if (o.space < DSM_SPACE_WORLD || o.space > DSM_SPACE_RASTER)
            return fail(DSM_ERROR_ARGUMENT, "dsm_lookup", "space is not DSM_SPACE_WORLD, _LIGHT or _RASTER");
        if (o.filter < DSM_FILTER_BOX || o.filter > DSM_FILTER_GAUSSIAN)
            return fail(DSM_ERROR_ARGUMENT, "dsm_lookup", "filter is not DSM_FILTER_BOX, _TRIANGLE or _GAUSSIAN");
        if (o.level < DSM_LEVEL_AUTO)
            return fail(DSM_ERROR_ARGUMENT, "dsm_lookup", "level is neither DSM_LEVEL_AUTO nor >= 0");
        dsm::LookupOptions lookup;
        lookup.filter = static_cast<dsm::PixelFilter>(o.filter);
        lookup.filterWidth = o.filter_width;
        if (o.level != DSM_LEVEL_AUTO) lookup.level = static_cast<unsigned>(o.level);
        lookup.bias = o.bias;

        dsm::LookupContext& c = *context->context;
        dsm_result first = DSM_OK;
        dsm::LookupResult result;
        for (std::size_t i = 0; i < count; ++i) {
            const double* p = points + 3 * i;
            bool ok = false;
            switch (o.space) {
            case DSM_SPACE_WORLD:
                ok = c.tryWorld({p[0], p[1], p[2]}, lookup, result);
                break;
            case DSM_SPACE_LIGHT:
                ok = c.tryLight({p[0], p[1], p[2]}, lookup, result);
                break;
            default:
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
