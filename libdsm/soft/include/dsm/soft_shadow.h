// Soft shadows of area lights from one map: ray tracing the map as a
// multilayer transparent shadow map (Xie, Tabellion & Pearce 2007, §4-§6),
// with the hierarchical search, penumbra classification and ray shortening of
// Curtis 2009 (§3.5-§3.7); and the classic "PCF based" baseline (Xie §3).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>

#include "dsm/area_light.h"
#include "dsm/lookup.h"
#include "dsm/reader.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// How a light ray that crosses estimated samples loses visibility. Segment i
/// of a layer (from vertex i-1 to vertex i) holds count_i samples that
/// together take V from v_{i-1} to v_i; a ray crosses k of them. Both rules
/// give the same total whether a ray crosses a segment's samples in one pixel
/// or spread over several, and both are exact for the light-centre ray.
enum class SampleAttenuation : std::uint8_t {
    /// Xie et al. eq. 3: subtract k (v_{i-1} - v_i) / count_i, clamped at 0.
    /// Linear in the samples crossed, as partial coverage of a pixel by an
    /// opaque surface is; but a later surface's drop is sized by what the
    /// light-centre ray had left, so a ray that missed an earlier
    /// semi-transparent surface is attenuated too little by a later one
    /// (missing the first of two 50% surfaces leaves 0.75, not 0.5).
    Subtractive = 0,
    /// Multiply by (v_i / v_{i-1})^(k / count_i) per channel: the segment's
    /// samples share its transmittance evenly, right for volumes and for
    /// successive surfaces whatever the ray missed before; but it darkens a
    /// ray that crosses only part of a segment made by partial coverage
    /// (half of a 50%-covered span passes 0.71, not 0.75).
    Multiplicative = 1,
};

struct SoftShadowOptions {
    /// N >= 1 light samples (rays) per receiver, stratified (AreaLight).
    int samples = 64;
    /// K: the map layers used, >= 1; unset uses all of them. Values above the
    /// map's maxLayers are clamped to it. K = 1 ignores every occluder hidden
    /// from the light centre behind a fully opaque one (Xie §6.2).
    std::optional<int> layers;
    /// Xie §6.1 "z threshold": a stored sample at depth z is hit by a ray whose
    /// depth range across the pixel meets [z - zThreshold, z + zThreshold].
    /// Light-space depth units (camera space, not the non-linear screen z),
    /// >= 0. Larger closes light leaks between the samples of surfaces seen
    /// at a grazing angle and grows the umbra. Each depth is counted once per
    /// ray, so a semi-transparent surface is not hit twice by a ray crossing
    /// it near a pixel edge (samples of one ray within 2 zThreshold of a
    /// sample already hit in an earlier pixel are not counted again).
    double zThreshold = 0.0;
    /// Receiver bias against self-shadowing: each ray ends this far (in
    /// light-space depth) before the receiver. >= 0. Must exceed zThreshold
    /// plus the receiver surface's depth change across the pixels around it.
    /// Unset (the default): zThreshold plus automaticBias() (dsm/auto_bias.h)
    /// at the receiver with `normal`.
    std::optional<double> bias;
    /// The receiver surface's world-space normal, for the automatic bias only
    /// (any length, either orientation). Unset: the bias assumes a slope of 1.
    std::optional<Vec3> normal;
    /// A ray stops once its visibility is below this in every channel (Xie
    /// §5.2); its value at that point is kept. In [0, 1].
    double visibilityThreshold = 1e-3;
    /// Seed of the light samples (AreaLight::samples).
    std::uint64_t seed = 1;
    /// Walk the rays through the min/max depth quadtree (Xie §4.3), skipping
    /// nodes a ray passes in front of or behind: a query's rays (64 at a time)
    /// go down it together, each node visited once for all of them; false
    /// walks every pixel each ray crosses. Same result either way.
    bool hierarchy = true;
    /// Penumbra classification and ray shortening (Curtis §3.6-3.7): find the
    /// smallest depth in the part of the map the light's rays to the receiver
    /// can cross (refined twice); a receiver in front of it is lit without
    /// tracing a ray, and every ray starts at that depth. Same result
    /// either way (only fully lit points are classified, never umbrae, which
    /// transparent layers cannot prove).
    bool classification = true;
    /// Stop a ray as soon as layers and counts prove it opaque: in a pixel
    /// where its depth range covers a whole layer (every estimated sample,
    /// none of them already counted) whose last vertex is 0 in every channel,
    /// its visibility is 0 and the rest of its walk is skipped. Crossing that
    /// layer's samples one by one ends at 0 too (or stops below
    /// visibilityThreshold first), so the answer moves by less than
    /// visibilityThreshold per ray, and not at all with a threshold of 0.
    bool umbraEarlyOut = true;
    /// Xie's rule is the default; neither wins everywhere. Against the
    /// reference ray tracer (same light samples), Subtractive had the smaller
    /// mean error on opaque meshes (the pipes of examples/cloud-and-pipes.json)
    /// and a homogeneous volume, Multiplicative on the semi-transparent hair
    /// of examples/hairball.json, and they were within 10% on the whole
    /// cloud-and-pipes scene.
    SampleAttenuation attenuation = SampleAttenuation::Subtractive;
};

struct SoftShadowResult {
    /// Mean visibility of the light in [0, 1] per channel; for a monochrome
    /// map v[1] = v[2] = v[0].
    std::array<double, 3> v{1.0, 1.0, 1.0};
    int channels = 1;
    /// Rays traced; 0 when the receiver is outside the map, behind the light's
    /// plane, or classified as lit.
    int rays = 0;
    /// The classification proved the receiver lit.
    bool classifiedLit = false;
    /// PCF baseline only: the blocker depth used and the filter width (level-0
    /// pixels) it gave; 0 when no blocker was found.
    double blockerDepth = 0.0;
    double filterWidth = 0.0;
};

/// Work counters of one context (summed over its queries).
struct SoftShadowStats {
    std::uint64_t queries = 0;
    std::uint64_t classifiedLit = 0;
    std::uint64_t rays = 0;
    std::uint64_t nodesVisited = 0;   ///< quadtree nodes above pixels that rays entered, once per ray
    std::uint64_t pixelsVisited = 0;  ///< pixels whose functions were read
    std::uint64_t samplesHit = 0;     ///< estimated samples that attenuated a ray
    std::uint64_t raysProvenOpaque = 0;  ///< rays stopped by the umbra early-out
};

/// A map and an area light, ready to be traced: holds the min/max depth
/// quadtree. Its levels above the tiles come from the tile directory when the
/// tracer is made; the levels inside a tile are built the first time a ray
/// or the penumbra classification's search reaches the tile (so a query pays
/// only for the tiles it touches; hierarchyTilesBuilt() counts them) and kept
/// for the tracer's life (about 2.7 KB per 32 x 32 tile; there is no
/// eviction). Thread-safe: share one between threads, and
/// give each thread a SoftShadowContext.
class DSM_API SoftShadowTracer {
public:
    /// `light` must have been made for the map's light camera (throws
    /// dsm::Error otherwise, or when the map is empty).
    SoftShadowTracer(std::shared_ptr<const DeepShadowMap> map, const AreaLight& light);
    ~SoftShadowTracer();
    SoftShadowTracer(const SoftShadowTracer&) = delete;
    SoftShadowTracer& operator=(const SoftShadowTracer&) = delete;

    const DeepShadowMap& map() const;
    const AreaLight& light() const;
    /// Tiles whose depth mini-pyramids have been built so far.
    std::size_t hierarchyTilesBuilt() const;

private:
    friend class ImplAccess;
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Soft-shadow queries for one thread (not thread-safe itself). Keeps the
/// last tiles it touched and a LookupContext for the PCF baseline. Results
/// depend only on the map, the light, the receiver and the options: the same
/// on every thread and every run.
///
/// Receivers are world points. A receiver whose light-centre projection falls
/// outside the raster [0, width] x [0, height], or whose depth is not beyond
/// the light's plane plus the bias, is lit (v = 1, no rays).
/// Throws dsm::Error for options out of range or a non-finite receiver, and
/// passes on the reader's errors for a damaged file.
class DSM_API SoftShadowContext {
public:
    explicit SoftShadowContext(std::shared_ptr<const SoftShadowTracer> tracer);
    ~SoftShadowContext();
    SoftShadowContext(const SoftShadowContext&) = delete;
    SoftShadowContext& operator=(const SoftShadowContext&) = delete;

    /// Fraction of the light visible from `receiverWorld`: the mean over
    /// options.samples rays from the receiver to AreaLight samples of the
    /// rays' visibility through the map (Xie §5.2). Per pixel a ray crosses,
    /// its light-space depth range [z_enter, z_exit] is met with the stored
    /// vertices and, between two vertices of a layer, with count_i evenly
    /// spaced estimated sample depths; each sample hit attenuates the ray
    /// (see SampleAttenuation). Layers 0 .. K-1 are used. A map without counts
    /// has one sample per vertex.
    SoftShadowResult visibility(const Vec3& receiverWorld, const SoftShadowOptions& options = {});

    /// The classic PCF-based soft shadow from the same map (Xie §3): the
    /// smallest depth z_b in the map region the light's rays to the receiver
    /// cross (the classification search above) estimates the blocker; the
    /// penumbra width at the receiver's raster position follows from similar
    /// triangles, w = 2 r (p_z - z_b) / ((p_z - d) z_b) in screen units,
    /// converted to level-0 pixels (r the light's larger half-size, d its
    /// plane depth; Xie eq. 1 with the light at depth d); the result is a
    /// box-filtered, mip-mapped deep shadow lookup (LookupContext) of that
    /// width at the receiver's depth minus the bias. Uses the bias,
    /// options.zThreshold (in the blocker test) and nothing else.
    SoftShadowResult pcfVisibility(const Vec3& receiverWorld, const SoftShadowOptions& options = {});

    const SoftShadowStats& stats() const;
    void resetStats();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
