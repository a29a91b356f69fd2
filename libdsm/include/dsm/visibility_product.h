// The product of visibility functions: the light that passes several
// independent occluders (hair and smoke built separately) is the product of
// their visibilities. Proof of the error bound: spec/merge.md.
#pragma once

#include <cstddef>
#include <span>

#include "dsm/visibility.h"

namespace dsm {

struct VisibilityProductOptions {
    /// L-infinity tolerance epsilon >= 0 of the recompression (compressor.h).
    double tolerance = 0.0;
    /// Largest chord error allowed per pairwise product, where both factors
    /// change along one segment and the exact product there is quadratic.
    /// Negative means tolerance / 16, but at least 2^-20 (so that a tolerance
    /// of 0 does not ask for unbounded subdivision).
    double maxInterpolationError = -1.0;
    /// Keep sample counts: a vertex's count is the sum of the factors' counts
    /// that fall in its segment. Factors without counts contribute 0.
    bool keepCounts = false;
    /// Store a monochrome function when every channel agrees within the
    /// tolerance (as the compressor allows).
    bool allowMonochrome = true;
};

struct VisibilityProduct {
    /// The product, compressed: one layer; RGB when a non-empty factor is RGB
    /// (a monochrome factor multiplies every channel) unless allowMonochrome
    /// and the channels agree within the tolerance; monochrome otherwise.
    /// Empty when every factor is empty (V = 1).
    VisibilityFunction function;
    /// Largest chord error of the piecewise-linear product before compression
    /// against the exact product of the factors as stored, summed over the
    /// pairwise products (N - 1 of them for N factors). The result obeys
    /// |V - prod_i F_i| <= interpolationError + max(tolerance, 2^-25) at every
    /// depth, prod_i F_i being the exact product of the light-centre functions
    /// of the factors.
    double interpolationError = 0.0;
    /// Vertices of the uncompressed product handed to the compressor.
    std::size_t productVertices = 0;
};

/// Multiplies the light-centre functions of `factors` (layers beyond layer 0
/// are not representable in a product and are dropped, see spec/merge.md) and
/// recompresses the result with options.tolerance. The product is evaluated
/// at the union of the factors' depths; a segment where two factors both
/// change is subdivided into n equal parts with |dA dB| / (4 n^2) at most
/// options.maxInterpolationError, as far as float32 depths allow.
///
/// Factors must be valid (VisibilityView::validate) and have 1 or 3 channels.
/// No factors gives an empty function. Throws dsm::Error for an option out of
/// range.
VisibilityProduct multiplyVisibility(std::span<const VisibilityView> factors,
                                     const VisibilityProductOptions& options = {});

}  // namespace dsm
