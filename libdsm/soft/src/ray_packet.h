// The rays of one soft-shadow query traced together down a map's min/max
// depth hierarchy (internal). The rays from a receiver to the samples of an
// area light leave from nearly one raster point, so they cross mostly the
// same nodes: on the hair ball, 64 rays visited 477 nodes one by one but only
// 20 distinct ones. A packet visits each node once, fetches its depth range
// once, and tests every ray still in it against the node in one pass over
// the rays (a loop the compiler vectorises).
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "depth_hierarchy.h"
#include "tested_internal.h"

namespace dsm::detail {

/// A ray between two light-space points, as its raster image r(u) = r0 + u dr,
/// u in [0, 1], with 1/z linear in u (perspective-correct depth).
struct RasterRay {
    double r0x = 0.0, r0y = 0.0, drx = 0.0, dry = 0.0;
    double invZ0 = 0.0, dInvZ = 0.0;
    double z(double u) const { return 1.0 / (invZ0 + u * dInvZ); }
};

/// 1 / the raster steps of a ray (infinite along an axis it does not move
/// on), worked out once for a ray clipped to many boxes.
struct RayInverse {
    explicit RayInverse(const RasterRay& r) : x(1.0 / r.drx), y(1.0 / r.dry) {}
    double x, y;
};

/// Clips [ua, ub] to the part of the ray inside the closed box; false if none.
/// Inline: every ray is clipped to the map, and to each pixel it reads.
inline bool clipRay(const RasterRay& r, const RayInverse& inverse, double x0, double y0, double x1, double y1,
                    double& ua, double& ub) {
    auto slab = [&](double origin, double direction, double perStep, double lo, double hi) {
        if (direction == 0.0) return origin >= lo && origin <= hi;
        const double t0 = (lo - origin) * perStep, t1 = (hi - origin) * perStep;
        ua = std::max(ua, std::min(t0, t1));  // no branch on the direction's sign
        ub = std::min(ub, std::max(t0, t1));
        return true;
    };
    return slab(r.r0x, r.drx, inverse.x, x0, x1) && slab(r.r0y, r.dry, inverse.y, y0, y1) && ua <= ub;
}

class DSM_TESTED_INTERNAL RayPacket {
public:
    static constexpr int kLanes = 64;

    struct Pixel {
        std::uint32_t x, y;
    };

    /// Traces rays[k] over its stretch [ua[k], ub[k]] (inside the map),
    /// k < count <= kLanes, down the hierarchy from the level whose 2 x 2
    /// nodes hold every ray. Finds for each ray the level-0 pixels it may
    /// cross where the pixel's depths (the hierarchy's level 0, read once a
    /// pixel for all the rays) may meet the ray's within zThreshold: every
    /// pixel whose depth range an exact test finds the ray's to meet, and
    /// perhaps a few more (the tests are in single precision, widened by a
    /// few ulps). Their order is the packet's, not the ray's. May read and
    /// decode tiles (through the hierarchy); throws what it throws.
    void trace(const DepthHierarchy& hierarchy, const RasterRay* rays, const double* ua,
               const double* ub, int count, double zThreshold);

    /// The pixels found for ray k by the last trace().
    const Pixel* pixelsBegin(int k) const { return pixels_.data() + first_[static_cast<std::size_t>(k)]; }
    const Pixel* pixelsEnd(int k) const { return pixels_.data() + first_[static_cast<std::size_t>(k) + 1]; }
    /// Every ray's pixels from the last trace() (a pixel once for each ray).
    const std::vector<Pixel>& allPixels() const { return pixels_; }
    /// Nodes above level 0 that rays entered (a node once for each ray).
    std::uint64_t nodeVisits() const { return nodeVisits_; }

private:
    struct Found {
        std::uint32_t lane;
        Pixel pixel;
    };
    // Each ray's state in the frame of the packet's first nodes, one array
    // per field so that one pass over the rays is a vector loop.
    struct Lanes {
        float ox[kLanes], oy[kLanes];                  // the ray's raster position at ua, in the frame
        float invDx[kLanes], invDy[kLanes];            // 1 / raster step per unit of length (0 when fixed)
        float slackX[kLanes], slackY[kLanes];          // rounding allowance of the stretches
        float lowX[kLanes], highX[kLanes];             // span across x, for a ray fixed in x
        float lowY[kLanes], highY[kLanes];
        float fixedX[kLanes], fixedY[kLanes];          // 1: the ray (almost) does not move along the axis
        float length[kLanes];                          // ub - ua
        float w0[kLanes], dw[kLanes], wError[kLanes];  // inverse depth at ua, its change, its rounding
    };
    struct ChildBoxes;
    // Rays [begin, begin + 8) against the four children of a node: bit k of
    // reached[c] when ray begin + k's stretch in child c (its clip to the
    // child's box, widened by the ray's slack) is not empty and its inverse
    // depth there can meet the child's depth range within zT.
    static void testGroup(const Lanes& r, int begin, const ChildBoxes& b, float zT, int reached[4]);

    Lanes lanes_;
    std::vector<Found> found_;
    std::vector<Pixel> pixels_;
    std::vector<std::size_t> first_, next_;  // each ray's first pixel; the next free slot while filing
    std::uint64_t nodeVisits_ = 0;
};

}  // namespace dsm::detail
