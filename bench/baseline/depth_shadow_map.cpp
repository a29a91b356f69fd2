#include "depth_shadow_map.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>

#include <OpenImageIO/imageio.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "dsm/error.h"
#include "dsm/output_file.h"
#include "dsm/threads.h"
#include "light_rays.h"
#include "ray_caster.h"
#include "text.h"

namespace dsm {

using detail::concat;

DepthShadowMap DepthShadowMap::render(const Scene& scene, const DepthMapOptions& options) {
    DepthShadowMap map;
    map.width_ = options.width.value_or(scene.light.width);
    map.height_ = options.height.value_or(scene.light.height);
    if (map.width_ == 0 || map.height_ == 0 || map.width_ > (1u << 17) || map.height_ > (1u << 17))
        throw Error(ErrorCode::argument,
                    concat("depth shadow map: size ", map.width_, "x", map.height_, " is empty or too large"));
    LightDescription light = scene.light;
    light.width = map.width_;
    light.height = map.height_;
    map.camera_ = lightCamera(light);
    map.depth_.assign(std::size_t(map.width_) * map.height_, std::numeric_limits<float>::infinity());

    const detail::LightRayFrame frame = detail::lightRayFrame(map.camera_, map.width_, map.height_);
    const RayCaster caster(scene);
    tbb::task_arena arena(static_cast<int>(usableThreads(options.threads)));
    arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, map.height_), [&](const auto& rows) {
            RaySurfaceHits hits;
            for (std::uint32_t y = rows.begin(); y != rows.end(); ++y)
                for (std::uint32_t x = 0; x < map.width_; ++x) {
                    detail::SplitMix64 rng(detail::pixelSeed(options.seed, x, y));
                    const double jx = options.jitter ? rng.uniform() : 0.5, jy = options.jitter ? rng.uniform() : 0.5;
                    const double time = rng.uniform();
                    Vec3 o, d;
                    frame.ray(x + jx, y + jy, o, d);
                    hits.clear();
                    caster.surfaceHits(o, d, time, map.camera_.nearPlane, hits);
                    double nearest = std::numeric_limits<double>::infinity();
                    for (const RaySurfaceHit& h : hits) nearest = std::min(nearest, h.t);
                    map.depth_[std::size_t(y) * map.width_ + x] = static_cast<float>(nearest);
                }
        });
    });
    return map;
}

double DepthShadowMap::lookupRaster(double rx, double ry, double z, double filterWidth, double bias) const {
    if (!std::isfinite(rx) || !std::isfinite(ry) || !std::isfinite(z)) return 1.0;
    const double half = 0.5 * std::max(1.0, filterWidth);
    const double x0 = rx - half, x1 = rx + half, y0 = ry - half, y1 = ry + half;
    const long ix0 = std::max(0L, static_cast<long>(std::floor(x0)));
    const long ix1 = std::min(static_cast<long>(width_) - 1, static_cast<long>(std::floor(x1)));
    const long iy0 = std::max(0L, static_cast<long>(std::floor(y0)));
    const long iy1 = std::min(static_cast<long>(height_) - 1, static_cast<long>(std::floor(y1)));
    if (ix0 > ix1 || iy0 > iy1) return 1.0;
    const double threshold = z - bias;
    double lit = 0.0, total = 0.0;
    for (long y = iy0; y <= iy1; ++y) {
        const double wy = std::min<double>(y + 1, y1) - std::max<double>(y, y0);
        if (wy <= 0.0) continue;
        const float* row = &depth_[std::size_t(y) * width_];
        for (long x = ix0; x <= ix1; ++x) {
            const double wx = std::min<double>(x + 1, x1) - std::max<double>(x, x0);
            if (wx <= 0.0) continue;
            const double w = wx * wy;
            total += w;
            if (row[x] > threshold) lit += w;
        }
    }
    return total > 0.0 ? lit / total : 1.0;
}

double DepthShadowMap::lookupRasterSampled(double rx, double ry, double z, double filterWidth, unsigned grid,
                                           std::uint64_t seed, double bias) const {
    if (!std::isfinite(rx) || !std::isfinite(ry) || !std::isfinite(z) || grid == 0) return 1.0;
    const double width = std::max(1.0, filterWidth), cell = width / grid;
    const double x0 = rx - 0.5 * width, y0 = ry - 0.5 * width;
    const double threshold = z - bias;
    detail::SplitMix64 rng(seed);
    unsigned lit = 0, inside = 0;
    for (unsigned j = 0; j < grid; ++j)
        for (unsigned i = 0; i < grid; ++i) {
            const double x = x0 + (i + rng.uniform()) * cell, y = y0 + (j + rng.uniform()) * cell;
            if (x < 0.0 || y < 0.0 || x >= width_ || y >= height_) continue;
            ++inside;
            if (depth_[std::size_t(y) * width_ + std::size_t(x)] > threshold) ++lit;
        }
    return inside ? double(lit) / inside : 1.0;
}

double DepthShadowMap::lookupWorld(const Vec3& point, double filterWidth, double bias) const {
    double rx = 0.0, ry = 0.0, z = 0.0;
    if (!camera_.lightToRaster(camera_.worldToLightSpace(point), static_cast<int>(width_), static_cast<int>(height_),
                               rx, ry, z))
        return 1.0;
    return lookupRaster(rx, ry, z, filterWidth, bias);
}

std::uint64_t DepthShadowMap::writeExr(const std::string& path) const {
    auto out = OIIO::ImageOutput::create(path);
    if (!out) throw Error(ErrorCode::argument, concat("'", path, "': cannot write: ", OIIO::geterror()));
    OIIO::ImageSpec spec(static_cast<int>(width_), static_cast<int>(height_), 1, OIIO::TypeDesc::FLOAT);
    spec.channelnames = {"Z"};
    spec.attribute("compression", "zip");
    spec.attribute("oiio:ColorSpace", "Linear");
    OutputFile output(path, std::filesystem::path(path).extension().string());
    if (!out->open(output.temporaryPath(), spec) || !out->write_image(OIIO::TypeDesc::FLOAT, depth_.data()) ||
        !out->close())
        throw Error(ErrorCode::io, concat("'", path, "': cannot write: ", out->geterror()));
    // OpenEXR reports failed writes, but a file that does not read back must not replace `path`.
    const auto written = OIIO::ImageInput::open(output.temporaryPath());
    std::vector<float> check(depth_.size());
    if (!written || !written->read_image(0, 0, 0, 1, OIIO::TypeDesc::FLOAT, check.data()))
        throw Error(ErrorCode::io, concat("'", path, "': the written file does not read back"));
    output.commit();
    return std::filesystem::file_size(path);
}

}  // namespace dsm
