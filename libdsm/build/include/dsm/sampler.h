// The reference sampler: renders a scene from the light and writes a deep
// shadow map (Lokovic & Veach 2000, §3.2, §5.1, §5.5; Xie et al. 2007, §5.1).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>

#include "dsm/map_info.h"
#include "dsm/scene.h"
#include "dsm/transmittance.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// How a build's samples find the surfaces they cross. Both give each
/// sample the same crossings (the exact crossings of the ray through it, at
/// its time); volumes are ray-marched per sample by both.
enum class SamplerMethod {
    /// Primitives bucketed once into the tiles they reach, then each
    /// tested against the tile's samples under its projected bounds.
    scanline,
    /// A ray cast per sample through Embree's bounding volume hierarchy,
    /// each primitive it reaches crossed by the same exact test (the
    /// cross-check).
    raytrace,
};

struct BuildOptions {
    /// Image size, each >= 1; unset keeps the scene light's resolution.
    std::optional<std::uint32_t> width;
    std::optional<std::uint32_t> height;
    /// Samples per pixel, stratified and jittered: one sample in each cell of
    /// a g x ceil(spp / g) grid over the pixel, g = floor(sqrt(spp)) (a
    /// sqrt x sqrt grid when spp is a square). When the grid has more cells
    /// than spp, each pixel uses spp of them chosen at random. Shutter times
    /// are stratified likewise, spp strata in random order.
    std::uint32_t samplesPerPixel = 16;
    /// Compression tolerance, finite and >= 0; unset (automatic) = 0.25 /
    /// sqrt(samples per pixel) (Lokovic & Veach §4), or for a scene with an
    /// area light half that.
    std::optional<double> tolerance;
    /// Pixel filter; unset = Gaussian, or for a scene with an area light box.
    std::optional<PixelFilter> filter;
    /// Filter width in pixels (the footprint's diameter); unset = 2, or 1 for
    /// the box filter of a scene with an area light.
    std::optional<double> filterWidth;
    /// As WriterOptions::mipLevels: 1 = no mip-maps, N levels; unset = full pyramid.
    std::optional<unsigned> mipLevels;
    /// As WriterOptions::levelToleranceFactor: each coarser level's tolerance
    /// is the previous one's times this, finite and > 0 (0.5: every level's
    /// error bound stays within 2 x tolerance; 1: smaller pyramids, the bound
    /// grows by one tolerance per level; docs/dsm-build.md measures both).
    double levelToleranceFactor = 0.5;
    /// Centred compression (CompressorOptions::centred) at every level: plateaus
    /// behind semi-transparent surfaces and ramps keep a mean signed error
    /// within a tenth of the tolerance, and so do plateaus where they end, for
    /// larger maps (docs/dsm-build.md, "Centred compression"). Off: Lokovic &
    /// Veach's greedy rule.
    bool centredCompression = false;
    std::uint32_t tileSize = 32;
    /// Layers per pixel (1 = plain deep shadow map; > 1 = MTSM with counts);
    /// unset = 1, or for a scene with an area light 2.
    std::optional<int> mtsmLayers;
    /// Store sample counts even without MTSM layers.
    bool counts = false;
    /// Pixel rectangle [x0, x1) x [y0, y1) to build; the rest of the map is
    /// left empty (for distributed builds stitched later). Empty = everything.
    std::array<std::uint32_t, 4> region{0, 0, 0, 0};
    /// Worker threads, >= 1; unset uses all cores, and more than the cores are
    /// clamped to them (usableThreads(), dsm/threads.h). The output does not
    /// depend on it.
    std::optional<unsigned> threads;
    std::uint64_t seed = 1;
    SamplerMethod sampler = SamplerMethod::scanline;
    int zlibLevel = 6;
    /// The tiles' compressor and, for zstd, its level (WriterOptions).
    TileCodec codec = TileCodec::Zlib;
    int zstdLevel = 19;
    /// Called now and then with the fraction done, one call at a time, from
    /// one of the build's threads (not necessarily the calling one).
    std::function<void(double)> progress;
    /// Receives the sample rays of each built pixel (x, y) before filtering:
    /// the raw data a deep image would hold (each ray's hits and volume
    /// samples, in no particular order within a ray). Called once per pixel of
    /// the region, from worker threads, in no particular order: it must be
    /// thread-safe. The spans are valid during the call only.
    std::function<void(std::uint32_t x, std::uint32_t y, std::span<const SampleRay> rays)> sampleRays;
};

struct BuildStats {
    double samplingSeconds = 0.0;     ///< ray casting and transmittance (summed over threads)
    double crossingSeconds = 0.0;     ///< of samplingSeconds: finding what each sample crosses
    double sweepSeconds = 0.0;        ///< filtering by the sweep (summed over threads)
    double compressionSeconds = 0.0;  ///< L-infinity compression (summed over threads)
    double writingSeconds = 0.0;      ///< tile encoding, mip levels and I/O
    double wallSeconds = 0.0;
    std::uint64_t samples = 0;        ///< sample rays cast
    std::uint64_t sampleVertices = 0; ///< vertices of all transmittance functions (the raw data)
    std::uint64_t pixels = 0;
    std::uint64_t vertices = 0;       ///< level-0 vertices written
    std::uint32_t maxVerticesPerPixel = 0;
    double tolerance = 0.0;           ///< the level-0 tolerance used
    std::uint64_t fileBytes = 0;
    /// Bytes the raw per-sample transmittance vertices would take as float
    /// (z, V per channel) pairs.
    std::uint64_t rawBytes = 0;
};

/// What a build will take, known before it starts.
struct BuildEstimate {
    std::uint32_t width = 0;         ///< map size (the scene light's or the options')
    std::uint32_t height = 0;
    std::uint64_t pixels = 0;        ///< pixels built: the region's
    std::uint64_t sampleRays = 0;    ///< pixels x samples per pixel
    /// Memory the build holds at once, at least: the tile directories of all
    /// levels, the pixel functions of the level-0 tiles in flight (a row of
    /// tiles and two per worker, built or waiting for the writer) and of the
    /// pending mip tiles (a few vertices each), and each worker's samples of
    /// one tile with their transmittances.
    std::uint64_t memoryBytes = 0;
};

/// The options a build of `scene` uses: `options` with every unset field
/// that has a default set to it (size, tolerance, filter, filter width,
/// layers). A scene whose light has an area light (area_radius > 0) is built
/// for soft shadows traced through the map, and gets defaults chosen for that
/// from the measured error budget (docs/dsm-lookup.md, "Where the error comes
/// from"); any other scene gets the plain deep shadow map's. Fields the caller
/// set are kept as they are (and not checked: buildMap does that).
DSM_API BuildOptions resolvedBuildOptions(const Scene& scene, const BuildOptions& options);

/// The estimate for buildMap(scene, options, ...), without building; options
/// are not checked (buildMap does that).
DSM_API BuildEstimate estimateBuild(const Scene& scene, const BuildOptions& options);

/// Renders `scene` from its light and writes the map to `path` (atomically:
/// nothing is left at `path` on failure). Deterministic: the same scene,
/// options and seed give a byte-identical file for any thread count.
DSM_API BuildStats buildMap(const Scene& scene, const BuildOptions& options, const std::string& path);

DSM_NAMESPACE_END
