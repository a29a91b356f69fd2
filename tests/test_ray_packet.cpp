// RayPacket (libdsm/soft/src/ray_packet.h): the rays of a soft-shadow query
// traced together down a map's min/max depth hierarchy must find, for each
// ray, every pixel it crosses whose depths meet its own (the pixels whose
// reading can change the ray) and few others. Checked against every pixel of a map with scattered
// depths, for rays in every direction (along the raster axes too), packets of
// 1 to 64 rays, and z thresholds.
#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "depth_hierarchy.h"
#include "map_fixtures.h"
#include "ray_packet.h"
#include "temp_dir.h"

namespace {

using dsm::detail::clipRay;
using dsm::detail::RasterRay;
using dsm::detail::RayInverse;
using dsm::detail::RayPacket;

// A 75 x 53 map of 8 x 8 tiles (so the hierarchy has levels in the tiles and
// above them, and partial tiles at the edges): pixels of one to three
// vertices at depths spread over 1 .. 40, in patches, and empty ones.
std::shared_ptr<const dsm::DeepShadowMap> scatteredDepths(const std::filesystem::path& path) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<float> patchDepth(1.0f, 40.0f);
    std::vector<float> patches(10 * 7);
    for (float& z : patches) z = patchDepth(rng);
    const dsm::test::Image image = dsm::test::makeImage(75, 53, [&](std::uint32_t x, std::uint32_t y) {
        if (rng() % 7 == 0) return dsm::VisibilityFunction(1, false);
        const float zStart = patches[(y / 8) * 10 + x / 8] * (1.0f + 0.05f * static_cast<float>(rng() % 5));
        return dsm::test::randomFunction(rng, 1, false, 1, 3, zStart);
    });
    dsm::WriterOptions options;
    options.tileSize = 8;
    options.channels = 1;
    options.tolerance = 0.0;
    options.mipLevels = 1;
    dsm::test::writeMap(path, options, image);
    return dsm::DeepShadowMap::open(path.string());
}

// A random ray over the map: from a point around it to another, its inverse
// depth linear along it between depths 0.5 and 60; now and then along a
// raster axis, exactly or nearly, or from a pixel corner through others
// (where rounding decides which pixels a float test lets through).
RasterRay randomRay(std::mt19937_64& rng) {
    std::uniform_real_distribution<double> x(-20.0, 95.0), y(-20.0, 73.0), z(0.5, 60.0), tiny(-1e-7, 1e-7);
    RasterRay r;
    r.r0x = x(rng);
    r.r0y = y(rng);
    r.drx = x(rng) - r.r0x;
    r.dry = y(rng) - r.r0y;
    switch (rng() % 10) {
        case 0: r.drx = 0.0; break;
        case 1: r.dry = 0.0; break;
        case 2: r.drx = tiny(rng); break;
        case 3: r.dry = tiny(rng); break;
        case 4:
        case 5: {
            const double step = 1.0 + static_cast<double>(rng() % 3);  // through every, second or third corner
            r.r0x = std::round(r.r0x);
            r.r0y = std::round(r.r0y);
            r.drx = step * 30.0 * (rng() % 2 ? 1.0 : -1.0);
            r.dry = step * 30.0 * (rng() % 2 ? 1.0 : -1.0) * (rng() % 2 ? 1.0 : 0.5);
            if (rng() % 2) std::swap(r.drx, r.dry);
            break;
        }
        default: break;
    }
    const double z0 = z(rng), z1 = z(rng);
    r.invZ0 = 1.0 / z0;
    r.dInvZ = 1.0 / z1 - 1.0 / z0;
    return r;
}

TEST(RayPacket, FindsEveryPixelWhoseDepthsMeetTheRay) {
    dsm::test::TempDir dir;
    const auto map = scatteredDepths(dir.path() / "scattered.dsm");
    const dsm::detail::DepthHierarchy hierarchy(*map);
    const std::uint32_t W = map->info().width, H = map->info().height;
    std::mt19937_64 rng(5);
    RayPacket packet;
    std::size_t relevant = 0, crossed = 0, found = 0;
    for (int trial = 0; trial < 600; ++trial) {
        const int count = trial % 5 == 0 ? 1 : 1 + static_cast<int>(rng() % RayPacket::kLanes);
        const double zThreshold = std::vector<double>{0.0, 0.05, 0.5}[rng() % 3];
        std::vector<RasterRay> rays;
        std::vector<double> ua, ub;
        while (static_cast<int>(rays.size()) < count) {
            const RasterRay r = randomRay(rng);
            double a = 0.0, b = 1.0;
            if (!clipRay(r, RayInverse(r), 0.0, 0.0, W, H, a, b)) continue;
            // Now and then a part of it only.
            if (rng() % 4 == 0) a += (b - a) * 0.5;
            rays.push_back(r);
            ua.push_back(a);
            ub.push_back(b);
        }
        packet.trace(hierarchy, rays.data(), ua.data(), ub.data(), count, zThreshold);
        for (int k = 0; k < count; ++k) {
            const RayInverse inverse(rays[k]);
            std::set<std::pair<std::uint32_t, std::uint32_t>> pixels;
            for (const RayPacket::Pixel* p = packet.pixelsBegin(k); p != packet.pixelsEnd(k); ++p) {
                ASSERT_LT(p->x, W);
                ASSERT_LT(p->y, H);
                pixels.insert({p->x, p->y});
            }
            found += pixels.size();
            for (std::uint32_t y = 0; y < H; ++y)
                for (std::uint32_t x = 0; x < W; ++x) {
                    double a = ua[k], b = ub[k];
                    if (!clipRay(rays[k], inverse, x, y, std::min(x + 1.0, double(W)), std::min(y + 1.0, double(H)), a, b))
                        continue;
                    ++crossed;
                    // As a ray's read of a pixel tests it first.
                    const dsm::PixelFunction pf = map->pixel(0, x, y);
                    const dsm::VisibilityView& f = pf.view();
                    if (f.empty()) continue;
                    const double za = rays[k].z(a), zb = rays[k].z(b);
                    const double lo = std::min(za, zb) - zThreshold, hi = std::max(za, zb) + zThreshold;
                    if (f.z(0) > hi || f.z(f.size() - 1) < lo) continue;
                    ++relevant;
                    ASSERT_TRUE(pixels.count({x, y}))
                        << "trial " << trial << ", ray " << k << " of " << count << " misses pixel " << x << "," << y
                        << " (ray from " << rays[k].r0x << "," << rays[k].r0y << " by " << rays[k].drx << ","
                        << rays[k].dry << ", u " << ua[k] << " .. " << ub[k] << ")";
                }
        }
    }
    // The depths do cull: few pixels beyond those that matter are offered.
    EXPECT_GT(relevant, 1000u);
    EXPECT_LT(found, 2 * relevant) << relevant << " relevant of " << crossed << " crossed";
    std::printf("  %zu pixels crossed, %zu meet the rays' depths, %zu found\n", crossed, relevant, found);
}

TEST(RayPacket, ClipsToTheClosedBox) {
    RasterRay r;
    r.r0x = -1.0;
    r.r0y = 0.5;
    r.drx = 4.0;
    r.dry = 0.0;
    double a = 0.0, b = 1.0;
    const RayInverse inverse(r);
    ASSERT_TRUE(clipRay(r, inverse, 0.0, 0.0, 2.0, 1.0, a, b));
    EXPECT_DOUBLE_EQ(a, 0.25);
    EXPECT_DOUBLE_EQ(b, 0.75);
    a = 0.0;
    b = 1.0;
    EXPECT_FALSE(clipRay(r, inverse, 0.0, 0.6, 2.0, 1.0, a, b));  // parallel to the box's edge, outside it
    a = 0.0;
    b = 1.0;
    EXPECT_TRUE(clipRay(r, inverse, 3.0, 0.5, 4.0, 1.0, a, b));   // touching the box's edge
    EXPECT_DOUBLE_EQ(a, 1.0);
    EXPECT_DOUBLE_EQ(b, 1.0);
}

}  // namespace
