// What a deep shadow map file describes about itself: size, tiling, channels,
// the light camera, the mip levels and their tolerances, metadata.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "dsm/vec3.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// How the light sees the scene. Light space: x right, y up, z forward along
/// the view axis. Depth in a map is light-space z (world units when the
/// world-to-light transform is rigid).
enum class Projection : std::uint8_t { Perspective = 0, Orthographic = 1 };

/// The pixel filter used to build a map (recorded for reference) or to filter
/// lookups.
enum class PixelFilter : std::uint8_t { Box = 0, Triangle = 1, Gaussian = 2 };

/// The light camera of a map (the "shadow camera" of Lokovic & Veach §2).
///
/// Screen coordinates: perspective (sx, sy) = (x / z, y / z); orthographic
/// (sx, sy) = (x, y). The screen window [xmin, xmax] x [ymin, ymax] maps onto the
/// raster [0, width] x [0, height] with raster y pointing down:
///   rx = (sx - xmin) / (xmax - xmin) * width,  ry = (ymax - sy) / (ymax - ymin) * height.
/// Pixel (i, j) covers [i, i+1) x [j, j+1); its centre is (i + 0.5, j + 0.5).
struct DSM_API LightCamera {
    Projection projection = Projection::Perspective;
    /// Row-major 4x4 matrix M with light = M * (world, 1).
    std::array<double, 16> worldToLight{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    /// xmin, xmax, ymin, ymax. For a perspective light, tan of the half angles
    /// (the window at unit depth); for an orthographic light, light-space units.
    std::array<double, 4> screenWindow{-1.0, 1.0, -1.0, 1.0};
    /// Depth of the near plane: nothing nearer was sampled.
    double nearPlane = 0.0;

    /// World point to light space. Inline: the sampler's bucketing projects
    /// ten points a primitive.
    std::array<double, 3> worldToLightSpace(const std::array<double, 3>& world) const {
        const auto& m = worldToLight;
        return {m[0] * world[0] + m[1] * world[1] + m[2] * world[2] + m[3],
                m[4] * world[0] + m[5] * world[1] + m[6] * world[2] + m[7],
                m[8] * world[0] + m[9] * world[1] + m[10] * world[2] + m[11]};
    }
    /// Light-space point to raster (rx, ry) and depth z. For a perspective
    /// camera, points at z <= 0 have no raster position: returns false.
    bool lightToRaster(const std::array<double, 3>& light, int width, int height, double& rx, double& ry,
                       double& z) const;
    /// Throws dsm::Error when a field is not finite or the window is empty.
    void validate() const;

    friend bool operator==(const LightCamera& a, const LightCamera& b) {
        return a.projection == b.projection && a.worldToLight == b.worldToLight &&
               a.screenWindow == b.screenWindow && a.nearPlane == b.nearPlane;
    }
    friend bool operator!=(const LightCamera& a, const LightCamera& b) { return !(a == b); }
};

/// One mip level (Lokovic & Veach §5.3).
struct LevelInfo {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    std::uint32_t tilesX = 0;
    std::uint32_t tilesY = 0;
    /// The compression tolerance epsilon used for this level's functions.
    double tolerance = 0.0;
    /// Bound on |V - V_exact| for this level's functions against the exact
    /// average of the full-resolution functions it summarises: the sum over
    /// this level and every finer one of max(tolerance, 2^-25), the compressor's
    /// bound including float32 rounding (see compressor.h).
    double errorBound = 0.0;
    std::uint64_t vertexCount = 0;
    std::uint64_t nonEmptyPixels = 0;
    /// Bytes the level's tiles take in the file.
    std::uint64_t storedBytes = 0;
    /// Values of this level are stored as multiples of this step (a power of
    /// two, see dsm/value_step.h); 0: stored exactly as float32. The step is
    /// part of the tolerance: the stated bound holds for the stored values.
    double valueStep = 0.0;
};

/// The general-purpose compressor a file's tiles went through (spec
/// dsm-format.md §3): zlib streams, RFC 1950.
/// How compressed tiles are compressed (spec/dsm-format.md §3, codec): zlib
/// (RFC 1950), or zstd frames (RFC 8878), larger by 3-6 % but several times
/// faster to decompress.
enum class TileCodec : std::uint8_t { Zlib = 0, Zstd = 1 };

/// Everything a map's header and level table hold.
struct MapInfo {
    std::uint16_t versionMajor = 0;
    std::uint16_t versionMinor = 0;
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    std::uint32_t tileSize = 0;
    /// 1 (monochrome) or 3 (RGB); an RGB map may still store monochrome pixels.
    int channels = 1;
    /// Vertices carry sample counts (for MTSM ray tracing).
    bool hasCounts = false;
    /// Most layers any pixel may have (1 = ordinary deep shadow map).
    int maxLayers = 1;
    LightCamera camera;
    PixelFilter filter = PixelFilter::Box;
    /// Filter width in pixels used when the map was built.
    double filterWidth = 1.0;
    std::vector<LevelInfo> levels;
    /// Tiles use the 1.1 coding (depth deltas, quantised values, variable
    /// length integers); false for the 1.0 layout of raw arrays.
    bool codedTiles = false;
    /// Coded tiles predict each pixel's first and last depth from the
    /// previous pixel's (PREDICTED_DEPTHS, every coded map written today);
    /// false for maps of the first 1.1 coding (depth steps within each pixel).
    bool predictedDepths = false;
    /// The tiles' compressor and the level the writer gave it (0 = tiles
    /// stored uncompressed); codecLevel is -1 when the file does not record
    /// it (format 1.0). A writer given the same level reproduces the tiles.
    TileCodec codec = TileCodec::Zlib;
    int codecLevel = -1;
    /// The area light the map was built for: a disk of this radius (light
    /// space units) centred on the light axis in the plane z =
    /// areaLightPlaneDepth, behind which the projection centre was pushed.
    /// Radius 0: a point light (or a file that does not record it, 1.0).
    double areaLightRadius = 0.0;
    double areaLightPlaneDepth = 0.0;
    /// JSON text: build settings, scene, software.
    std::string metadata = "{}";
    std::uint64_t fileBytes = 0;
};

/// Size of mip level `level` of a width x height map: each level halves the
/// previous one, rounding up, down to 1.
DSM_API std::uint32_t levelExtent(std::uint32_t fullExtent, unsigned level);
/// Number of levels of a full pyramid down to 1 x 1.
DSM_API unsigned fullLevelCount(std::uint32_t width, std::uint32_t height);

DSM_NAMESPACE_END
