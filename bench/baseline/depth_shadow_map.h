// A conventional depth shadow map with percentage-closer filtering: the
// baseline deep shadow maps are measured against (Lokovic & Veach 2000, §6,
// Fig. 7; Williams 1978; Reeves, Salesin & Cook 1987).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/scene.h"

namespace dsm {

struct DepthMapOptions {
    /// Depth map size, each >= 1; unset keeps the scene light's resolution. To compare with a
    /// deep shadow map of R x R pixels and N samples per pixel "with the same
    /// number of depth samples", use R * sqrt(N) on each side.
    std::optional<std::uint32_t> width;
    std::optional<std::uint32_t> height;
    /// Jitter each sample inside its pixel (otherwise pixel centres).
    bool jitter = true;
    std::uint64_t seed = 1;
    /// Worker threads; 0 = all cores, and more than the cores are clamped to
    /// them (usableThreads(), dsm/threads.h). The map does not depend on it.
    unsigned threads = 0;
};

/// One depth per pixel: the nearest surface its sample ray meets, whatever
/// that surface's opacity. A depth map cannot store partial coverage, so a
/// semi-transparent surface shadows like an opaque one, and volumes cast no
/// shadow at all: that is the baseline's honest limitation, not a defect of
/// this implementation.
///
/// The sample rays are the deep map's: the same light camera (lightCamera()),
/// the same parametrisation by light depth, one stratified shutter time per
/// pixel.
///
/// Thread safety: render() may run on several threads at once (each call
/// parallelises internally); a finished map is immutable and its const members
/// may be called from any number of threads.
class DepthShadowMap {
public:
    /// Renders the scene's surfaces from its light. Throws dsm::Error for an
    /// empty size.
    static DepthShadowMap render(const Scene& scene, const DepthMapOptions& options = {});

    std::uint32_t width() const { return width_; }
    std::uint32_t height() const { return height_; }
    const LightCamera& camera() const { return camera_; }
    /// Depth of pixel (x, y); +infinity where the ray met nothing.
    float depth(std::uint32_t x, std::uint32_t y) const { return depth_[std::size_t(y) * width_ + x]; }
    /// Bytes of the depths as float32: what the map costs in memory.
    std::uint64_t bytes() const { return std::uint64_t(depth_.size()) * sizeof(float); }

    /// Percentage-closer filtering: the box-filtered fraction of depth samples
    /// in the footprint that lie beyond z - bias (lit). (rx, ry) is in this
    /// map's raster; `filterWidth` is the box's side in this map's pixels
    /// (at least 1: a single pixel). Pixels under the footprint's edge count
    /// with the fraction of their area inside it; pixels outside the image are
    /// left out. Outside the image altogether: lit (1).
    double lookupRaster(double rx, double ry, double z, double filterWidth, double bias = 0.0) const;
    /// PCF with a fixed number of samples, as renderers filter wide footprints
    /// (Lokovic & Veach §6 use 8 x 8): the footprint is divided into a
    /// grid x grid array of cells and one jittered point per cell reads the
    /// depth pixel under it. Cost is grid^2 whatever the width; the answer is a
    /// noisy estimate of lookupRaster(). Deterministic for a seed.
    double lookupRasterSampled(double rx, double ry, double z, double filterWidth, unsigned grid,
                               std::uint64_t seed, double bias = 0.0) const;
    /// The same at a world-space point.
    double lookupWorld(const Vec3& point, double filterWidth, double bias = 0.0) const;

    /// Writes the depths as a one-channel float OpenEXR image (ZIP), the usual
    /// way depth maps are stored; returns the file's size in bytes. Atomic: a
    /// temporary file renamed into place. Throws dsm::Error naming the file.
    std::uint64_t writeExr(const std::string& path) const;

private:
    std::uint32_t width_ = 0, height_ = 0;
    LightCamera camera_;
    std::vector<float> depth_;
};

}  // namespace dsm
