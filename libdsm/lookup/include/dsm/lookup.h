// Filtered shadow lookups in a deep shadow map (Lokovic & Veach 2000, §3.4,
// §5.3): V(x, y, z) = sum_ij w_ij V_ij(z) / sum_ij w_ij.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "dsm/error.h"
#include "dsm/map_info.h"
#include "dsm/reader.h"
#include "dsm/vec3.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

struct LookupOptions {
    /// Filter shape. All are separable over pixel centres; a pixel's weight is
    /// kx(d_x) * ky(d_y), d = pixel centre - lookup point, in pixels of the
    /// level used:
    ///  - Box: the overlap of the pixel [i, i+1] with [x - w/2, x + w/2]; width 1
    ///    is bilinear interpolation between the four nearest pixel centres.
    ///  - Triangle: max(0, 1 - |d| / (w/2)); width 2 is bilinear.
    ///  - Gaussian: exp(-d^2 / (2 s^2)) with s = w/4, cut at |d| = w/2.
    PixelFilter filter = PixelFilter::Box;
    /// Filter width in level-0 pixels. The smallest useful width (1 for the box,
    /// 2 for the others) is used when a smaller one is asked for.
    double filterWidth = 1.0;
    /// Mip level. Unset (automatic) chooses from the filter width so that the
    /// footprint spans 1-2 of the smallest width at the chosen level, and blends
    /// the two nearest levels linearly (trilinear mip-mapping). A level uses that
    /// level only (clamped to the coarsest), with the width scaled to it.
    std::optional<unsigned> level;
    /// Subtracted from the query depth, against self-shadowing (light units;
    /// may be negative). Unset (the default): automaticBias() (dsm/auto_bias.h)
    /// at the lookup's point with `normal`, which scales with the depth and
    /// the map's resolution.
    std::optional<double> bias;
    /// The receiver surface's normal, for the automatic bias only: in world
    /// space for world lookups, in light space for light and raster lookups;
    /// any length, either orientation. Unset: the bias assumes a slope of 1.
    std::optional<Vec3> normal;
};

struct LookupResult {
    /// Visibility per channel in [0, 1]; for a monochrome map only v[0] is
    /// meaningful and v[1] = v[2] = v[0].
    std::array<double, 3> v{1.0, 1.0, 1.0};
    int channels = 1;
    /// Bound on |v - exact| from compression: the largest recorded error bound
    /// of the levels used (not counting the filter's own approximation).
    double errorBound = 0.0;
    /// Pixels with non-zero weight that were evaluated.
    int pixelsUsed = 0;
};

/// Why a non-throwing lookup (LookupContext::tryRaster and the others) failed.
struct LookupFailure {
    ErrorCode code = ErrorCode::internal;
    /// One line, as dsm::Error's message.
    std::string message;
};

/// Where a lookup's point is given: raster (level-0 pixels of the map and the
/// light depth z, see LightCamera), light space, or world space through the
/// map's light camera.
enum class LookupSpace { raster, light, world };

/// Tiles a per-thread lookup state keeps at hand (LookupContext, and
/// ShadowSystemOptions::threadTiles by default): each slot holds a reference
/// that keeps its tile in memory, outside the cache's budget, until the slot
/// is reused.
constexpr unsigned kDefaultThreadTiles = 64;

/// Lookups in one map for one thread. Prefer ShadowSystem when a renderer
/// looks up several maps: its per-thread state serves all of them and it
/// bounds open files. Keeps the last kDefaultThreadTiles tiles it touched
/// (so that lookups rarely reach the shared cache) and finds the segment of
/// each pixel's function by a branch-free binary search. Not thread-safe
/// itself: give each thread its own. The map must stay open while the
/// context is used.
///
/// Points outside the map, behind a perspective light, or carried beyond
/// double range by the map's camera (a finite point, an extreme camera) are
/// lit: V = 1. A non-finite point is an argument error.
/// Pixels of the footprint that fall outside the image are left out and the
/// weights of the others renormalised.
class DSM_API LookupContext {
public:
    explicit LookupContext(std::shared_ptr<const DeepShadowMap> map);
    ~LookupContext();
    LookupContext(const LookupContext&) = delete;
    LookupContext& operator=(const LookupContext&) = delete;

    /// Raster position (level-0 pixels, see LightCamera) and light depth z.
    LookupResult raster(double rx, double ry, double z, const LookupOptions& options = {});
    /// Point in light space.
    LookupResult light(const std::array<double, 3>& p, const LookupOptions& options = {});
    /// Point in world space, through the map's light camera.
    LookupResult world(const std::array<double, 3>& p, const LookupOptions& options = {});

    /// The three lookups above for shading loops: they never throw. On success
    /// they fill `result` and return true. On failure (a point or option out of
    /// range, a tile that cannot be read or is corrupt, memory) they return
    /// false and set `result` to the documented failure value, lit with no
    /// confidence: v = {1, 1, 1}, errorBound = 1, pixelsUsed = 0; lastFailure()
    /// then says why.
    bool tryRaster(double rx, double ry, double z, const LookupOptions& options, LookupResult& result) noexcept;
    bool tryLight(const std::array<double, 3>& p, const LookupOptions& options, LookupResult& result) noexcept;
    bool tryWorld(const std::array<double, 3>& p, const LookupOptions& options, LookupResult& result) noexcept;
    /// The failure of the last try* lookup that returned false.
    const LookupFailure& lastFailure() const noexcept;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
