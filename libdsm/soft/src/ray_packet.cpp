#include "ray_packet.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "simd_lanes.h"

namespace dsm::detail {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
// Rays are tested eight at a time; a group of eight without a ray in the node
// is skipped.
constexpr int kGroup = 8;

}  // namespace

// The four children of a node, children[j * 2 + i] = child (2x + i, 2y + j):
// their bounds in the frame and their depth ranges.
struct RayPacket::ChildBoxes {
    float x[3], y[3];     // column i spans [x[i], x[i + 1]], row j [y[j], y[j + 1]]
    DepthRange range[4];  // of each child
};

// Compiled for AVX2 too (chosen when the processor has it): eight lanes are
// one register there, two elsewhere. Eight-float values stay local here: no
// call takes or returns one, since such a call is made differently with and
// without AVX (clang refuses it in the code built without; see simd_lanes.h).
__attribute__((target_clones("avx2", "default"))) void RayPacket::testGroup(const Lanes& r, int begin,
                                                                            const ChildBoxes& b, float zT,
                                                                            int reached[4]) {
    const Float8 zero{}, inf = zero + kInf;
    Float8 start[2][2], end[2][2];  // [axis][half]
    for (int axis = 0; axis < 2; ++axis) {
        const float* bounds = axis == 0 ? b.x : b.y;
        Float8 origin, inverse, slack, low, high, fixedFlags;
        std::memcpy(&origin, (axis == 0 ? r.ox : r.oy) + begin, sizeof origin);
        std::memcpy(&inverse, (axis == 0 ? r.invDx : r.invDy) + begin, sizeof inverse);
        std::memcpy(&slack, (axis == 0 ? r.slackX : r.slackY) + begin, sizeof slack);
        std::memcpy(&low, (axis == 0 ? r.lowX : r.lowY) + begin, sizeof low);
        std::memcpy(&high, (axis == 0 ? r.highX : r.highY) + begin, sizeof high);
        std::memcpy(&fixedFlags, (axis == 0 ? r.fixedX : r.fixedY) + begin, sizeof fixedFlags);
        const Mask8 fixed = fixedFlags != zero;
        Float8 t[3];
        for (int i = 0; i < 3; ++i) t[i] = (zero + bounds[i] - origin) * inverse;
        for (int half = 0; half < 2; ++half) {
            const Float8 p = t[half], q = t[half + 1];
            const Float8 moving0 = (p < q ? p : q) - slack, moving1 = (p > q ? p : q) + slack;
            // A ray fixed along the axis meets the half where its span does.
            const Mask8 meets = (low <= zero + bounds[half + 1]) & (high >= zero + bounds[half]);
            start[axis][half] = fixed ? (meets ? -inf : inf) : moving0;
            end[axis][half] = fixed ? (meets ? inf : -inf) : moving1;
        }
    }
    Float8 length, w0, dw, wError;
    std::memcpy(&length, r.length + begin, sizeof length);
    std::memcpy(&w0, r.w0 + begin, sizeof w0);
    std::memcpy(&dw, r.dw + begin, sizeof dw);
    std::memcpy(&wError, r.wError + begin, sizeof wError);
    for (int c = 0; c < 4; ++c) {
        const int i = c & 1, j = c >> 1;
        Float8 ta = zero > start[0][i] ? zero : start[0][i];
        ta = ta > start[1][j] ? ta : start[1][j];
        Float8 tb = length < end[0][i] ? length : end[0][i];
        tb = tb < end[1][j] ? tb : end[1][j];
        // The ray meets [lo, hi] where its depth 1/w does: 1/wMin >= lo and
        // 1/wMax <= hi, w > 0.
        const Float8 wa = w0 + ta * dw, wb = w0 + tb * dw;
        const Float8 wMin = (wa < wb ? wa : wb) - wError, wMax = (wa > wb ? wa : wb) + wError;
        const Mask8 ok = (ta <= tb) & ~((wMin * (b.range[c].min - zT) > zero + (1.0f + 1e-5f)) |
                                        (wMax * (b.range[c].max + zT) < zero + (1.0f - 1e-5f)));
        reached[c] = laneMask(ok);
    }
}

void RayPacket::trace(const DepthHierarchy& hierarchy, const RasterRay* rays,
                      const double* ua, const double* ub, int count, double zThreshold) {
    found_.clear();
    nodeVisits_ = 0;
    first_.assign(kLanes + 1, 0);
    pixels_.clear();
    if (count <= 0) return;
    const std::uint32_t width = hierarchy.width(), height = hierarchy.height();
    // The pixels every ray's stretch spans, and the level whose 2 x 2 nodes
    // from (bx0, by0) hold them all (Curtis §3.5, for the packet).
    double xMin = std::numeric_limits<double>::infinity(), yMin = xMin, xMax = -xMin, yMax = -xMin;
    for (int k = 0; k < count; ++k) {
        const RasterRay& ray = rays[k];
        const double ax = ray.r0x + ua[k] * ray.drx, bx = ray.r0x + ub[k] * ray.drx;
        const double ay = ray.r0y + ua[k] * ray.dry, by = ray.r0y + ub[k] * ray.dry;
        xMin = std::min({xMin, ax, bx});
        xMax = std::max({xMax, ax, bx});
        yMin = std::min({yMin, ay, by});
        yMax = std::max({yMax, ay, by});
    }
    const std::uint32_t px0 = clampedPixel(xMin, width), px1 = clampedPixel(xMax, width);
    const std::uint32_t py0 = clampedPixel(yMin, height), py1 = clampedPixel(yMax, height);
    const int g0 = std::min(std::max(1, static_cast<int>(std::bit_width(std::max(px1 - px0, py1 - py0)))),
                            hierarchy.topLevel());
    const std::uint32_t bx0 = px0 >> g0, by0 = py0 >> g0;
    const double fx = static_cast<double>(std::uint64_t{bx0} << g0), fy = static_cast<double>(std::uint64_t{by0} << g0);
    // Rounding bounds: positions in the frame are below 2^(g0+2), so a few
    // ulps of that in raster units; inverse depths a few ulps of their
    // largest term.
    const float delta = 2e-6f * static_cast<float>(std::uint64_t{1} << g0);
    Lanes& r = lanes_;
    for (int l = 0; l < kLanes; ++l) {
        if (l >= count) {  // never in a mask; set so that reading them is defined
            r.ox[l] = r.oy[l] = r.invDx[l] = r.invDy[l] = r.slackX[l] = r.slackY[l] = 0.0f;
            r.lowX[l] = r.highX[l] = r.lowY[l] = r.highY[l] = r.fixedX[l] = r.fixedY[l] = 0.0f;
            r.length[l] = r.w0[l] = r.dw[l] = r.wError[l] = 0.0f;
            continue;
        }
        const RasterRay& ray = rays[l];
        const double ax = ray.r0x + ua[l] * ray.drx, ay = ray.r0y + ua[l] * ray.dry;
        const auto ox = static_cast<float>(ax - fx), oy = static_cast<float>(ay - fy);
        const auto dx = static_cast<float>(ray.drx), dy = static_cast<float>(ray.dry);
        const auto length = static_cast<float>(ub[l] - ua[l]);
        const bool alongY = std::abs(dx) * length <= delta, alongX = std::abs(dy) * length <= delta;
        const float invDx = alongY ? 0.0f : 1.0f / dx, invDy = alongX ? 0.0f : 1.0f / dy;
        r.ox[l] = ox;
        r.oy[l] = oy;
        r.invDx[l] = invDx;
        r.invDy[l] = invDy;
        r.slackX[l] = delta * std::abs(invDx) + 1e-6f * length;
        r.slackY[l] = delta * std::abs(invDy) + 1e-6f * length;
        r.lowX[l] = std::min(ox, ox + dx * length) - delta;
        r.highX[l] = std::max(ox, ox + dx * length) + delta;
        r.lowY[l] = std::min(oy, oy + dy * length) - delta;
        r.highY[l] = std::max(oy, oy + dy * length) + delta;
        r.fixedX[l] = alongY ? 1.0f : 0.0f;
        r.fixedY[l] = alongX ? 1.0f : 0.0f;
        r.length[l] = length;
        const auto w0 = static_cast<float>(ray.invZ0 + ua[l] * ray.dInvZ), dw = static_cast<float>(ray.dInvZ);
        r.w0[l] = w0;
        r.dw[l] = dw;
        r.wError[l] = 1e-6f * (std::abs(w0) + std::abs(dw) * length);
    }

    struct Node {
        std::uint32_t x, y;
        int g;
        std::uint64_t mask;
    };
    Node stack[4 * 66];
    int top = 0;
    const auto zT = static_cast<float>(zThreshold);
    const std::uint64_t all = count == kLanes ? ~std::uint64_t{0} : (std::uint64_t{1} << count) - 1;
    // The children of level g (x0 .. x0 + 1, y0 .. y0 + 1) that the rays of
    // `mask` reach, pushed with their rays; pixels recorded for their rays.
    const auto expand = [&](int g, std::uint32_t x0, std::uint32_t y0, std::uint64_t mask) {
        ChildBoxes b;
        const double size = static_cast<double>(std::uint64_t{1} << g);
        for (int i = 0; i < 3; ++i) {
            b.x[i] = static_cast<float>(static_cast<double>(x0 + i) * size - fx);
            b.y[i] = static_cast<float>(static_cast<double>(y0 + i) * size - fy);
        }
        bool inside[4];  // the child lies inside the map
        for (int c = 0; c < 4; ++c) {
            const std::uint32_t cx = x0 + (c & 1), cy = y0 + (c >> 1);
            inside[c] = (std::uint64_t{cx} << g) < width && (std::uint64_t{cy} << g) < height;
            if (inside[c]) b.range[c] = hierarchy.node(g, cx, cy);
        }
        std::uint64_t reached[4] = {0, 0, 0, 0};
        for (int group = 0; group < kLanes; group += kGroup) {
            if (((mask >> group) & ((std::uint64_t{1} << kGroup) - 1)) == 0) continue;
            int bits[4];
            testGroup(r, group, b, zT, bits);
            for (int c = 0; c < 4; ++c) reached[c] |= std::uint64_t(static_cast<unsigned>(bits[c])) << group;
        }
        for (int c = 0; c < 4; ++c) {
            const std::uint64_t rays = reached[c] & mask;
            if (!inside[c] || b.range[c].empty() || rays == 0) continue;
            const std::uint32_t cx = x0 + (c & 1), cy = y0 + (c >> 1);
            if (g == 0) {
                for (std::uint64_t m = rays; m != 0; m &= m - 1)
                    found_.push_back({static_cast<std::uint32_t>(std::countr_zero(m)), {cx, cy}});
            } else {
                nodeVisits_ += static_cast<std::uint64_t>(std::popcount(rays));
                stack[top++] = {cx, cy, g, rays};
            }
        }
    };
    expand(g0, bx0, by0, all);
    while (top > 0) {
        const Node n = stack[--top];
        expand(n.g - 1, 2 * n.x, 2 * n.y, n.mask);
    }
    // Grouped by ray, each ray's in the order found.
    for (const Found& f : found_) ++first_[f.lane + 1];
    for (int k = 0; k < kLanes; ++k) first_[static_cast<std::size_t>(k) + 1] += first_[static_cast<std::size_t>(k)];
    pixels_.resize(found_.size());
    next_.assign(first_.begin(), first_.end() - 1);
    for (const Found& f : found_) pixels_[next_[f.lane]++] = f.pixel;
}

}  // namespace dsm::detail
