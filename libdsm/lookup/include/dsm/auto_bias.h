// The automatic receiver bias against self-shadowing, from the map itself:
// how far in depth a receiver's own surface reaches into the pixels a lookup
// or a soft-shadow ray reads.
#pragma once

#include <optional>

#include "dsm/map_info.h"
#include "dsm/vec3.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// Largest depth slope the automatic bias assumes (a surface within about 6
/// degrees of edge-on to the light): beyond it the bias would hide the
/// receiver's neighbours, and such a surface is barely lit anyway.
constexpr double kAutomaticBiasMaxSlope = 10.0;

/// The bias (light-space depth units, >= 0) that LookupOptions and
/// SoftShadowOptions use when none is given, for a receiver at raster
/// (rx, ry) and light-space depth z:
///
///   bias = z 2^-14 + f(z) (1 + w / 2) t
///
///  - f(z): the size of a level-0 pixel at depth z (a perspective light:
///    z times the larger of (xmax - xmin) / width and (ymax - ymin) / height;
///    an orthographic one: those window sizes themselves). So the bias scales
///    with depth and with the map's resolution, from depths of 1e-3 to 1e4.
///  - 1 + w / 2, w the map's build filter width in pixels: a pixel's function
///    holds the samples within w / 2 pixels of its centre, and a bilinear
///    lookup (or a ray leaving the receiver) reads pixels up to one pixel
///    away, so the receiver's own surface reaches it from that far.
///  - t: the surface's depth slope, the tangent of the angle between its
///    normal and the light's ray through (rx, ry), in [1,
///    kAutomaticBiasMaxSlope]; 1 (a surface at 45 degrees) without a normal.
///    So a normal raises the bias of surfaces the light grazes and never
///    lowers it (rays leave a receiver at up to the area light's angle, and
///    filtered, curved or motion-blurred surfaces spread their depths).
///  - z 2^-14: depths are stored as 32-bit floats, and a receiver computed
///    from other geometry than the map's rounds differently.
///
/// `lightNormal`: the receiver surface's normal in light space, of any length
/// and either orientation (lightSpaceNormal() turns a world normal into it);
/// a zero or non-finite one counts as none. Never throws; a non-finite z
/// gives a non-finite bias (the lookup then reports the point).
DSM_API double automaticBias(const MapInfo& info, double rx, double ry, double z,
                             const std::optional<Vec3>& lightNormal = std::nullopt) noexcept;

/// A world-space surface normal in light space (the inverse transpose of the
/// camera's world-to-light matrix), not normalised.
DSM_API Vec3 lightSpaceNormal(const LightCamera& camera, const Vec3& worldNormal) noexcept;

DSM_NAMESPACE_END
