// From the sample rays of one pixel to its compressed visibility function:
// transmittance (LV §3.2) -> sweep (LV §5.1) -> compressor (LV §3.3), with the
// multilayer restarts of Xie et al. §5.1.
#pragma once

#include <cstdint>
#include <memory>

#include "dsm/compressor.h"
#include "dsm/transmittance.h"
#include "dsm/span.h"
#include "dsm/sweep.h"
#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// The visibility function of one pixel: the filter-weighted average of the
/// transmittance of `rays` (weights[k] for rays[k]), compressed with
/// `options`. Channel count and counts come from `options`.
///
/// With options.maxLayers = K > 1, when the compressor ends a layer at depth
/// z_e (all light blocked within tolerance), the transmittances are rebuilt
/// from what lies strictly beyond z_e and swept again into the next layer, up
/// to K layers. The sum of the counts equals the number of surface hits with
/// non-zero opacity plus volume steps over all rays.
///
/// Errors name the ray index and the offending hit or sample.
///
/// `timings`, when given, receives the seconds spent in each stage (added to
/// what it holds) and the number of transmittance vertices swept.
struct PixelTimings {
    double transmittanceSeconds = 0.0;
    double sweepSeconds = 0.0;
    double compressionSeconds = 0.0;
    std::uint64_t transmittanceVertices = 0;
};
DSM_API VisibilityFunction buildVisibility(Span<const SampleRay> rays, Span<const double> weights,
                                   const CompressorOptions& options, PixelTimings* timings = nullptr);

/// buildVisibility() with its working memory (transmittances, the sweep's
/// state and output, the compressor) kept between pixels, for a caller that
/// builds many pixels with one set of options on one thread: once its buffers
/// have grown to the largest pixel, a pixel allocates only its result, and
/// nothing when built into a function handed back pixel after pixel. Not
/// thread-safe: one per thread.
class DSM_API PixelBuilder {
public:
    /// Throws dsm::Error for bad options, as the compressor does.
    explicit PixelBuilder(const CompressorOptions& options);
    ~PixelBuilder();
    PixelBuilder(PixelBuilder&&) noexcept;
    PixelBuilder& operator=(PixelBuilder&&) noexcept;

    /// buildVisibility(rays, weights, options, timings).
    VisibilityFunction build(Span<const SampleRay> rays, Span<const double> weights, PixelTimings* timings = nullptr);

    /// The same from the rays' transmittances built beforehand (so that a ray
    /// shared by several pixels is built once): transmittances[k] must equal
    /// transmittance(rays[k], options.channels, options.keepCounts). The rays
    /// themselves are read only to start the layers after the first (MTSM).
    /// `timings` receives no transmittance time for the given functions.
    VisibilityFunction build(Span<const VisibilityView> transmittances, Span<const SampleRay> rays,
                             Span<const double> weights, PixelTimings* timings = nullptr);

    /// The same from the rays' transmittances prepared for the sweep
    /// (SweepInput::assign), so that a transmittance averaged into several
    /// pixels is read once.
    VisibilityFunction build(Span<const SweepInput* const> transmittances, Span<const SampleRay> rays,
                             Span<const double> weights, PixelTimings* timings = nullptr);

    /// The same into `out` (its previous contents dropped), whose storage the
    /// builder keeps for the next pixel (Compressor::finish(VisibilityFunction&)):
    /// a caller that builds into the same functions again, as a sampler
    /// rebuilding a tile's pixels tile after tile, allocates nothing per pixel
    /// once they have grown. On an error `out` is left empty or as it was.
    void build(Span<const SweepInput* const> transmittances, Span<const SampleRay> rays, Span<const double> weights,
               VisibilityFunction& out, PixelTimings* timings = nullptr);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
