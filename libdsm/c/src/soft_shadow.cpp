// Soft shadows of area lights through the C API.
#include <array>

#include "dsm/area_light.h"
#include "c_api.h"

using dsm::c::fail;
using dsm::c::guarded;
using dsm::c::missing;

extern "C" {

dsm_result dsm_soft_light_create(const dsm_map* map, const dsm_area_light* light, dsm_soft_light** soft) {
    return guarded([&] {
        if (!map) return missing("dsm_soft_light_create", "map");
        if (!light) return missing("dsm_soft_light_create", "light");
        if (!soft) return missing("dsm_soft_light_create", "soft");
        dsm_area_light l = DSM_AREA_LIGHT_INIT;
        if (const dsm_result r = dsm::c::readVersioned(light, l, "dsm_soft_light_create"); r != DSM_OK) return r;
        if (l.shape != DSM_AREA_LIGHT_DISK && l.shape != DSM_AREA_LIGHT_RECTANGLE)
            return fail(DSM_ERROR_ARGUMENT, "dsm_soft_light_create",
                        "shape is not DSM_AREA_LIGHT_DISK or DSM_AREA_LIGHT_RECTANGLE");
        const dsm::MapInfo& info = map->map->info();
        const bool disk = l.shape == DSM_AREA_LIGHT_DISK;
        const dsm::AreaLight area =
            l.plane_depth < 0.0
                ? dsm::AreaLight::forMap(info, disk ? dsm::AreaLightShape::Disk : dsm::AreaLightShape::Rectangle,
                                         l.half_width, disk ? l.half_width : l.half_height)
            : disk ? dsm::AreaLight::disk(info.camera, l.half_width, l.plane_depth)
                   : dsm::AreaLight::rectangle(info.camera, l.half_width, l.half_height, l.plane_depth);
        auto handle = std::make_unique<dsm_soft_light>();
        handle->tracer = std::make_shared<dsm::SoftShadowTracer>(map->map, area);
        *soft = handle.release();
        return DSM_OK;
    });
}

void dsm_soft_light_destroy(dsm_soft_light* soft) { delete soft; }

dsm_result dsm_soft_context_create(const dsm_soft_light* soft, dsm_soft_context** context) {
    return guarded([&] {
        if (!soft) return missing("dsm_soft_context_create", "soft");
        if (!context) return missing("dsm_soft_context_create", "context");
        auto handle = std::make_unique<dsm_soft_context>();
        handle->context = std::make_unique<dsm::SoftShadowContext>(soft->tracer);
        *context = handle.release();
        return DSM_OK;
    });
}

void dsm_soft_context_destroy(dsm_soft_context* context) { delete context; }

dsm_result dsm_soft_shadow(dsm_soft_context* context, const dsm_soft_shadow_options* options, size_t count,
                           const double* points, double* visibility, int32_t* rays) {
    return guarded([&] {
        if (!context) return missing("dsm_soft_shadow", "context");
        if (count > 0 && !points) return missing("dsm_soft_shadow", "points");
        if (count > 0 && !visibility) return missing("dsm_soft_shadow", "visibility");
        dsm_soft_shadow_options o = DSM_SOFT_SHADOW_OPTIONS_INIT;
        if (const dsm_result r = dsm::c::readVersioned(options, o, "dsm_soft_shadow"); r != DSM_OK) return r;
        if (o.method != DSM_SOFT_MTSM && o.method != DSM_SOFT_PCF)
            return fail(DSM_ERROR_ARGUMENT, "dsm_soft_shadow", "method is not DSM_SOFT_MTSM or DSM_SOFT_PCF");
        if (o.attenuation != DSM_ATTENUATION_SUBTRACTIVE && o.attenuation != DSM_ATTENUATION_MULTIPLICATIVE)
            return fail(DSM_ERROR_ARGUMENT, "dsm_soft_shadow",
                        "attenuation is not DSM_ATTENUATION_SUBTRACTIVE or DSM_ATTENUATION_MULTIPLICATIVE");
        dsm::SoftShadowOptions soft;
        soft.samples = o.samples;
        if (o.layers != 0) soft.layers = o.layers;  // 0: all of the map's layers
        soft.zThreshold = o.z_threshold;
        if (o.bias != DSM_BIAS_AUTO) soft.bias = o.bias;
        soft.visibilityThreshold = o.visibility_threshold;
        soft.seed = o.seed;
        soft.hierarchy = o.hierarchy != 0;
        soft.classification = o.classification != 0;
        soft.attenuation = o.attenuation == DSM_ATTENUATION_SUBTRACTIVE ? dsm::SampleAttenuation::Subtractive
                                                                        : dsm::SampleAttenuation::Multiplicative;

        dsm::SoftShadowContext& c = *context->context;
        dsm_result first = DSM_OK;
        for (std::size_t i = 0; i < count; ++i) {
            const dsm::Vec3 p{points[3 * i], points[3 * i + 1], points[3 * i + 2]};
            dsm::SoftShadowResult result;
            try {
                result = o.method == DSM_SOFT_PCF ? c.pcfVisibility(p, soft) : c.visibility(p, soft);
            } catch (const dsm::Error& e) {
                result = dsm::SoftShadowResult{};  // the failure value: lit, no rays
                if (first == DSM_OK) first = fail(e);
            }
            for (std::size_t k = 0; k < 3; ++k) visibility[3 * i + k] = result.v[k];
            if (rays) rays[i] = result.rays;
        }
        return first;
    });
}

}  // extern "C"
