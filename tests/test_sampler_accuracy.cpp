// Accuracy of the reference sampler (dsm::buildMap): small scenes built in
// code, rendered into maps and read back, compared with analytic truth. Every
// comparison has a bound derived from the sampler's documented error sources:
//  - compression: |V_stored - V_average| <= the level-0 tolerance epsilon
//    (compressor.h), plus float32 storage of depths and values;
//  - volumes: the optical depth is a trapezoid sum of extinction samples taken
//    every `step` of path length (exact for a homogeneous medium), and the
//    transmittance is interpolated linearly between samples; linear
//    interpolation of f(s) = exp(-k s) between samples h apart is off by at
//    most h^2 max|f''| / 8 = h^2 k^2 / 8 * exp(-k s_left);
//  - pixel sampling: a pixel's function is the filter-weighted average of its
//    stratified, jittered sample rays; coverage estimates are within
//    0.5 / sqrt(N) for N samples (the standard deviation of plain Monte Carlo
//    at coverage 1/2; stratified sampling does much better on edges);
//  - perspective: rays through one pixel differ slightly in direction, so
//    their path lengths per unit depth differ; the spread is bounded from the
//    pixel's corners.
// Most scenes use an orthographic light with one world unit per pixel, so
// that geometry in world units is geometry in pixels.
#include <gtest/gtest.h>

#include <dsm/dsm.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "map_fixtures.h"

#include "temp_dir.h"

namespace {

using dsm::Vec3;
using dsm::test::TempDir;
using dsm::test::expectSamePixels;

constexpr double kPi = 3.14159265358979323846;
// float32 storage of values (relative 2^-24, a few roundings) and of depths
// (relative 2^-24 of depths < 10, times slopes <= a few): far below 1e-5.
constexpr double kStorageSlack = 1e-5;
// Depth of the world plane z = 0 from the orthographic test light.
constexpr double kLightZ = 10.0;

// The orthographic test light: at world (0, 0, 10) looking down world -z with
// up +y, window half-size size/2 on a size x size map. Then light x = world x,
// light y = world y, depth = 10 - world z, and raster (rx, ry) = (x + size/2,
// size/2 - y): pixel (i, j) covers world x in [i - size/2, i + 1 - size/2] and
// y in [size/2 - j - 1, size/2 - j] (checked by OrthographicTestLightMapsAsAssumed).
dsm::LightDescription orthoLight(std::uint32_t size) {
    dsm::LightDescription l;
    l.projection = dsm::Projection::Orthographic;
    l.position = {0.0, 0.0, kLightZ};
    l.direction = {0.0, 0.0, -1.0};
    l.up = {0.0, 1.0, 0.0};
    l.extent = 0.5 * size;
    l.width = l.height = size;
    return l;
}

dsm::Scene sceneWith(const dsm::LightDescription& light, std::vector<dsm::SceneObject> objects) {
    dsm::Scene s;
    s.light = light;
    s.objects = std::move(objects);
    s.path = "test_sampler_accuracy";
    return s;
}

// A rectangle facing the orthographic light at `depth`: centre (cx, cy), half
// sizes (hx, hy) in world x and y.
dsm::SceneObject card(double depth, double cx, double cy, double hx, double hy, dsm::Rgb opacity) {
    dsm::SceneObject o;
    o.name = "card";
    o.geometry = dsm::Quad{{cx, cy, kLightZ - depth}, {hx, 0.0, 0.0}, {0.0, hy, 0.0}};
    o.opacity = opacity;
    return o;
}
// One that covers the whole view of any test map.
dsm::SceneObject wall(double depth, dsm::Rgb opacity) { return card(depth, 0.0, 0.0, 1000.0, 1000.0, opacity); }

// An opaque half-plane facing the orthographic light at `depth`: it covers the
// points p (world x, y) with (p - p0) . n <= 0, n = (cos angle, sin angle).
dsm::SceneObject halfPlane(double depth, double p0x, double p0y, double angle) {
    const double L = 1000.0, nx = std::cos(angle), ny = std::sin(angle);
    dsm::SceneObject o;
    o.name = "edge";
    o.geometry =
        dsm::Quad{{p0x - L * nx, p0y - L * ny, kLightZ - depth}, {L * nx, L * ny, 0.0}, {-L * ny, L * nx, 0.0}};
    return o;
}

// A homogeneous slab of extinction k between depths z0 and z1 (for the
// orthographic light, or for a spot light at the origin looking down +z when
// `depthIsWorldZ`), much wider than any view.
dsm::SceneObject slab(double z0, double z1, double k, double step, bool depthIsWorldZ = false) {
    dsm::Volume v;
    if (depthIsWorldZ) {
        v.boundsMin = {-100.0, -100.0, z0};
        v.boundsMax = {100.0, 100.0, z1};
    } else {
        v.boundsMin = {-100.0, -100.0, kLightZ - z1};
        v.boundsMax = {100.0, 100.0, kLightZ - z0};
    }
    v.density = dsm::HomogeneousDensity{k};
    v.scale = 1.0;
    v.step = step;
    dsm::SceneObject o;
    o.name = "slab";
    o.geometry = v;
    return o;
}

// Options for accuracy tests: a box filter of width 1 (each pixel averages
// exactly its own samples), no mip-maps, small tiles, two threads.
dsm::BuildOptions boxOptions(std::uint32_t spp, double tolerance) {
    dsm::BuildOptions o;
    o.samplesPerPixel = spp;
    o.tolerance = tolerance;
    o.filter = dsm::PixelFilter::Box;
    o.filterWidth = 1.0;
    o.mipLevels = 1;
    o.tileSize = 16;
    o.threads = 2;
    return o;
}

// Builds with the scanline sampler (the default) and, beside it, with the
// ray-casting one: every level-0 pixel of the two maps must be the same
// function, so each accuracy bound below holds for both samplers.
std::shared_ptr<dsm::DeepShadowMap> build(const dsm::Scene& scene, const dsm::BuildOptions& options,
                                          const std::string& path) {
    dsm::BuildOptions scanline = options, raytrace = options;
    scanline.sampler = dsm::SamplerMethod::scanline;
    raytrace.sampler = dsm::SamplerMethod::raytrace;
    dsm::buildMap(scene, scanline, path);
    dsm::validate(path);
    const std::string rayPath = path + ".raytrace.dsm";
    dsm::buildMap(scene, raytrace, rayPath);
    auto map = dsm::DeepShadowMap::open(path);
    expectSamePixels(*map, *dsm::DeepShadowMap::open(rayPath));
    std::remove(rayPath.c_str());
    return map;
}

std::string readBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Area of the unit pixel square [x0, x0+1] x [y0, y0+1] on the side
// (p - p0) . n <= 0 of a line (Sutherland-Hodgman clipping, shoelace area).
double coveredArea(double x0, double y0, double p0x, double p0y, double nx, double ny) {
    const std::vector<std::array<double, 2>> square{{x0, y0}, {x0 + 1, y0}, {x0 + 1, y0 + 1}, {x0, y0 + 1}};
    auto side = [&](const std::array<double, 2>& p) { return (p[0] - p0x) * nx + (p[1] - p0y) * ny; };
    std::vector<std::array<double, 2>> clipped;
    for (std::size_t i = 0; i < square.size(); ++i) {
        const auto& a = square[i];
        const auto& b = square[(i + 1) % square.size()];
        const double sa = side(a), sb = side(b);
        if (sa <= 0.0) clipped.push_back(a);
        if ((sa < 0.0 && sb > 0.0) || (sa > 0.0 && sb < 0.0)) {
            const double t = sa / (sa - sb);
            clipped.push_back({a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])});
        }
    }
    double area = 0.0;
    for (std::size_t i = 0; i < clipped.size(); ++i) {
        const auto& a = clipped[i];
        const auto& b = clipped[(i + 1) % clipped.size()];
        area += a[0] * b[1] - b[0] * a[1];
    }
    return std::abs(0.5 * area);
}

// World x, y of the lower left corner of pixel (i, j) of a size x size map of the orthographic light.
double pixelX0(std::uint32_t i, std::uint32_t size) { return double(i) - 0.5 * size; }
double pixelY0(std::uint32_t j, std::uint32_t size) { return 0.5 * size - double(j) - 1.0; }

TEST(SamplerAccuracy, OrthographicTestLightMapsAsAssumed) {
    const std::uint32_t size = 16;
    const dsm::LightCamera camera = dsm::lightCamera(orthoLight(size));
    for (const Vec3& p : {Vec3{0.0, 0.0, 0.0}, Vec3{-7.25, 3.5, 2.0}, Vec3{5.0, -6.75, -4.0}}) {
        double rx = 0, ry = 0, z = 0;
        ASSERT_TRUE(camera.lightToRaster(camera.worldToLightSpace(p), size, size, rx, ry, z));
        EXPECT_NEAR(rx, p[0] + 0.5 * size, 1e-12);
        EXPECT_NEAR(ry, 0.5 * size - p[1], 1e-12);
        EXPECT_NEAR(z, kLightZ - p[2], 1e-12);
    }
}

// A semi-transparent card covering the whole view: V = 1 before its depth and
// 1 - a at and after it, in every pixel. Every ray is the same step, so the
// pixel average is exact and only compression (epsilon) and float storage
// separate the map from the truth.
TEST(SamplerAccuracy, SemiTransparentCardIsAStep) {
    TempDir dir;
    const double a = 0.375, d = 2.5;  // both exact in binary: the hit depth is computed exactly
    const dsm::Scene scene = sceneWith(orthoLight(8), {wall(d, {float(a), float(a), float(a)})});
    const dsm::BuildOptions options = boxOptions(4, 0.01);
    const auto map = build(scene, options, (dir / "card.dsm").string());
    ASSERT_EQ(map->info().channels, 1);
    const double bound = map->info().levels.at(0).tolerance + kStorageSlack;
    EXPECT_DOUBLE_EQ(map->info().levels[0].tolerance, 0.01);
    const std::vector<double> before{0.0, 0.5, 1.0, 2.0, 2.49, 2.4999};
    const std::vector<double> after{2.5, 2.5001, 2.6, 3.0, 7.0, 100.0};
    double worst = 0.0;
    for (std::uint32_t y = 0; y < 8; ++y)
        for (std::uint32_t x = 0; x < 8; ++x) {
            const auto f = map->pixel(0, x, y);
            ASSERT_FALSE(f->empty()) << x << "," << y;
            for (double z : before) {
                worst = std::max(worst, std::abs(f->evaluate(z) - 1.0));
                EXPECT_NEAR(f->evaluate(z), 1.0, bound) << "pixel " << x << "," << y << " z " << z;
            }
            for (double z : after) {
                worst = std::max(worst, std::abs(f->evaluate(z) - (1.0 - a)));
                EXPECT_NEAR(f->evaluate(z), 1.0 - a, bound) << "pixel " << x << "," << y << " z " << z;
            }
        }
    // The same through filtered lookups at world points (light depth 10 - world z).
    dsm::LookupContext lookup(map);
    dsm::LookupOptions atTheDepth;
    atTheDepth.bias = 0.0;  // the card is checked right behind itself
    for (const auto& [x, y] : {std::pair{0.1, 0.2}, std::pair{-3.3, 2.9}, std::pair{3.7, -3.9}}) {
        for (double z : before) {
            const dsm::LookupResult r = lookup.world({x, y, kLightZ - z}, atTheDepth);
            EXPECT_NEAR(r.v[0], 1.0, bound) << x << "," << y << " z " << z;
            EXPECT_LE(r.errorBound, 0.01 + 1e-12);
        }
        for (double z : after)
            EXPECT_NEAR(lookup.world({x, y, kLightZ - z}, atTheDepth).v[0], 1.0 - a, bound) << x << "," << y;
    }
    std::printf("[ measured ] card: max |V - truth| = %.3g (bound %.3g)\n", worst, bound);
}

// Largest |V - exp(-k (z - z0) pathPerDepth)| of a pixel over a fine depth grid
// across the slab and beyond, and the same at the depths of the volume samples only.
struct SlabError {
    double anywhere = 0.0;
    double atSamples = 0.0;
};
SlabError slabError(const dsm::VisibilityView& f, double z0, double z1, double k, double h, double pathPerDepth) {
    auto truth = [&](double z) {
        if (z <= z0) return 1.0;
        return std::exp(-k * (std::min(z, z1) - z0) * pathPerDepth);
    };
    SlabError e;
    for (double z = 0.0; z <= z1 + 1.0; z += h / 64.0)
        e.anywhere = std::max(e.anywhere, std::abs(f.evaluate(z) - truth(z)));
    const double dz = h / pathPerDepth;  // sample spacing in depth
    for (double z = z0; z < z1; z += dz) e.atSamples = std::max(e.atSamples, std::abs(f.evaluate(z) - truth(z)));
    e.atSamples = std::max(e.atSamples, std::abs(f.evaluate(z1) - truth(z1)));
    return e;
}

// A homogeneous slab seen from an orthographic light: V(z) = exp(-k (z - z0))
// inside, within epsilon plus the linear-interpolation error h^2 k^2 / 8 of
// the transmittance between volume samples h apart (the trapezoid optical depth
// of a constant extinction is exact, so at the samples only epsilon remains).
// The second variant places the slab by a rotation about the light axis and a
// translation (the same slab in world space): the entry and exit samples, on
// the box's faces, must still see the medium.
TEST(SamplerAccuracy, HomogeneousSlabOrthographic) {
    TempDir dir;
    const double z0 = 1.3, z1 = 2.2, k = 2.0, h = 0.1;
    const double tolerance = 1e-4;
    const double interpolation = h * h * k * k / 8.0;  // 0.005
    for (int variant = 0; variant < 2; ++variant) {
        dsm::SceneObject object = slab(z0, z1, k, h);
        if (variant == 1) {
            // Object space: the slab centred on the origin, turned by -37 degrees;
            // the transform turns it back by 37 degrees and moves it into place.
            auto& v = std::get<dsm::Volume>(object.geometry);
            const double mid = kLightZ - 0.5 * (z0 + z1), half = 0.5 * (z1 - z0);
            v.boundsMin = {-100.0, -100.0, -half};
            v.boundsMax = {100.0, 100.0, half};
            const double c = std::cos(37.0 * kPi / 180.0), s = std::sin(37.0 * kPi / 180.0);
            object.objectToWorld = {c, -s, 0, 0.1, s, c, 0, -0.2, 0, 0, 1, mid, 0, 0, 0, 1};
        }
        const dsm::Scene scene = sceneWith(orthoLight(4), {object});
        const auto map =
            build(scene, boxOptions(4, tolerance), (dir / ("slab" + std::to_string(variant) + ".dsm")).string());
        const double eps = map->info().levels.at(0).tolerance;
        SlabError worst;
        for (std::uint32_t y = 0; y < 4; ++y)
            for (std::uint32_t x = 0; x < 4; ++x) {
                const auto f = map->pixel(0, x, y);
                const SlabError e = slabError(f.view(), z0, z1, k, h, 1.0);
                EXPECT_LE(e.anywhere, eps + interpolation + kStorageSlack)
                    << "variant " << variant << " pixel " << x << "," << y;
                EXPECT_LE(e.atSamples, eps + kStorageSlack) << "variant " << variant << " pixel " << x << "," << y;
                worst.anywhere = std::max(worst.anywhere, e.anywhere);
                worst.atSamples = std::max(worst.atSamples, e.atSamples);
            }
        std::printf(
            "[ measured ] slab (orthographic, variant %d): max error %.3g (bound %.3g = eps %.3g + h^2k^2/8 %.3g); "
            "at the samples %.3g (bound %.3g)\n",
            variant, worst.anywhere, eps + interpolation + kStorageSlack, eps, interpolation, worst.atSamples,
            eps + kStorageSlack);
    }
}

// The same slab under a spot light, off axis (Lokovic & Veach, footnote 3):
// extinction is per unit path length and depth is light-space z, so along the
// ray through the pixel centre, direction d = (sx, sy, 1) in light space,
// V(z) = exp(-k (z - z0) |d| / d_z). Rays elsewhere in the pixel have other
// |d|; their average lies between exp(-k (z - z0) |d|max) and
// exp(-k (z - z0) |d|min), |d| taken over the pixel's corners (|d| is monotone
// in |sx| and |sy| and the pixels do not straddle the axes). The volume step is
// h along the path for every ray, so the interpolation error is h^2 k^2 / 8 as
// before. The pixels are near a corner of a 90 degree field (|d| ~ 1.6), where
// leaving out the correction would be off by ~0.15.
TEST(SamplerAccuracy, HomogeneousSlabPerspectiveCorrection) {
    TempDir dir;
    const double z0 = 1.0, z1 = 2.0, k = 1.0, h = 0.05;
    const std::uint32_t size = 128;
    dsm::LightDescription light;
    light.projection = dsm::Projection::Perspective;
    light.position = {0.0, 0.0, 0.0};
    light.direction = {0.0, 0.0, 1.0};
    light.up = {0.0, 1.0, 0.0};
    light.fieldOfViewDegrees = 90.0;
    light.width = light.height = size;
    const dsm::Scene scene = sceneWith(light, {slab(z0, z1, k, h, true)});
    dsm::BuildOptions options = boxOptions(16, 1e-4);
    const std::array<std::uint32_t, 4> region{8, 100, 12, 104};  // lower left, far off axis
    options.region = region;
    const auto map = build(scene, options, (dir / "spot.dsm").string());
    const double eps = map->info().levels.at(0).tolerance;
    const auto& w = map->info().camera.screenWindow;
    auto sx = [&](double rx) { return w[0] + rx / size * (w[1] - w[0]); };
    auto sy = [&](double ry) { return w[3] - ry / size * (w[3] - w[2]); };
    auto length = [](double x, double y) { return std::sqrt(1.0 + x * x + y * y); };
    const double interpolation = h * h * k * k / 8.0;
    double worstError = 0.0, worstBound = 0.0, worstUncorrected = 1.0;
    for (std::uint32_t y = region[1]; y < region[3]; ++y)
        for (std::uint32_t x = region[0]; x < region[2]; ++x) {
            ASSERT_TRUE(sx(x) * sx(x + 1) > 0.0 && sy(y) * sy(y + 1) > 0.0) << "pixel straddles an axis";
            const double centre = length(sx(x + 0.5), sy(y + 0.5));
            double lo = 1e300, hi = 0.0;
            for (double cx : {sx(x), sx(x + 1)})
                for (double cy : {sy(y), sy(y + 1)}) {
                    lo = std::min(lo, length(cx, cy));
                    hi = std::max(hi, length(cx, cy));
                }
            const auto f = map->pixel(0, x, y);
            ASSERT_FALSE(f->empty());
            double uncorrected = 0.0;  // how far the map is from the uncorrected exp(-k (z - z0))
            for (double z = 0.0; z <= z1 + 0.5; z += h / 16.0) {
                const double dz = std::clamp(z - z0, 0.0, z1 - z0);
                const double truth = std::exp(-k * dz * centre);
                const double spread = std::exp(-k * dz * lo) - std::exp(-k * dz * hi);
                const double bound = eps + interpolation + spread + kStorageSlack;
                const double error = std::abs(f->evaluate(z) - truth);
                EXPECT_LE(error, bound) << "pixel " << x << "," << y << " z " << z << " |d| " << centre;
                worstError = std::max(worstError, error);
                worstBound = std::max(worstBound, bound);
                uncorrected = std::max(uncorrected, std::abs(f->evaluate(z) - std::exp(-k * dz)));
            }
            worstUncorrected = std::min(worstUncorrected, uncorrected);
            EXPECT_GT(uncorrected, 0.1) << "the map looks uncorrected at pixel " << x << "," << y;
        }
    // Pixels outside the region were not built.
    EXPECT_TRUE(map->pixel(0, 0, 0)->empty());
    EXPECT_TRUE(map->pixel(0, 64, 64)->empty());
    std::printf(
        "[ measured ] slab (spot, off axis): max error %.3g (largest bound %.3g = eps %.3g + h^2k^2/8 %.3g + "
        "spread); an uncorrected exp(-k dz) would be off by >= %.3g\n",
        worstError, worstBound, eps, interpolation, worstUncorrected);
}

// An opaque half-plane whose edge crosses the map at an angle: behind it each
// pixel's V is 1 - (the area of the pixel it covers), computed exactly by
// clipping. With a box filter of width 1 each pixel averages its own N samples,
// one jittered in each cell of a gx x gy grid (gx gy = N for these N). Cells
// the edge misses are estimated exactly; each of the at most gx + gy - 1 cells
// it crosses adds an error below 1/N. So per pixel, without exception,
//   |V - (1 - coverage)| < (gx + gy - 1) / N + eps.
// Over the partly covered pixels, the root mean square error is asserted
// within 0.5 / sqrt(N), the standard deviation of plain Monte Carlo sampling
// at coverage 1/2 (stratification gives about 0.6 N^-3/4 on an edge). The
// measured errors are printed.
TEST(SamplerAccuracy, EdgeCoverage) {
    TempDir dir;
    const std::uint32_t size = 16;
    const double d = 3.0, p0x = 0.37, p0y = -0.21, angle = 0.35;  // about 20 degrees
    const double nx = std::cos(angle), ny = std::sin(angle);
    for (std::uint32_t spp : {4u, 8u, 16u, 64u, 256u}) {
        const std::uint32_t gy = static_cast<std::uint32_t>(std::floor(std::sqrt(double(spp))));
        const std::uint32_t gx = spp / gy;
        ASSERT_EQ(gx * gy, spp);
        const dsm::Scene scene = sceneWith(orthoLight(size), {halfPlane(d, p0x, p0y, angle)});
        const auto map = build(scene, boxOptions(spp, 1e-3), (dir / ("edge" + std::to_string(spp) + ".dsm")).string());
        const double eps = map->info().levels.at(0).tolerance;
        const double pixelBound = double(gx + gy - 1) / spp + eps + kStorageSlack;
        const double rmsBound = 0.5 / std::sqrt(double(spp)) + eps + kStorageSlack;
        double worst = 0.0, sumSquares = 0.0;
        int partial = 0;
        for (std::uint32_t y = 0; y < size; ++y)
            for (std::uint32_t x = 0; x < size; ++x) {
                const double coverage = coveredArea(pixelX0(x, size), pixelY0(y, size), p0x, p0y, nx, ny);
                const auto f = map->pixel(0, x, y);
                EXPECT_NEAR(f->evaluate(d - 0.01), 1.0, eps + kStorageSlack) << x << "," << y;
                const double error = std::abs(f->evaluate(d) - (1.0 - coverage));
                EXPECT_LT(error, pixelBound) << "spp " << spp << " pixel " << x << "," << y << " coverage " << coverage;
                if (coverage == 0.0 || coverage == 1.0) {
                    EXPECT_LE(error, eps + kStorageSlack) << "spp " << spp << " pixel " << x << "," << y;
                } else {
                    ++partial;
                    worst = std::max(worst, error);
                    sumSquares += error * error;
                }
            }
        ASSERT_GT(partial, 10);
        const double rms = std::sqrt(sumSquares / partial);
        EXPECT_LE(rms, rmsBound) << "spp " << spp;
        std::printf(
            "[ measured ] edge, spp %3u: %d partly covered pixels, max error %.3g (bound (gx+gy-1)/N + eps "
            "= %.3g; 0.5/sqrt(N) = %.3g), rms %.3g (bound 0.5/sqrt(N) + eps = %.3g)\n",
            spp, partial, worst, pixelBound, 0.5 / std::sqrt(double(spp)), rms, rmsBound);
    }
}

// Sampling must be unbiased for every sample count, also when N is not a
// product of two near-square factors: an occluder that covers the same small
// part of every pixel (here a 0.3 x 0.45 rectangle in the bottom right corner
// of each pixel, area 0.135) must be seen on average at its area. With N = 5,
// say, a 3 x 2 grid whose last cell is never sampled would miss it entirely.
// The mean over 256 pixels of independent errors each within 0.5 / sqrt(N) is
// within 4 standard deviations, 2 / sqrt(256 N).
TEST(SamplerAccuracy, EveryPartOfThePixelIsSampled) {
    TempDir dir;
    const std::uint32_t size = 16;
    const double d = 2.0, w = 0.3, hgt = 0.45;
    std::vector<dsm::SceneObject> cards;
    for (std::uint32_t j = 0; j < size; ++j)
        for (std::uint32_t i = 0; i < size; ++i) {
            // Bottom right of pixel (i, j) in raster space = larger world x, smaller world y.
            const double x1 = pixelX0(i, size) + 1.0, y0 = pixelY0(j, size);
            cards.push_back(card(d, x1 - 0.5 * w, y0 + 0.5 * hgt, 0.5 * w, 0.5 * hgt, {1.0f, 1.0f, 1.0f}));
        }
    for (std::uint32_t spp : {2u, 3u, 5u, 7u, 10u, 16u}) {
        const dsm::Scene scene = sceneWith(orthoLight(size), cards);
        const auto map = build(scene, boxOptions(spp, 1e-3), (dir / ("cells" + std::to_string(spp) + ".dsm")).string());
        double sum = 0.0;
        for (std::uint32_t y = 0; y < size; ++y)
            for (std::uint32_t x = 0; x < size; ++x) sum += 1.0 - map->pixel(0, x, y)->evaluate(d);
        const double mean = sum / (size * size);
        const double bound = 2.0 / std::sqrt(double(size * size * spp)) + 1e-3 + kStorageSlack;
        EXPECT_NEAR(mean, w * hgt, bound) << "spp " << spp;
        std::printf("[ measured ] corner occluder, spp %2u: mean coverage %.4f (truth %.4f, bound +-%.3g)\n", spp, mean,
                    w * hgt, bound);
    }
}

// Coloured cards one behind the other: V per channel is the product of
// (1 - opacity) per channel of the cards in front; the map is RGB.
TEST(SamplerAccuracy, ColouredCards) {
    TempDir dir;
    const dsm::Rgb o1{0.2f, 0.5f, 0.875f}, o2{0.625f, 0.25f, 0.125f};
    const double d1 = 1.5, d2 = 3.25;
    const dsm::Scene scene = sceneWith(orthoLight(8), {wall(d2, o2), wall(d1, o1)});
    ASSERT_TRUE(scene.isColoured());
    const auto map = build(scene, boxOptions(4, 0.002), (dir / "rgb.dsm").string());
    ASSERT_EQ(map->info().channels, 3);
    const double bound = map->info().levels.at(0).tolerance + kStorageSlack;
    auto truth = [&](double z, std::size_t c) {
        double v = 1.0;
        if (z >= d1) v *= 1.0 - double(o1[c]);
        if (z >= d2) v *= 1.0 - double(o2[c]);
        return v;
    };
    double worst = 0.0;
    for (std::uint32_t y = 0; y < 8; ++y)
        for (std::uint32_t x = 0; x < 8; ++x) {
            const auto f = map->pixel(0, x, y);
            ASSERT_EQ(f->channels(), 3) << "pixel " << x << "," << y << " was stored monochrome";
            for (double z : {0.0, 1.0, 1.49, 1.5, 2.0, 3.2, 3.25, 4.0, 50.0})
                for (std::size_t c = 0; c < 3; ++c) {
                    const double error = std::abs(f->evaluate(z, int(c)) - truth(z, c));
                    worst = std::max(worst, error);
                    EXPECT_LE(error, bound) << "pixel " << x << "," << y << " z " << z << " channel " << c;
                }
        }
    std::printf("[ measured ] coloured cards: max error %.3g (bound %.3g)\n", worst, bound);
}

// An opaque edge moving across pixels during the shutter: the map holds the
// time-averaged coverage. The edge is parallel to the raster columns (it
// covers world x < e(t), e(t) = e0 + m t), so the truth per column is the
// integral over t of clamp(e(t) - x0, 0, 1) (midpoint rule, error < 1e-5).
// Each sample has a jittered position in its cell and a jittered time in its
// own shutter stratum (strata in random order: a Latin hypercube in time), so a
// pixel's estimate has a standard deviation of at most about 0.5 / sqrt(N - 1)
// (Latin hypercube sampling is never worse than N/(N-1) times plain Monte
// Carlo). The 16 pixels of a column are independent estimates of the same
// coverage: their mean is asserted within 4 standard deviations,
// 4 * 0.5 / sqrt(16 (N - 1)) = 0.5 / sqrt(N - 1), and the root mean square
// error over all partly covered pixels within 0.5 / sqrt(N).
TEST(SamplerAccuracy, MovingEdgeGivesTimeAveragedCoverage) {
    TempDir dir;
    const std::uint32_t size = 16;
    const double d = 2.0, e0 = -2.3, m = 3.4;
    dsm::SceneObject edge = halfPlane(d, e0, 0.0, 0.0);
    edge.motion = {m, 0.0, 0.0};
    auto timeAveraged = [&](double x0) {
        const int n = 200000;
        double sum = 0.0;
        for (int i = 0; i < n; ++i) sum += std::clamp(e0 + m * (i + 0.5) / n - x0, 0.0, 1.0);
        return sum / n;
    };
    for (std::uint32_t spp : {16u, 64u}) {
        const dsm::Scene scene = sceneWith(orthoLight(size), {edge});
        const auto map =
            build(scene, boxOptions(spp, 1e-3), (dir / ("motion" + std::to_string(spp) + ".dsm")).string());
        const double eps = map->info().levels.at(0).tolerance;
        const double columnBound = 0.5 / std::sqrt(double(spp - 1)) + eps + 1e-5 + kStorageSlack;
        const double rmsBound = 0.5 / std::sqrt(double(spp)) + eps + 1e-5 + kStorageSlack;
        double worst = 0.0, worstColumn = 0.0, sumSquares = 0.0;
        int partial = 0;
        for (std::uint32_t x = 0; x < size; ++x) {
            const double coverage = timeAveraged(pixelX0(x, size));
            double columnSum = 0.0;
            for (std::uint32_t y = 0; y < size; ++y) {
                const double error = map->pixel(0, x, y)->evaluate(d) - (1.0 - coverage);
                columnSum += error;
                if (coverage == 0.0 || coverage == 1.0) {
                    EXPECT_LE(std::abs(error), eps + kStorageSlack) << "spp " << spp << " pixel " << x << "," << y;
                } else {
                    ++partial;
                    sumSquares += error * error;
                    worst = std::max(worst, std::abs(error));
                }
            }
            const double columnError = std::abs(columnSum / size);
            EXPECT_LE(columnError, columnBound) << "spp " << spp << " column " << x << " coverage " << coverage;
            worstColumn = std::max(worstColumn, columnError);
        }
        ASSERT_GE(partial, 3 * int(size));  // the edge sweeps over several columns
        const double rms = std::sqrt(sumSquares / partial);
        EXPECT_LE(rms, rmsBound) << "spp " << spp;
        std::printf(
            "[ measured ] moving edge, spp %u: column means off by <= %.3g (bound %.3g); pixels: max %.3g, "
            "rms %.3g (bound %.3g)\n",
            spp, worstColumn, columnBound, worst, rms, rmsBound);
    }
}

// A multilayer map (Xie et al. 2007, §5.1) of a half-transparent card in front
// of two opaque ones: layer 0 ends at the first opaque card, layer 1 restarts
// at V = 1 behind it and ends at the second; counts are stored and add up to
// the hits of each layer.
TEST(SamplerAccuracy, MultilayerTwoOpaqueCards) {
    TempDir dir;
    const double dGlass = 0.5, d1 = 1.5, d2 = 3.0;
    const std::uint32_t spp = 4;
    const dsm::Scene scene =
        sceneWith(orthoLight(8), {wall(d2, {1, 1, 1}), wall(d1, {1, 1, 1}), wall(dGlass, {0.5f, 0.5f, 0.5f})});
    dsm::BuildOptions options = boxOptions(spp, 0.01);
    options.mtsmLayers = 2;
    const auto map = build(scene, options, (dir / "mtsm.dsm").string());
    ASSERT_TRUE(map->info().hasCounts);
    ASSERT_EQ(map->info().maxLayers, 2);
    const double bound = map->info().levels.at(0).tolerance + kStorageSlack;
    for (std::uint32_t y = 0; y < 8; ++y)
        for (std::uint32_t x = 0; x < 8; ++x) {
            const auto f = map->pixel(0, x, y);
            ASSERT_EQ(f->layerCount(), 2u) << x << "," << y;
            ASSERT_TRUE(f->hasCounts());
            // Layer 0: the light-centre function, ending at the first opaque card.
            EXPECT_FLOAT_EQ(f->z(f->layerEnd(0) - 1), float(d1));
            EXPECT_NEAR(f->evaluate(0.25), 1.0, bound);
            EXPECT_NEAR(f->evaluate(1.0), 0.5, bound);
            EXPECT_NEAR(f->evaluate(d1), 0.0, bound);
            EXPECT_NEAR(f->evaluate(2.5), 0.0, bound);
            // Layer 1: only what lies behind d1.
            EXPECT_GT(f->z(f->layerBegin(1)), float(d1));
            EXPECT_NEAR(f->evaluateLayer(1, 2.0), 1.0, bound);
            EXPECT_NEAR(f->evaluateLayer(1, 2.99), 1.0, bound);
            EXPECT_NEAR(f->evaluateLayer(1, d2), 0.0, bound);
            EXPECT_NEAR(f->evaluateLayer(1, 10.0), 0.0, bound);
            std::uint64_t counts[2] = {0, 0};
            for (std::size_t layer = 0; layer < 2; ++layer)
                for (std::size_t i = f->layerBegin(layer); i < f->layerEnd(layer); ++i) counts[layer] += f->count(i);
            EXPECT_EQ(counts[0], 2u * spp) << "two hits per ray in layer 0, pixel " << x << "," << y;
            EXPECT_EQ(counts[1], 1u * spp) << "one hit per ray in layer 1, pixel " << x << "," << y;
        }
}

// A scene with partial coverage everywhere (an edge, a moving half-transparent
// sphere, a slab), for determinism and regions.
dsm::Scene mixedScene(std::uint32_t size) {
    dsm::SceneObject sphere;
    sphere.name = "ball";
    sphere.geometry = dsm::Sphere{{-3.0, 2.0, kLightZ - 3.0}, 4.5};
    sphere.opacity = {0.6f, 0.6f, 0.6f};
    sphere.motion = {1.5, -0.5, 0.0};
    return sceneWith(orthoLight(size), {halfPlane(5.0, 1.1, -0.4, 1.0), sphere, slab(1.0, 2.0, 0.7, 0.2)});
}

// Same scene, options and seed: byte-identical files for 1 and 2 threads; a
// different seed changes the pixels (not just the seed in the metadata).
TEST(SamplerAccuracy, DeterministicAcrossThreadCounts) {
    TempDir dir;
    const dsm::Scene scene = mixedScene(40);
    dsm::BuildOptions options;  // the defaults: Gaussian filter of width 2, full mip pyramid
    options.samplesPerPixel = 4;
    options.tileSize = 8;
    options.counts = true;
    options.seed = 7;
    options.threads = 1;
    const std::string one = (dir / "one.dsm").string(), two = (dir / "two.dsm").string(),
                      other = (dir / "other.dsm").string();
    dsm::buildMap(scene, options, one);
    options.threads = 2;
    dsm::buildMap(scene, options, two);
    options.seed = 8;
    dsm::buildMap(scene, options, other);
    const std::string a = readBytes(one), b = readBytes(two), c = readBytes(other);
    ASSERT_GT(a.size(), 1000u);
    EXPECT_TRUE(a == b) << "threads = 1 and threads = 2 gave different files";
    EXPECT_FALSE(a == c) << "a different seed gave the same file";
    const auto mapA = dsm::DeepShadowMap::open(one), mapC = dsm::DeepShadowMap::open(other);
    int differing = 0;
    for (std::uint32_t y = 0; y < 40; ++y)
        for (std::uint32_t x = 0; x < 40; ++x)
            if (!(mapA->pixel(0, x, y)->toFunction() == mapC->pixel(0, x, y)->toFunction())) ++differing;
    EXPECT_GT(differing, 40) << "a different seed should move the samples of every partly covered pixel";
}

// A map built for the right half of the image: the left half is empty, the
// right half identical vertex for vertex to a full build's (with the default
// Gaussian filter of width 2, pixels at the region's edge use samples of
// pixels outside it, which must be the same samples). The region's left edge
// is not on a tile boundary, and the region is built with other tiles (level-0
// pixels do not depend on the tiling).
TEST(SamplerAccuracy, RegionMatchesFullBuild) {
    TempDir dir;
    const std::uint32_t size = 40;
    const dsm::Scene scene = mixedScene(size);
    dsm::BuildOptions options;
    options.samplesPerPixel = 4;
    options.tileSize = 16;
    options.counts = true;
    options.mipLevels = 1;
    const std::string full = (dir / "full.dsm").string(), half = (dir / "half.dsm").string();
    dsm::buildMap(scene, options, full);
    options.region = {size / 2, 0, size, size};
    options.tileSize = 8;
    const dsm::BuildStats stats = dsm::buildMap(scene, options, half);
    EXPECT_EQ(stats.pixels, std::uint64_t(size / 2) * size);
    dsm::validate(half);
    const auto mapFull = dsm::DeepShadowMap::open(full), mapHalf = dsm::DeepShadowMap::open(half);
    std::uint64_t rightVertices = 0;
    for (std::uint32_t y = 0; y < size; ++y)
        for (std::uint32_t x = 0; x < size; ++x) {
            const auto h = mapHalf->pixel(0, x, y);
            if (x < size / 2) {
                EXPECT_TRUE(h->empty()) << "pixel " << x << "," << y << " outside the region";
            } else {
                const auto f = mapFull->pixel(0, x, y);
                EXPECT_TRUE(h->toFunction() == f->toFunction()) << "pixel " << x << "," << y;
                rightVertices += f->size();
            }
        }
    EXPECT_EQ(mapHalf->info().levels.at(0).vertexCount, rightVertices);
    EXPECT_EQ(mapHalf->info().levels.at(0).nonEmptyPixels, std::uint64_t(size / 2) * size);
}

}  // namespace

namespace {

// Records the sampleRays calls of a build of wallScene(): how often each
// pixel's rays arrive, and whether each call held `spp` rays that crossed the
// wall alone.
struct WallRayRecorder {
    WallRayRecorder(std::uint32_t side, std::uint32_t spp, dsm::BuildOptions& options)
        : size(side), calls(side * side, 0) {
        options.sampleRays = [this, spp](std::uint32_t x, std::uint32_t y, std::span<const dsm::SampleRay> rays) {
            std::lock_guard<std::mutex> lock(mutex);
            ++calls[y * size + x];
            if (rays.size() != spp) raysAsExpected = false;
            for (const dsm::SampleRay& r : rays)
                if (r.hits.size() != 1 || std::abs(r.hits[0].z - 3.0f) > 1e-5f || r.hits[0].opacity[0] != 0.4f ||
                    !r.volume.empty())
                    raysAsExpected = false;
        };
    }
    int callsAt(std::uint32_t x, std::uint32_t y) const { return calls[y * size + x]; }

    std::uint32_t size;
    std::mutex mutex;
    std::vector<int> calls;
    bool raysAsExpected = true;
};

dsm::Scene wallScene(std::uint32_t size) { return sceneWith(orthoLight(size), {wall(3.0, {0.4f, 0.4f, 0.4f})}); }

// A whole-image build with a filter reaching the neighbouring pixels, so
// that tiles also sample their borders: each pixel's own rays are handed
// over once, by the tile the pixel belongs to, and no border sample is.
TEST(SamplerRawSamples, EveryPixelOfAWholeImageReceivesItsRaysOnce) {
    TempDir dir;
    dsm::BuildOptions options = boxOptions(5, 0.0);
    options.filter = dsm::PixelFilter::Gaussian;
    options.filterWidth = 3.0;
    options.tileSize = 8;
    WallRayRecorder recorder(19, 5, options);
    const dsm::BuildStats stats = dsm::buildMap(wallScene(19), options, (dir / "raw.dsm").string());
    EXPECT_GT(stats.samples, 19u * 19u * 5u);  // the tiles' borders were sampled too
    EXPECT_TRUE(recorder.raysAsExpected);
    for (std::uint32_t y = 0; y < 19; ++y)
        for (std::uint32_t x = 0; x < 19; ++x) EXPECT_EQ(recorder.callsAt(x, y), 1) << x << "," << y;
}

TEST(SamplerRawSamples, EveryPixelOfTheRegionReceivesItsRaysOnce) {
    TempDir dir;
    dsm::BuildOptions options = boxOptions(9, 0.0);
    options.region = {2, 3, 13, 11};
    WallRayRecorder recorder(16, 9, options);
    dsm::buildMap(wallScene(16), options, (dir / "raw.dsm").string());
    EXPECT_TRUE(recorder.raysAsExpected);
    for (std::uint32_t y = 0; y < 16; ++y)
        for (std::uint32_t x = 0; x < 16; ++x) {
            const bool inside = x >= 2 && x < 13 && y >= 3 && y < 11;
            EXPECT_EQ(recorder.callsAt(x, y), inside ? 1 : 0) << x << "," << y;
        }
}

}  // namespace
