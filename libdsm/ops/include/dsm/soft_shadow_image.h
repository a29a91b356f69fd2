// A picture of the soft shadow a map casts on a plane of constant light
// depth: for previewing what an area light makes of an MTSM map.
#pragma once

#include <memory>

#include "dsm/map_images.h"
#include "dsm/soft_shadow.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

struct SoftShadowImageOptions {
    /// Light-space depth of the receiver plane (beyond the light's plane).
    double receiverDepth = 1.0;
    /// Rays, layers, bias, ... of each receiver's query.
    SoftShadowOptions shadow;
};

/// Visibility of the tracer's area light (SoftShadowContext::visibility) from
/// the receiver plane, one receiver per pixel of `rect` of a level: the point
/// at depth receiverDepth whose light-centre projection is the pixel's centre
/// (scaled to level-0 raster coordinates). One value per channel of the map.
/// Throws dsm::Error (argument) when `rect` is not a part of the level or the
/// options are out of range, and passes on the reader's errors.
DSM_API FloatImage softShadowImage(const std::shared_ptr<const SoftShadowTracer>& tracer, unsigned level,
                                   const PixelRect& rect, const SoftShadowImageOptions& options);

DSM_NAMESPACE_END
