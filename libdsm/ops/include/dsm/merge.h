// Combining deep shadow maps into one file (the dsm-merge tool): the product
// of maps of separately built occluders, or stitching maps built over parts of
// one image. Definitions and the error bound: spec/merge.md.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

enum class MergeMode : std::uint8_t {
    /// Per pixel and channel, the visibilities multiply (light passing two
    /// independent occluders), then level 0 is recompressed and the writer
    /// rebuilds the mip levels. Inputs: the same light camera, size, tile
    /// size, pixel filter and width. A monochrome map times an RGB map is RGB
    /// (the monochrome value multiplies every channel). The output has counts
    /// when every input has them. When every input has layers (MTSM,
    /// maxLayers > 1) the output has as many as the input with the most: each
    /// layer after the first is the product of the inputs' restarts where the
    /// previous one became opaque (VisibilityProductOptions::maxLayers);
    /// otherwise it has one layer, the light-centre product.
    Product,
    /// Maps built with BuildOptions::region over disjoint parts that cover
    /// the whole image become the map a single full build would have written,
    /// byte for byte: each level-0 pixel comes from the part whose region holds
    /// it, the metadata's settings.region becomes the whole image, tiles are
    /// written in row order with the inputs' writer settings. Inputs must agree
    /// on everything but settings.region.
    Stitch,
};

struct MergeOptions {
    MergeMode mode = MergeMode::Product;
    /// Product: the level-0 recompression tolerance, finite and >= 0; unset
    /// (automatic) = the largest level-0 tolerance of the inputs. Ignored by
    /// Stitch (it keeps the inputs').
    std::optional<double> tolerance;
    /// Product: the largest chord error per pairwise product (see
    /// VisibilityProductOptions); unset = tolerance / 16, at least 2^-20.
    std::optional<double> maxInterpolationError;
    /// zlib level 0..9 of the output; unset (automatic) = Product: 6; Stitch:
    /// the level the inputs' headers record (format 1.1), 6 for 1.0 inputs.
    std::optional<int> zlibLevel;
};

struct MergeReport {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    int channels = 1;
    /// Most layers per pixel of the output (the header's maxLayers).
    int maxLayers = 1;
    std::uint64_t vertices = 0;  ///< level-0 vertices written
    /// Level-0 tolerance of the output.
    double tolerance = 0.0;
    int zlibLevel = 6;
    /// Product: the sum of the inputs' level-0 error bounds plus the largest
    /// interpolation error; the output's level 0 is within this plus
    /// max(tolerance, 2^-25) of the exact product of the exact inputs
    /// (errorBound below). Stitch: the inputs' level-0 bound.
    double inputErrorBound = 0.0;
    double interpolationError = 0.0;
    double errorBound = 0.0;
    std::uint64_t fileBytes = 0;
};

/// Reads `inputs` (at least one; Stitch and Product with one input are
/// allowed), writes `output` atomically (nothing is left at `output` on
/// failure). Throws dsm::Error naming the files and, for inputs that do not
/// fit together, the differing field with both values; for Stitch regions
/// that overlap or leave holes, the overlapping pairs with their rectangles or
/// the uncovered rectangles. The output may not be one of the inputs.
DSM_API MergeReport mergeMaps(const std::vector<std::string>& inputs, const std::string& output, const MergeOptions& options);

DSM_NAMESPACE_END
