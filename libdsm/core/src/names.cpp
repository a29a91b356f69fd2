#include "dsm/names.h"

DSM_NAMESPACE_BEGIN

const char* projectionName(Projection projection) {
    switch (projection) {
        case Projection::Perspective: return "perspective";
        case Projection::Orthographic: return "orthographic";
    }
    return "unknown";
}

const char* filterName(PixelFilter filter) {
    switch (filter) {
        case PixelFilter::Box: return "box";
        case PixelFilter::Triangle: return "triangle";
        case PixelFilter::Gaussian: return "gaussian";
    }
    return "unknown";
}

std::optional<PixelFilter> pixelFilterFromName(std::string_view name) {
    for (const PixelFilter f : {PixelFilter::Box, PixelFilter::Triangle, PixelFilter::Gaussian})
        if (name == filterName(f)) return f;
    return std::nullopt;
}

DSM_NAMESPACE_END
