// Deep OpenEXR interop: deep shadow maps as deep EXR images and back
// (mapping and error analysis: spec/exr-interop.md).
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// One deep EXR sample seen from the light ("Interpreting OpenEXR Deep
/// Pixels"). zBack <= z makes a point sample at z; zBack > z a volume sample
/// over [z, zBack) whose transmittance falls exponentially:
///   T(z') = (1 - alpha)^((z' - z) / (zBack - z)).
/// `alpha` is the A channel; `alphaRGB` the AR, AG, AB channels (equal to
/// `alpha` in a monochrome image).
struct DeepSample {
    float z = 0.0f;
    float zBack = 0.0f;
    float alpha = 0.0f;
    std::array<float, 3> alphaRGB{0.0f, 0.0f, 0.0f};
};

/// Largest |linear - exponential| over one segment whose visibility falls
/// from v0 to v1 (0 <= v1 <= v0 <= 1): a linear segment of a map against the
/// volume sample of alpha 1 - v1/v0 that replaces it, and the other way round.
/// Equals v0 * g(v1 / v0) with g(1) = 0, g(r) ~ ln(r)^2 / 8 near 1, g(0) = 1.
DSM_API double exponentialDeviation(double v0, double v1);

/// The samples that represent a visibility function in a deep EXR: one point
/// sample per vertical step (including the drop from V = 1 at the first
/// vertex), volume samples for sloped segments, subdivided so that
/// exponentialDeviation() of every piece, in every channel and in the mean of
/// the channels, is at most `maxDeviation` (> 0), except for pieces one float
/// step of depth long (see ExrExportReport::oneStepExcess). Flat segments make no
/// sample; nothing follows V = 0. For a layered (MTSM) function, the
/// light-centre function is exported (layer 0, then 0 from its last vertex).
/// Sorted and non-overlapping ("tidy"). For RGB, alphaRGB carries the channels
/// and alpha the mean visibility: 1 - alpha = mean(V after) / mean(V before).
/// The product of (1 - alpha) over all samples is V at the last vertex.
/// Throws dsm::Error when maxDeviation is not positive.
DSM_API std::vector<DeepSample> deepSamplesFromVisibility(const VisibilityView& function, double maxDeviation);

/// The transmittance of deep samples in any order (messy or tidy: the result
/// is that of the tidy image "Interpreting OpenEXR Deep Pixels" defines, the
/// product over all samples of (1 - alpha_i(z))), as a piecewise-linear
/// function with |V - T| <= maxLinearError (> 0) everywhere: exact at every
/// sample front and back, densely enough in between. `channels` 1 uses
/// `alpha`, 3 uses `alphaRGB`. A volume sample of alpha 1 becomes a step at its
/// front (EXR leaves T = 1 at exactly z, 0 just after). Not compressed.
/// Throws dsm::Error naming the sample index for a depth that is negative or
/// not finite, or an alpha outside [0, 1].
DSM_API VisibilityFunction visibilityFromDeepSamples(std::span<const DeepSample> samples, int channels,
                                             double maxLinearError);

/// Standard OpenEXR camera attributes for a light camera (Imath row-vector
/// convention, p' = p * M). worldToCamera: the light space is OpenEXR's camera
/// space (x right, y up, z the viewing direction), so this is the transpose of
/// worldToLight. worldToNDC: worldToCamera times a projection onto NDC
/// ((0, 0) top left, (1, 1) bottom right of the display window).
struct StandardCameraMatrices {
    std::array<std::array<float, 4>, 4> worldToCamera{};
    std::array<std::array<float, 4>, 4> worldToNDC{};
};
DSM_API StandardCameraMatrices standardCameraMatrices(const LightCamera& camera);

/// The light camera described by worldToCamera and worldToNDC (the inverse of
/// standardCameraMatrices, up to float precision; nearPlane 0). Throws
/// dsm::Error when worldToCamera is singular or worldToNDC is not a
/// perspective or orthographic projection along the camera's z axis.
DSM_API LightCamera cameraFromStandardMatrices(const std::array<std::array<double, 4>, 4>& worldToCamera,
                                       const std::array<std::array<double, 4>, 4>& worldToNDC);

/// The smallest bound accepted for ExrExportOptions::maxDeviation and
/// ExrImportOptions::maxLinearError. Depths and visibilities pass through
/// float32, which resolves a visibility near 1 to 2^-24 (about 6e-8) and
/// carries errors of a few 1e-7 through a pixel's samples: a tighter bound
/// cannot be kept, and chasing it only multiplies samples (memory) and chord
/// vertices (time) without end.
inline constexpr double kMinExrErrorBound = 1e-6;

struct ExrExportOptions {
    /// Mip level of the map to export (0 = full resolution).
    unsigned level = 0;
    /// Deep tiled instead of deep scanline (some compositors read only scanline).
    bool tiled = false;
    /// Tile edge of a tiled EXR.
    std::uint32_t tileSize = 64;
    /// Bound on |T_exr(z) - V(z)| from the exponential interpretation of volume
    /// samples. Unset (automatic) chooses clamp(tolerance / 2, 1e-5, 1e-3) from
    /// the exported level's tolerance; a value must lie in [kMinExrErrorBound,
    /// 1] (NaN and values outside are refused with ErrorCode::argument).
    std::optional<double> maxDeviation;
};

struct ExrExportReport {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    int channels = 1;
    double maxDeviation = 0.0;
    std::uint64_t pointSamples = 0;
    std::uint64_t volumeSamples = 0;
    /// Largest exponentialDeviation() of any volume sample written, except
    /// those counted in oneStepExcess.
    double largestDeviation = 0.0;
    /// Volume samples (times channels) one float step of depth long whose
    /// deviation exceeds the bound: a segment too steep to cut finer in
    /// float depths. The excess lies strictly between two adjacent float
    /// depths, where no float query can see it.
    std::uint64_t oneStepExcess = 0;
    /// The map has counts or layers: its exact vertices are also written, as
    /// vertex samples (alpha 0, dsm.* channels; spec/exr-interop.md).
    bool vertexSamples = false;
    /// Vertex samples written.
    std::uint64_t vertices = 0;
};

/// Writes level `options.level` of a map as a deep EXR (ZIPS, float channels
/// Z, ZBack, A and for RGB maps also AR, AG, AB, R, G, B with R = AR etc.), the
/// standard worldToCamera / worldToNDC / screenWindow attributes and the
/// exact dsm:* attributes (spec/exr-interop.md). A map with counts or layers
/// also gets vertex samples. The header attributes and windows an imported
/// map kept in its metadata ("exr") are given back. Written to a temporary file
/// beside `exrPath` and renamed into place: on failure no file is left.
/// Throws dsm::Error naming the file, level or pixel.
DSM_API ExrExportReport exportDeepExr(const std::string& dsmPath, const std::string& exrPath,
                              const ExrExportOptions& options = {});

struct ExrImportOptions {
    /// The part to read: its index ("0", "1", ...) or its name. Empty: the
    /// first deep part of `view`, or the first deep part.
    std::string part;
    /// The view to read: the deep part whose `view` attribute is this.
    std::string view;
    /// The channel for a role (Z, ZBack, A, AR, AG, AB). A role not mapped is
    /// the channel of that name, else the one channel whose last component
    /// (after the last '.') is the role, as in "depth.Z" (parseExrChannelMapping()).
    std::map<std::string, std::string> channels;
    /// Compression tolerance, finite and >= 0. Unset (automatic) uses the
    /// file's dsm:tolerance when present, else kDefaultExrImportTolerance.
    std::optional<double> tolerance;
    /// Bound on the linearisation of exponential volume samples. Unset
    /// (automatic) uses clamp(tolerance / 4, 1e-5, 1e-3); a value must lie in
    /// [kMinExrErrorBound, 1] (NaN and values outside are refused with
    /// ErrorCode::argument).
    std::optional<double> maxLinearError;
    /// The light camera; when empty it comes from the file (dsm:* attributes,
    /// else worldToCamera and worldToNDC).
    std::optional<LightCamera> camera;
    /// When set (and no `camera`): a perspective light with this horizontal
    /// field of view in degrees, in (0, 180), square pixels, centred; its
    /// worldToLight from the file's worldToCamera, else the identity.
    std::optional<double> fieldOfView;
    /// When set (and no `camera` or fieldOfView): an orthographic light with a
    /// window this wide in light units (finite, > 0), square pixels, centred;
    /// worldToLight as for fieldOfView.
    std::optional<double> orthoWidth;
    std::uint32_t tileSize = 32;
    /// As WriterOptions::mipLevels (unset = full pyramid).
    std::optional<unsigned> mipLevels;
    /// As WriterOptions::levelToleranceFactor (docs/dsm-convert.md measures
    /// what it trades on sparse camera images).
    double levelToleranceFactor = 0.5;
    int zlibLevel = 6;
};

/// One display step of an 8-bit image: a deep EXR records no sample count to
/// derive Lokovic & Veach's 0.25 / sqrt(N) from.
inline constexpr double kDefaultExrImportTolerance = 1.0 / 256.0;

struct ExrImportReport {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    int channels = 1;
    double tolerance = 0.0;
    double maxLinearError = 0.0;
    /// "option", "field of view", "orthographic width", "dsm attributes" or
    /// "standard attributes".
    std::string cameraSource;
    /// The part read ("part 1 'deep' (view 'left')") and its channels
    /// ("Z=depth.Z, A=rgba.A").
    std::string part;
    std::string channelNames;
    /// What a caller should know: the other deep parts not read.
    std::vector<std::string> notes;
    /// Samples of the display window read into the map.
    std::uint64_t samples = 0;
    /// Of those, samples at the depth (Z and ZBack) of another sample of the
    /// same pixel: combined with it (OpenEXR's merge rule), not lost.
    std::uint64_t mergedSamples = 0;
    /// Samples of the data window outside the display window: not in the map.
    std::uint64_t droppedSamples = 0;
    std::uint64_t vertices = 0;
    /// The image carried vertex samples: the map's vertices were read as
    /// they are (no linearisation, no compression).
    bool fromVertexSamples = false;
    /// Chunks (scanline blocks or tiles) of the image and decodes made: each
    /// chunk is decoded once.
    std::uint64_t exrChunks = 0;
    std::uint64_t exrDecodes = 0;
    bool tiled = false;
    /// What the source image states as its own error (its dsm:errorBound plus
    /// dsm:maxDeviation; 0 for other images), and the error bound recorded
    /// for level 0: tolerance + maxLinearError + sourceErrorBound (only the
    /// source's for vertex samples).
    double sourceErrorBound = 0.0;
    double errorBound = 0.0;
};

/// The channel mapping "ROLE=CHANNEL[,ROLE=CHANNEL...]" with roles Z, ZBack,
/// A, AR, AG, AB (ExrImportOptions::channels). Throws dsm::Error
/// (ErrorCode::argument) naming the item that is not one.
DSM_API std::map<std::string, std::string> parseExrChannelMapping(const std::string& text);

/// True when the file at `path` starts with OpenEXR's magic number (whatever
/// its name); false when it does not or cannot be read.
DSM_API bool hasOpenExrMagic(const std::string& path);

/// Reads a deep EXR part (scanline or tiled; options.part / view, else the
/// first deep part) rendered from a light and writes a map of its display
/// window: per pixel visibilityFromDeepSamples() then the compressor,
/// mip-mapped by MapWriter, or the vertex samples as they are. Monochrome
/// from A, or RGB when AR, AG and AB are all present (options.channels).
/// Pixels outside the data window are empty; samples outside the display
/// window are counted, not read. Level 0 records as its tolerance the whole
/// error bound against the image's transmittance (and what the image states
/// of its own source): tolerance + maxLinearError + sourceErrorBound. The
/// image's string attributes and windows go into the metadata under "exr".
/// Throws dsm::Error naming the file (and pixel) when it is not a deep EXR,
/// has no such part, no Z or alpha channel, holds invalid samples, or has no
/// camera.
DSM_API ExrImportReport importDeepExr(const std::string& exrPath, const std::string& dsmPath,
                              const ExrImportOptions& options = {});

DSM_NAMESPACE_END
