// Transmittance of one sample ray from the light (Lokovic & Veach 2000, §3.2).
#pragma once

#include <array>
#include <limits>
#include <memory>

#include "dsm/span.h"
#include "dsm/sweep.h"
#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// A surface crossed by the ray: depth and opacity per channel in [0, 1]. For a
/// monochrome ray only opacity[0] is used.
struct SurfaceHit {
    float z = 0.0f;
    std::array<float, kMaxChannels> opacity{1.0f, 1.0f, 1.0f};
};

/// A sample of a volume's extinction coefficient kappa (per unit depth, >= 0)
/// at depth z. Between two samples kappa is linear; outside the first and last
/// sample of a ray there is no volume.
struct VolumeSample {
    float z = 0.0f;
    float extinction = 0.0f;
};

/// Everything one sample ray met, in any order; transmittance() sorts a copy.
struct SampleRay {
    Span<const SurfaceHit> hits;
    Span<const VolumeSample> volume;
};

/// Builds the transmittance function tau(z) = tau_s(z) * tau_v(z) of one ray.
///
/// - Surfaces composite as products of (1 - opacity); each hit becomes a
///   vertical step (two vertices at its depth). Several hits at one depth make
///   one step. Hits with opacity exactly 0 in every channel block nothing and
///   are left out (no vertex, no count).
/// - The volume transmittance multiplies, per segment between consecutive
///   samples, T_i = exp(-(z_{i+1} - z_i) (kappa_i + kappa_{i+1}) / 2).
/// - tau is evaluated at the merged vertices of both and is linear between them.
/// - Counts (when `withCounts`): 1 per surface hit, on the vertex after its
///   step; 1 per volume step of positive length, on the vertex that ends it.
/// - `zStart`: only what lies strictly beyond zStart counts (used to start a new
///   MTSM layer behind an opaque one). Hits at z <= zStart are dropped; a volume
///   segment that straddles zStart is cut there, with kappa interpolated.
///
/// Computed in double and stored as float; underflow ends at exactly 0, never NaN.
/// Throws dsm::Error naming the hit or sample index and the bad value for
/// non-finite or negative depths, opacities outside [0, 1] and non-finite or
/// negative extinction.
DSM_API VisibilityFunction transmittance(const SampleRay& ray, int channels, bool withCounts,
                                 float zStart = -std::numeric_limits<float>::infinity());

/// transmittance() with its working memory (the sorted copies of a ray's hits
/// and volume samples) kept between rays, for a caller that builds many on one
/// thread: once the buffers and `out` have grown to the largest ray, building
/// allocates nothing. Not thread-safe: one per thread.
class DSM_API TransmittanceBuilder {
public:
    TransmittanceBuilder();
    ~TransmittanceBuilder();
    TransmittanceBuilder(TransmittanceBuilder&&) noexcept;
    TransmittanceBuilder& operator=(TransmittanceBuilder&&) noexcept;

    /// Replaces `out` by transmittance(ray, channels, withCounts, zStart),
    /// reusing its storage. Same checks and errors; `out` is unspecified
    /// after an error.
    void build(const SampleRay& ray, int channels, bool withCounts, float zStart, VisibilityFunction& out);
    /// Prepares the same transmittance for the sweep: what out.assign() of
    /// the function above gives, bit for bit. A ray without volume samples
    /// (steps alone) is prepared directly, without building the function.
    /// Same checks and errors; `out` is unspecified after an error.
    void build(const SampleRay& ray, int channels, bool withCounts, float zStart, SweepInput& out);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
