// The product of visibility functions: the light that passes several
// independent occluders (hair and smoke built separately) is the product of
// their visibilities. Proof of the error bound: spec/merge.md.
#pragma once

#include <cstddef>
#include <optional>

#include "dsm/span.h"
#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

struct VisibilityProductOptions {
    /// L-infinity tolerance epsilon >= 0 of the recompression (compressor.h).
    double tolerance = 0.0;
    /// Largest chord error allowed per pairwise product, where both factors
    /// change along one segment and the exact product there is quadratic:
    /// finite and > 0. Unset (automatic) means tolerance / 16, but at least
    /// 2^-20 (so that a tolerance of 0 does not ask for unbounded subdivision).
    std::optional<double> maxInterpolationError;
    /// Keep sample counts: a vertex's count is the sum of the factors' counts
    /// that fall in its segment. Factors without counts contribute 0.
    bool keepCounts = false;
    /// Store a monochrome function when every channel agrees within the
    /// tolerance (as the compressor allows).
    bool allowMonochrome = true;
    /// Most layers of the product (MTSM, Xie et al. 2007 §5.1), 1..255. With
    /// 1 the product is the light-centre product alone. With K > 1 layer 0
    /// ends, as the compressor ends a layer, at the first product vertex at or
    /// below the tolerance in every channel, depth d; the next layer is the
    /// product of the factors' restarts at d (what lies strictly beyond d,
    /// rebuilt from each factor's own layers), and so on up to K layers.
    /// Callers ask for layers only when every factor comes from a layered
    /// source: a factor with one layer is taken as complete, so it knows
    /// nothing of what hides behind its opaque parts (spec/merge.md).
    int maxLayers = 1;
    /// The layer budget of each factor (the maxLayers of the map it comes
    /// from), one per factor; empty means maxLayers for every factor. A factor
    /// with fewer layers than its budget has nothing behind the end of its
    /// last layer (a build would have begun another); one that used its whole
    /// budget may hide more there, unknown, so the product's layers stop where
    /// a restart would need what lies behind it.
    Span<const int> factorLayers;
};

struct VisibilityProduct {
    /// The product, compressed: up to options.maxLayers layers; RGB when a non-empty factor is RGB
    /// (a monochrome factor multiplies every channel) unless allowMonochrome
    /// and the channels agree within the tolerance; monochrome otherwise.
    /// Empty when every factor is empty (V = 1).
    VisibilityFunction function;
    /// Largest chord error of the piecewise-linear product before compression
    /// against the exact product of the factors as stored, summed over the
    /// pairwise products (N - 1 of them for N factors); with layers, the
    /// largest over the layers. The light-centre function of the result obeys
    /// |V - prod_i F_i| <= interpolationError + max(tolerance, 2^-25) at every
    /// depth, prod_i F_i being the exact product of the light-centre functions
    /// of the factors. Layer k > 0 is within the same of the product of the
    /// factors' restarts at its start depth (spec/merge.md: exact restarts at
    /// the factors' own layer boundaries, ratios inside a layer).
    double interpolationError = 0.0;
    /// Vertices of the uncompressed product handed to the compressor, over
    /// all layers.
    std::size_t productVertices = 0;
};

/// Multiplies the light-centre functions of `factors` and recompresses the
/// result with options.tolerance; with options.maxLayers > 1 the deeper
/// layers follow from the factors' layers (see VisibilityProductOptions). The product is evaluated
/// at the union of the factors' depths; a segment where two factors both
/// change is subdivided into n equal parts with |dA dB| / (4 n^2) at most
/// options.maxInterpolationError, as far as float32 depths allow.
///
/// Factors must be valid (VisibilityView::validate) and have 1 or 3 channels.
/// No factors gives an empty function. Throws dsm::Error for an option out of
/// range (tolerance, interpolation error, maxLayers).
DSM_API VisibilityProduct multiplyVisibility(Span<const VisibilityView> factors,
                                     const VisibilityProductOptions& options = {});

DSM_NAMESPACE_END
