// Filtered lookups (lookup.h; Lokovic & Veach §3.4, §5.3) against brute force:
// the documented box, triangle and Gaussian kernels evaluated over every pixel
// of level 0 and of the stored coarser levels, the documented trilinear level
// selection, the error bound reported, points outside the map, RGB maps with
// monochrome pixels, world/light space through perspective and orthographic
// cameras, the depth bias; then several threads sharing one map and a small
// tile cache, and the cache's byte budget under random pixel access.
#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <numeric>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "map_fixtures.h"
#include "oracle.h"
#include "temp_dir.h"

namespace {

using dsm::DeepShadowMap;
using dsm::LookupContext;
using dsm::LookupOptions;
using dsm::LookupResult;
using dsm::PixelFilter;
using dsm::VisibilityFunction;
using dsm::WriterOptions;
using dsm::test::Image;
using dsm::test::TempDir;

constexpr double kTight = 1e-12;  // same formulas, possibly another summation order

// Options that look up the queried depth itself (no bias): the tests below
// check the filters against the stored functions at that depth.
LookupOptions atTheDepth() {
    LookupOptions o;
    o.bias = 0.0;
    return o;
}
constexpr double kPi = 3.14159265358979323846;

double minimumWidth(PixelFilter f) { return f == PixelFilter::Box ? 1.0 : 2.0; }

// The documented kernel (lookup.h) of pixel i along one axis, for a footprint of
// width w (>= the minimum) centred at c, in pixels of the level used.
double kernel(PixelFilter f, long i, double c, double w) {
    const double r = 0.5 * w;
    const double d = (static_cast<double>(i) + 0.5) - c;
    switch (f) {
        case PixelFilter::Box: {
            const double lo = std::max(static_cast<double>(i), c - r);
            const double hi = std::min(static_cast<double>(i) + 1.0, c + r);
            return std::max(0.0, hi - lo);
        }
        case PixelFilter::Triangle: return std::max(0.0, 1.0 - std::abs(d) / r);
        case PixelFilter::Gaussian: {
            const double s = w / 4.0;
            return std::abs(d) < r ? std::exp(-d * d / (2.0 * s * s)) : 0.0;
        }
    }
    return 0.0;
}

struct Filtered {
    std::array<double, 3> v{1.0, 1.0, 1.0};
    int used = 0;
    double total = 0.0;
};

// sum w V / sum w over every pixel of a width x height level, V(x, y, c) given.
template <class Value>
Filtered filterAll(std::uint32_t width, std::uint32_t height, PixelFilter f, double w, double cx, double cy,
                   const Value& value) {
    Filtered out;
    std::array<double, 3> sum{0.0, 0.0, 0.0};
    for (std::uint32_t y = 0; y < height; ++y) {
        const double ky = kernel(f, y, cy, w);
        if (ky == 0.0) continue;
        for (std::uint32_t x = 0; x < width; ++x) {
            const double kx = kernel(f, x, cx, w);
            if (kx == 0.0) continue;
            const double k = kx * ky;
            for (int c = 0; c < 3; ++c) sum[static_cast<std::size_t>(c)] += k * value(x, y, c);
            out.total += k;
            ++out.used;
        }
    }
    if (out.total > 0.0)
        for (int c = 0; c < 3; ++c) out.v[static_cast<std::size_t>(c)] = sum[static_cast<std::size_t>(c)] / out.total;
    return out;
}

// Level-0 brute force from the functions written (oracle evaluation of their
// light-centre functions).
class LevelZero {
public:
    explicit LevelZero(const Image& image) : width_(image.width), height_(image.height) {
        for (const VisibilityFunction& f : image.pixels) centre_.push_back(dsm::test::lightCentre(f, f.channels()));
    }
    double value(std::uint32_t x, std::uint32_t y, double z, int c) const {
        const VisibilityFunction& f = centre_[std::size_t(y) * width_ + x];
        return dsm::test::valueAt(f, z, std::min(c, f.channels() - 1));
    }
    Filtered filter(PixelFilter f, double width, double rx, double ry, double z) const {
        const double w = std::max(width, minimumWidth(f));
        return filterAll(width_, height_, f, w, rx, ry,
                         [&](std::uint32_t x, std::uint32_t y, int c) { return value(x, y, z, c); });
    }
    std::uint32_t width() const { return width_; }
    std::uint32_t height() const { return height_; }

private:
    std::uint32_t width_, height_;
    std::vector<VisibilityFunction> centre_;
};

// One stored level filtered by the documented kernel, from the reader's pixels.
Filtered filterStored(const DeepShadowMap& map, unsigned level, PixelFilter f, double levelWidth, double rx, double ry,
                      double z) {
    const dsm::LevelInfo& L = map.info().levels[level];
    const double scale = std::ldexp(1.0, -static_cast<int>(level));
    return filterAll(L.width, L.height, f, levelWidth, rx * scale, ry * scale, [&](std::uint32_t x, std::uint32_t y, int c) {
        const dsm::PixelFunction p = map.pixel(level, x, y);
        return p->empty() ? 1.0 : p->evaluate(z, std::min(c, p->channels() - 1));
    });
}

// The documented level choice and trilinear blend, evaluated by brute force.
struct Reference {
    std::array<double, 3> v{1.0, 1.0, 1.0};
    int used = 0;
    double errorBound = 0.0;
    unsigned level0 = 0, level1 = 0;
    double blend = 0.0;
};

/// A test's level: negative for automatic.
std::optional<unsigned> levelOption(int level) {
    if (level < 0) return std::nullopt;
    return static_cast<unsigned>(level);
}

Reference referenceLookup(const DeepShadowMap& map, const LookupOptions& o, double rx, double ry, double z) {
    const auto& levels = map.info().levels;
    const unsigned coarsest = static_cast<unsigned>(levels.size() - 1);
    const double minW = minimumWidth(o.filter);
    const double width = std::max(o.filterWidth, minW);
    Reference r;
    if (o.level) {
        r.level0 = r.level1 = std::min(*o.level, coarsest);
    } else {
        const double lambda = std::max(0.0, std::log2(width / minW));
        r.level0 = std::min(static_cast<unsigned>(std::floor(lambda)), coarsest);
        r.level1 = std::min(r.level0 + 1, coarsest);
        r.blend = r.level1 == r.level0 ? 0.0 : lambda - std::floor(lambda);
    }
    const double zq = z - (o.bias ? *o.bias : dsm::automaticBias(map.info(), rx, ry, z, o.normal));
    const auto levelWidth = [&](unsigned l) { return std::max(width * std::ldexp(1.0, -static_cast<int>(l)), minW); };
    const Filtered a = filterStored(map, r.level0, o.filter, levelWidth(r.level0), rx, ry, zq);
    r.used = a.used;
    r.v = a.v;
    if (a.total > 0.0) r.errorBound = levels[r.level0].errorBound;
    if (r.blend > 0.0) {
        const Filtered b = filterStored(map, r.level1, o.filter, levelWidth(r.level1), rx, ry, zq);
        r.used += b.used;
        if (b.total > 0.0) r.errorBound = std::max(r.errorBound, levels[r.level1].errorBound);
        for (std::size_t c = 0; c < 3; ++c) r.v[c] = std::clamp(a.v[c] + r.blend * (b.v[c] - a.v[c]), 0.0, 1.0);
    }
    return r;
}

// A map whose functions vary smoothly with the pixel centre: four vertices
// whose depths and values are smooth functions of (x, y); continuous in z.
VisibilityFunction smoothPixel(std::uint32_t x, std::uint32_t y, std::uint32_t w, std::uint32_t h, int channels) {
    const double cx = x + 0.5, cy = y + 0.5;
    const double shift = 0.4 * std::sin(2 * kPi * cx / w) + 0.3 * std::cos(2 * kPi * cy / h);
    VisibilityFunction f(channels);
    float v[3];
    auto b = [&](int c) { return 0.5 + 0.3 * std::sin(2 * kPi * cx / w + 0.7 * c) * std::cos(2 * kPi * cy / h - 0.4 * c); };
    const double fractions[4] = {0.0, 0.45, 0.85, 0.97};
    for (int k = 0; k < 4; ++k) {
        for (int c = 0; c < channels; ++c) v[c] = static_cast<float>(1.0 - fractions[k] * (k == 3 ? 1.0 : b(c)));
        f.append(static_cast<float>(1.0 + k + shift * (1.0 + 0.2 * k)), v);
    }
    return f;
}

Image smoothImage(std::uint32_t w, std::uint32_t h, int channels) {
    return dsm::test::makeImage(w, h, [&](std::uint32_t x, std::uint32_t y) { return smoothPixel(x, y, w, h, channels); });
}

// Random functions: RGB and monochrome pixels, two layers, empty pixels.
Image randomImage(std::uint32_t w, std::uint32_t h, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    return dsm::test::makeImage(w, h, [&](std::uint32_t x, std::uint32_t y) {
        if ((x * 5 + y * 3) % 11 == 0) return VisibilityFunction((x + y) % 2 ? 3 : 1);
        return dsm::test::randomFunction(rng, (x + 2 * y) % 3 == 0 ? 1 : 3, false, 1 + static_cast<int>((x + y) % 2), 6);
    });
}

struct OpenMap {
    TempDir dir;
    Image image;
    std::shared_ptr<DeepShadowMap> map;
};

std::unique_ptr<OpenMap> writeAndOpen(Image image, WriterOptions o, const dsm::ReaderOptions& ro = {}) {
    auto m = std::make_unique<OpenMap>();
    m->image = std::move(image);
    const auto path = m->dir / "map.dsm";
    dsm::test::writeMap(path, o, m->image, 3);
    m->map = DeepShadowMap::open(path.string(), ro);
    return m;
}

std::unique_ptr<OpenMap> randomRgbMap() {
    WriterOptions o;
    o.tileSize = 4;
    o.channels = 3;
    o.maxLayers = 2;
    o.tolerance = 0.01;
    return writeAndOpen(randomImage(23, 17, 42), o);
}

std::unique_ptr<OpenMap> smoothMonoMap() {
    WriterOptions o;
    o.tileSize = 16;
    o.tolerance = 0.002;
    return writeAndOpen(smoothImage(128, 96, 1), o);
}

void expectMatches(const LookupResult& got, const std::array<double, 3>& want, int wantUsed, const std::string& where) {
    for (std::size_t c = 0; c < 3; ++c) EXPECT_NEAR(got.v[c], want[c], kTight) << where << " channel " << c;
    EXPECT_EQ(got.pixelsUsed, wantUsed) << where;
}

std::string describe(const LookupOptions& o, double rx, double ry, double z) {
    return "filter " + std::to_string(int(o.filter)) + " width " + std::to_string(o.filterWidth) + " level " +
           (o.level ? std::to_string(*o.level) : std::string("auto")) + " at " + std::to_string(rx) + "," +
           std::to_string(ry) + " z " + std::to_string(z);
}

// Query points: random inside, the corners and edges, pixel centres and borders.
std::vector<std::array<double, 2>> queryPoints(std::uint32_t w, std::uint32_t h, std::mt19937_64& rng, int randomCount) {
    std::vector<std::array<double, 2>> p;
    std::uniform_real_distribution<double> ux(0.0, w), uy(0.0, h);
    for (int i = 0; i < randomCount; ++i) p.push_back({ux(rng), uy(rng)});
    p.push_back({0.0, 0.0});
    p.push_back({double(w), double(h)});
    p.push_back({0.25, h - 0.1});
    p.push_back({w - 0.3, 0.6});
    p.push_back({2.5, 3.5});  // a pixel centre
    p.push_back({3.0, 2.0});  // a pixel corner
    p.push_back({w * 0.5, 0.01});
    return p;
}

TEST(LookupLevelZero, BoxOfWidthOneIsBilinearBetweenTheFourNearestCentres) {
    const auto m = randomRgbMap();
    const LevelZero ref(m->image);
    LookupContext ctx(m->map);
    std::mt19937_64 rng(1);
    std::uniform_real_distribution<double> depth(0.0, 6.0);
    for (const auto& [rx, ry] : queryPoints(23, 17, rng, 300)) {
        const double z = depth(rng);
        // Bilinear interpolation written out: the four centres around (rx, ry),
        // those outside the image left out and the weights renormalised.
        const double fx = rx - 0.5 - std::floor(rx - 0.5), fy = ry - 0.5 - std::floor(ry - 0.5);
        const long x0 = static_cast<long>(std::floor(rx - 0.5)), y0 = static_cast<long>(std::floor(ry - 0.5));
        std::array<double, 3> sum{0, 0, 0};
        double total = 0.0;
        int used = 0;
        for (long dy = 0; dy < 2; ++dy)
            for (long dx = 0; dx < 2; ++dx) {
                const long x = x0 + dx, y = y0 + dy;
                const double w = (dx ? fx : 1.0 - fx) * (dy ? fy : 1.0 - fy);
                if (x < 0 || y < 0 || x >= 23 || y >= 17 || w == 0.0) continue;
                for (int c = 0; c < 3; ++c)
                    sum[static_cast<std::size_t>(c)] += w * ref.value(std::uint32_t(x), std::uint32_t(y), z, c);
                total += w;
                ++used;
            }
        for (double& s : sum) s /= total;
        for (PixelFilter f : {PixelFilter::Box, PixelFilter::Triangle}) {
            LookupOptions o = atTheDepth();
            o.filter = f;
            o.filterWidth = f == PixelFilter::Box ? 1.0 : 2.0;  // both documented as bilinear
            o.level = 0;
            const LookupResult r = ctx.raster(rx, ry, z, o);
            for (std::size_t c = 0; c < 3; ++c) EXPECT_NEAR(r.v[c], sum[c], 1e-12) << describe(o, rx, ry, z);
            EXPECT_EQ(r.pixelsUsed, used) << describe(o, rx, ry, z);
            EXPECT_EQ(r.channels, 3);
        }
    }
}

TEST(LookupLevelZero, HugeFootprintsCoverTheImageWithoutBlowingUp) {
    // A box far wider than the image at level 0 weighs every pixel equally:
    // the plain mean of the image, whatever the width (up to 1e300) and even
    // from far outside the image's raster.
    const auto m = randomRgbMap();
    const LevelZero ref(m->image);
    LookupContext ctx(m->map);
    const double z = 2.5;
    std::array<double, 3> mean{0, 0, 0};
    for (std::uint32_t y = 0; y < 17; ++y)
        for (std::uint32_t x = 0; x < 23; ++x)
            for (int c = 0; c < 3; ++c) mean[static_cast<std::size_t>(c)] += ref.value(x, y, z, c) / (23.0 * 17.0);
    for (double width : {1e4, 1e9, 1e300}) {
        LookupOptions o = atTheDepth();
        o.filterWidth = width;
        o.level = 0;
        const LookupResult r = ctx.raster(11.0, 8.0, z, o);
        EXPECT_EQ(r.pixelsUsed, 23 * 17) << width;
        for (std::size_t c = 0; c < 3; ++c) EXPECT_NEAR(r.v[c], mean[c], 1e-9) << width;
    }
}

TEST(LookupLevelZero, KernelsMatchTheDocumentedFormulasAtSeveralWidths) {
    const auto m = randomRgbMap();
    const LevelZero ref(m->image);
    LookupContext ctx(m->map);
    std::mt19937_64 rng(2);
    std::uniform_real_distribution<double> depth(0.0, 6.0);
    const std::vector<std::pair<PixelFilter, std::vector<double>>> widths = {
        {PixelFilter::Box, {0.3, 1.0, 1.7, 2.5, 4.0, 7.25}},
        {PixelFilter::Triangle, {1.0, 2.0, 2.6, 3.0, 5.5}},
        {PixelFilter::Gaussian, {0.5, 2.0, 3.7, 6.0, 9.0}},
    };
    int checked = 0;
    for (const auto& [filter, ws] : widths) {
        for (double w : ws) {
            for (const auto& [rx, ry] : queryPoints(23, 17, rng, 40)) {
                const double z = depth(rng);
                LookupOptions o = atTheDepth();
                o.filter = filter;
                o.filterWidth = w;
                o.level = 0;
                const Filtered want = ref.filter(filter, w, rx, ry, z);
                const LookupResult got = ctx.raster(rx, ry, z, o);
                expectMatches(got, want.v, want.used, describe(o, rx, ry, z));
                EXPECT_EQ(got.errorBound, m->map->info().levels[0].errorBound);
                ++checked;
            }
        }
    }
    EXPECT_GT(checked, 500);
}

TEST(LookupLevels, ForcedAndAutomaticLevelsFollowTheDocumentedSelection) {
    const auto m = randomRgbMap();
    LookupContext ctx(m->map);
    const auto& levels = m->map->info().levels;
    ASSERT_EQ(levels.size(), 6u);  // 23x17 12x9 6x5 3x3 2x2 1x1
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> depth(0.0, 6.0);
    for (PixelFilter filter : {PixelFilter::Box, PixelFilter::Triangle, PixelFilter::Gaussian}) {
        for (int level : {-1, 0, 1, 2, 5, 40}) {
            for (double w : {1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.5, 40.0, 300.0}) {
                for (const auto& [rx, ry] : queryPoints(23, 17, rng, 4)) {
                    const double z = depth(rng);
                    LookupOptions o = atTheDepth();
                    o.filter = filter;
                    o.filterWidth = w;
                    o.level = levelOption(level);
                    const Reference want = referenceLookup(*m->map, o, rx, ry, z);
                    const LookupResult got = ctx.raster(rx, ry, z, o);
                    const std::string where = describe(o, rx, ry, z);
                    expectMatches(got, want.v, want.used, where);
                    // The error bound is the recorded bound of the level(s) used.
                    EXPECT_EQ(got.errorBound, want.errorBound) << where;
                    if (level >= 0) {
                        EXPECT_EQ(got.errorBound, levels[std::min<std::size_t>(level, levels.size() - 1)].errorBound)
                            << where;
                    } else {
                        EXPECT_EQ(got.errorBound, std::max(levels[want.level0].errorBound,
                                                           want.blend > 0.0 ? levels[want.level1].errorBound : 0.0))
                            << where;
                    }
                }
            }
        }
    }
}

TEST(LookupLevels, ErrorBoundNamesTheLevelsUsed) {
    const auto m = smoothMonoMap();
    LookupContext ctx(m->map);
    const auto& levels = m->map->info().levels;
    ASSERT_EQ(levels.size(), 8u);
    // Bounds strictly increase with the level (the tolerance is > 2^-25).
    for (std::size_t l = 1; l < levels.size(); ++l) EXPECT_GT(levels[l].errorBound, levels[l - 1].errorBound);
    LookupOptions o = atTheDepth();
    for (int l = 0; l < 8; ++l) {
        o.level = l;
        EXPECT_EQ(ctx.raster(20.3, 17.9, 2.0, o).errorBound, levels[l].errorBound) << "level " << l;
    }
    o.level = 100;
    EXPECT_EQ(ctx.raster(20.3, 17.9, 2.0, o).errorBound, levels.back().errorBound);
    o.level = std::nullopt;
    for (PixelFilter f : {PixelFilter::Box, PixelFilter::Triangle, PixelFilter::Gaussian}) {
        o.filter = f;
        const double minW = minimumWidth(f);
        for (int k = 0; k < 6; ++k) {
            o.filterWidth = minW * std::ldexp(1.0, k);  // exactly level k: no blend
            EXPECT_EQ(ctx.raster(20.3, 17.9, 2.0, o).errorBound, levels[k].errorBound) << "width " << o.filterWidth;
            o.filterWidth = minW * std::ldexp(1.5, k);  // between k and k + 1
            EXPECT_EQ(ctx.raster(20.3, 17.9, 2.0, o).errorBound, levels[k + 1].errorBound) << "width " << o.filterWidth;
        }
        o.filterWidth = 1e6;  // beyond the coarsest level
        EXPECT_EQ(ctx.raster(20.3, 17.9, 2.0, o).errorBound, levels.back().errorBound);
        o.filterWidth = 0.1;  // below the minimum
        EXPECT_EQ(ctx.raster(20.3, 17.9, 2.0, o).errorBound, levels[0].errorBound);
    }
}

// Automatic level selection on smooth maps against level-0 brute force.
//
// The slack: a lookup at level L is a convex combination of level-L pixels,
// each within errorBound(L) of the area average of the level-0 pixels under it,
// and the trilinear blend is a convex combination of two levels. Every level-0
// pixel that contributes lies within R = max(w/2, minW * 2^(L-1)) + 2^L
// level-0 pixels (Chebyshev) of the lookup point (filter radius at level L plus
// one level-L pixel), for the levels used; the brute-force level-0 value is a
// convex combination of pixels within w/2 + 1. So both are in [min, max] of the
// level-0 values in that window, and
//   |auto - level0| <= errorBound + (max - min of level-0 values within R).
// The oscillation is computed per query from the level-0 functions. On the
// smooth 128 x 96 map (values change by about 0.01-0.02 per pixel) it averages
// about 0.09 (the test requires <= 0.1, so the map stays smooth enough to be
// meaningful), while the observed differences stay below 30% of the bound.
// Exact agreement with the documented level choice and blend is checked
// separately (ForcedAndAutomaticLevelsFollowTheDocumentedSelection); this test
// ties the coarser levels back to level 0. A second map, constant over x and y,
// has no oscillation at all: there the bound is errorBound alone.
void checkAutomaticAgainstLevelZero(const OpenMap& m, double maxMeanSlack) {
    const LevelZero ref(m.image);
    LookupContext ctx(m.map);
    const auto& levels = m.map->info().levels;
    std::mt19937_64 rng(4);
    std::uniform_real_distribution<double> depth(0.5, 5.5);
    double slackSum = 0.0, worstRatio = 0.0;
    int n = 0;
    for (PixelFilter filter : {PixelFilter::Box, PixelFilter::Triangle, PixelFilter::Gaussian}) {
        for (double w : {1.0, 2.0, 3.0, 4.5, 6.0, 8.0}) {
            for (const auto& [rx, ry] : queryPoints(m.image.width, m.image.height, rng, 25)) {
                const double z = depth(rng);
                LookupOptions o = atTheDepth();
                o.filter = filter;
                o.filterWidth = w;
                const Reference sel = referenceLookup(*m.map, o, rx, ry, z);
                const LookupResult got = ctx.raster(rx, ry, z, o);
                const Filtered exact = ref.filter(filter, w, rx, ry, z);
                const double minW = minimumWidth(filter), width = std::max(w, minW);
                double radius = width / 2 + 1.0;
                for (unsigned l : {sel.level0, sel.level1})
                    radius = std::max(radius, std::max(width / 2, minW * std::ldexp(1.0, int(l) - 1)) + std::ldexp(1.0, int(l)));
                std::array<double, 3> lo{1, 1, 1}, hi{0, 0, 0};
                const auto first = [&](double c) { return static_cast<std::uint32_t>(std::max(0.0, std::floor(c - radius))); };
                for (std::uint32_t y = first(ry); y < m.image.height; ++y) {
                    if (y + 0.5 - ry > radius) break;
                    if (std::abs(y + 0.5 - ry) > radius) continue;
                    for (std::uint32_t x = first(rx); x < m.image.width; ++x) {
                        if (x + 0.5 - rx > radius) break;
                        if (std::abs(x + 0.5 - rx) > radius) continue;
                        for (std::size_t c = 0; c < 3; ++c) {
                            const double v = ref.value(x, y, z, int(c));
                            lo[c] = std::min(lo[c], v);
                            hi[c] = std::max(hi[c], v);
                        }
                    }
                }
                for (std::size_t c = 0; c < 3; ++c) {
                    const double slack = hi[c] - lo[c];
                    const double diff = std::abs(got.v[c] - exact.v[c]);
                    EXPECT_LE(diff, got.errorBound + slack + 1e-12)
                        << describe(o, rx, ry, z) << " channel " << c << " slack " << slack;
                    slackSum += slack;
                    if (slack + got.errorBound > 0) worstRatio = std::max(worstRatio, diff / (slack + got.errorBound));
                    ++n;
                }
                EXPECT_LE(got.errorBound, levels[std::min<std::size_t>(levels.size() - 1, 3)].errorBound);
            }
        }
    }
    EXPECT_LE(slackSum / n, maxMeanSlack) << "the map is not smooth enough for a meaningful comparison";
    ::testing::Test::RecordProperty("mean_slack", std::to_string(slackSum / n));
    ::testing::Test::RecordProperty("worst_diff_over_bound", std::to_string(worstRatio));
}

TEST(LookupAutomatic, SmoothMapIsWithinErrorBoundPlusFilterSlackOfLevelZero) {
    const auto m = smoothMonoMap();
    checkAutomaticAgainstLevelZero(*m, 0.1);
}

TEST(LookupAutomatic, ConstantMapIsWithinErrorBoundOfLevelZero) {
    WriterOptions o;
    o.tileSize = 4;
    o.channels = 3;
    o.tolerance = 0.004;
    const VisibilityFunction f = smoothPixel(3, 7, 16, 16, 3);
    const auto m = writeAndOpen(dsm::test::makeImage(27, 19, [&](std::uint32_t, std::uint32_t) { return f; }), o);
    checkAutomaticAgainstLevelZero(*m, 0.0);
}

TEST(LookupSpace, PointsOutsideTheMapAreLit) {
    const auto m = randomRgbMap();
    LookupContext ctx(m->map);
    const std::vector<std::array<double, 2>> outside = {
        {-0.2, 5.0}, {23.1, 5.0}, {5.0, -0.01}, {5.0, 17.5}, {-3.0, -3.0}, {-1e6, 1e6}, {24.0, 18.0}, {-0.5, 8.5}};
    for (const auto& [rx, ry] : outside) {
        for (PixelFilter f : {PixelFilter::Box, PixelFilter::Triangle, PixelFilter::Gaussian}) {
            for (double w : {1.0, 3.0, 9.0}) {
                for (int level : {-1, 0, 2}) {
                    LookupOptions o = atTheDepth();
                    o.filter = f;
                    o.filterWidth = w;
                    o.level = levelOption(level);
                    const LookupResult r = ctx.raster(rx, ry, 100.0, o);
                    const std::string where = describe(o, rx, ry, 100.0);
                    EXPECT_EQ(r.v, (std::array<double, 3>{1.0, 1.0, 1.0})) << where;
                    EXPECT_EQ(r.pixelsUsed, 0) << where;
                    EXPECT_EQ(r.errorBound, 0.0) << where;
                    EXPECT_EQ(r.channels, 3) << where;
                }
            }
        }
    }
    // A point inside, deep behind everything, is not lit: the map holds shadow.
    EXPECT_LT(ctx.raster(11.5, 8.5, 100.0).v[0], 1.0);
}

TEST(LookupChannels, MonochromeMapsAndMonochromePixelsReplicate) {
    // RGB map: left half monochrome pixels, right half RGB pixels with distinct channels.
    std::mt19937_64 rng(6);
    Image image = dsm::test::makeImage(16, 8, [&](std::uint32_t x, std::uint32_t y) {
        return x < 8 ? dsm::test::randomFunction(rng, 1, false, 1, 5) : smoothPixel(x, y, 16, 8, 3);
    });
    WriterOptions o;
    o.tileSize = 4;
    o.channels = 3;
    const auto m = writeAndOpen(image, o);
    const LevelZero ref(m->image);
    LookupContext ctx(m->map);
    LookupOptions lo = atTheDepth();
    lo.level = 0;
    bool distinct = false;
    for (double z = 0.25; z < 6.0; z += 0.25) {
        const LookupResult mono = ctx.raster(3.3, 4.1, z, lo);  // footprint within the monochrome half
        EXPECT_EQ(mono.channels, 3);
        EXPECT_EQ(mono.v[0], mono.v[1]);
        EXPECT_EQ(mono.v[0], mono.v[2]);
        expectMatches(mono, ref.filter(PixelFilter::Box, 1.0, 3.3, 4.1, z).v, 4, "mono half");
        const LookupResult rgb = ctx.raster(12.7, 4.2, z, lo);
        expectMatches(rgb, ref.filter(PixelFilter::Box, 1.0, 12.7, 4.2, z).v, 4, "rgb half");
        distinct = distinct || rgb.v[0] != rgb.v[1] || rgb.v[1] != rgb.v[2];
        lo.filterWidth = 4.0;  // straddling both halves
        const Filtered both = ref.filter(PixelFilter::Box, 4.0, 8.1, 4.0, z);
        expectMatches(ctx.raster(8.1, 4.0, z, lo), both.v, both.used, "both");
        lo.filterWidth = 1.0;
    }
    EXPECT_TRUE(distinct);

    // Monochrome map: one channel, v[1] = v[2] = v[0].
    const auto mm = smoothMonoMap();
    LookupContext mctx(mm->map);
    for (double z = 0.5; z < 6.0; z += 0.5) {
        const LookupResult r = mctx.raster(30.2, 20.7, z, atTheDepth());
        EXPECT_EQ(r.channels, 1);
        EXPECT_EQ(r.v[1], r.v[0]);
        EXPECT_EQ(r.v[2], r.v[0]);
    }
}

// Rigid world-to-light transform: rotation about y by `a`, then about x by
// `b`, then a translation.
dsm::LightCamera rigidCamera(dsm::Projection projection, double a, double b, std::array<double, 3> t,
                             std::array<double, 4> window) {
    const double ca = std::cos(a), sa = std::sin(a), cb = std::cos(b), sb = std::sin(b);
    // R = Rx(b) * Ry(a)
    const double r[3][3] = {{ca, 0, sa}, {sb * sa, cb, -sb * ca}, {-cb * sa, sb, cb * ca}};
    dsm::LightCamera cam;
    cam.projection = projection;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) cam.worldToLight[static_cast<std::size_t>(4 * i + j)] = r[i][j];
        cam.worldToLight[static_cast<std::size_t>(4 * i + 3)] = t[static_cast<std::size_t>(i)];
    }
    cam.screenWindow = window;
    return cam;
}

// Options of a small map seen through `camera`, for the lookups in world and
// light space.
WriterOptions cameraMapOptions(int channels, const dsm::LightCamera& camera) {
    WriterOptions o;
    o.tileSize = 8;
    o.channels = channels;
    o.tolerance = 0.001;
    o.camera = camera;
    return o;
}

// Light point -> world point through the inverse of a rigid transform.
std::array<double, 3> lightToWorld(const dsm::LightCamera& cam, const std::array<double, 3>& l) {
    const auto& m = cam.worldToLight;
    std::array<double, 3> d{l[0] - m[3], l[1] - m[7], l[2] - m[11]};
    std::array<double, 3> w{};
    for (std::size_t j = 0; j < 3; ++j) w[j] = m[j] * d[0] + m[4 + j] * d[1] + m[8 + j] * d[2];
    return w;
}

TEST(LookupSpace, WorldAndLightAgreeWithRasterForBothProjections) {
    for (dsm::Projection projection : {dsm::Projection::Perspective, dsm::Projection::Orthographic}) {
        SCOPED_TRACE(projection == dsm::Projection::Perspective ? "perspective" : "orthographic");
        const WriterOptions o = cameraMapOptions(
            3, rigidCamera(projection, 0.5, -0.3, {0.25, -1.5, 0.75},
                           projection == dsm::Projection::Perspective ? std::array<double, 4>{-0.6, 0.4, -0.35, 0.45}
                                                                      : std::array<double, 4>{-3.0, 5.0, -2.0, 4.0}));
        const auto m = writeAndOpen(smoothImage(40, 30, 3), o);
        LookupContext ctx(m->map);
        const dsm::LightCamera& cam = m->map->info().camera;
        const auto& win = cam.screenWindow;
        std::mt19937_64 rng(7);
        std::uniform_real_distribution<double> ux(0.0, 40.0), uy(0.0, 30.0), uz(0.5, 5.5);
        int shadowed = 0;
        for (int i = 0; i < 200; ++i) {
            const double rx = ux(rng), ry = uy(rng), z = uz(rng);
            // Raster -> screen -> light space, by the formulas of map_info.h.
            const double sx = win[0] + rx / 40.0 * (win[1] - win[0]);
            const double sy = win[3] - ry / 30.0 * (win[3] - win[2]);
            const std::array<double, 3> light = projection == dsm::Projection::Perspective
                                                    ? std::array<double, 3>{sx * z, sy * z, z}
                                                    : std::array<double, 3>{sx, sy, z};
            const std::array<double, 3> world = lightToWorld(cam, light);
            // Our inversion is right: the camera maps the world point back.
            const std::array<double, 3> back = cam.worldToLightSpace(world);
            double bx, by, bz;
            ASSERT_TRUE(cam.lightToRaster(back, 40, 30, bx, by, bz));
            ASSERT_NEAR(bx, rx, 1e-9);
            ASSERT_NEAR(by, ry, 1e-9);
            ASSERT_NEAR(bz, z, 1e-9);
            for (double w : {1.0, 3.0}) {
                LookupOptions lo = atTheDepth();
                lo.filterWidth = w;
                lo.filter = PixelFilter::Triangle;
                const LookupResult r = ctx.raster(rx, ry, z, lo);
                const LookupResult viaLight = ctx.light(light, lo);
                const LookupResult viaWorld = ctx.world(world, lo);
                for (std::size_t c = 0; c < 3; ++c) {
                    EXPECT_NEAR(viaLight.v[c], r.v[c], 1e-9);
                    EXPECT_NEAR(viaWorld.v[c], r.v[c], 1e-9);
                }
                EXPECT_EQ(viaWorld.pixelsUsed, r.pixelsUsed);
                EXPECT_EQ(viaWorld.errorBound, r.errorBound);
                shadowed += r.v[0] < 0.99 ? 1 : 0;
            }
        }
        EXPECT_GT(shadowed, 100);  // the comparison is not between lit points only
        if (projection == dsm::Projection::Perspective) {
            // Behind the light: no raster position, lit.
            const LookupResult behind = ctx.light({0.1, 0.1, -2.0});
            EXPECT_EQ(behind.v, (std::array<double, 3>{1.0, 1.0, 1.0}));
            EXPECT_EQ(behind.pixelsUsed, 0);
            const LookupResult atLight = ctx.light({0.0, 0.0, 0.0});
            EXPECT_EQ(atLight.v, (std::array<double, 3>{1.0, 1.0, 1.0}));
            EXPECT_EQ(ctx.world(lightToWorld(cam, {0.2, -0.1, -1.0})).v, (std::array<double, 3>{1.0, 1.0, 1.0}));
        }
        // Outside the screen window: lit.
        const LookupResult off = ctx.light(projection == dsm::Projection::Perspective
                                               ? std::array<double, 3>{5.0, 0.0, 1.0}
                                               : std::array<double, 3>{-10.0, 0.0, 3.0});
        EXPECT_EQ(off.v, (std::array<double, 3>{1.0, 1.0, 1.0}));
    }
}

// A file may hold any finite camera, and a finite point may then land beyond
// double range in light space: such a point is outside the map, lit, and no
// lookup throws for it. Only a point the caller passes non-finite is an
// argument error.
TEST(LookupSpace, FinitePointsThatAnExtremeCameraCarriesBeyondDoubleRangeAreLit) {
    for (dsm::Projection projection : {dsm::Projection::Perspective, dsm::Projection::Orthographic}) {
        SCOPED_TRACE(projection == dsm::Projection::Perspective ? "perspective" : "orthographic");
        dsm::LightCamera camera = rigidCamera(projection, 0.0, 0.0, {0.0, 0.0, 1.0}, {-1.0, 1.0, -1.0, 1.0});
        camera.worldToLight[1] = -1.6e264;  // x depends on y, enormously
        camera.worldToLight[10] = 1e308;    // and depth on z
        const WriterOptions o = cameraMapOptions(1, camera);
        const auto m = writeAndOpen(smoothImage(16, 16, 1), o);
        LookupContext ctx(m->map);
        LookupOptions wide;
        wide.filter = PixelFilter::Gaussian;
        wide.filterWidth = 3.0;
        for (const std::array<double, 3>& p : std::vector<std::array<double, 3>>{
                 {0.1, 1e100, 1.5}, {0.0, 1e200, 0.5}, {0.0, 0.0, 10.0}, {0.0, 0.0, -10.0}}) {
            for (const LookupOptions& lo : {LookupOptions{}, wide}) {
                LookupResult r;
                ASSERT_NO_THROW(r = ctx.world(p, lo)) << p[0] << "," << p[1] << "," << p[2];
                EXPECT_EQ(r.v, (std::array<double, 3>{1.0, 1.0, 1.0}));
                EXPECT_EQ(r.pixelsUsed, 0);
            }
        }
        // The camera itself still works for ordinary points: inside, shadowed.
        EXPECT_LT(ctx.world({0.0, 0.0, 0.5e-308}, atTheDepth()).v[0], 1.0);
        for (const std::array<double, 3>& bad : std::vector<std::array<double, 3>>{
                 {std::nan(""), 0.0, 1.0}, {0.0, HUGE_VAL, 1.0}, {0.0, 0.0, -HUGE_VAL}}) {
            try {
                (void)ctx.world(bad);
                ADD_FAILURE() << "a non-finite world point was looked up";
            } catch (const dsm::Error& e) {
                EXPECT_EQ(e.code(), dsm::ErrorCode::argument);
                EXPECT_NE(std::string(e.what()).find("world-space point"), std::string::npos) << e.what();
            }
            EXPECT_THROW((void)ctx.light(bad), dsm::Error);
        }
    }
}

TEST(LookupBias, BiasShiftsTheQueryDepth) {
    const auto m = smoothMonoMap();
    LookupContext ctx(m->map);
    std::mt19937_64 rng(8);
    std::uniform_real_distribution<double> ux(0.0, 128.0), uy(0.0, 96.0), uz(0.5, 5.5), ub(-0.5, 1.0);
    int raised = 0;
    for (int i = 0; i < 300; ++i) {
        const double rx = ux(rng), ry = uy(rng), z = uz(rng), bias = ub(rng);
        LookupOptions biased, plain;
        biased.bias = bias;
        plain.bias = 0.0;
        biased.filterWidth = plain.filterWidth = 2.5;
        const LookupResult a = ctx.raster(rx, ry, z, biased);
        const LookupResult b = ctx.raster(rx, ry, z - bias, plain);
        EXPECT_EQ(a.v, b.v);
        EXPECT_EQ(a.pixelsUsed, b.pixelsUsed);
        const LookupResult unbiased = ctx.raster(rx, ry, z, plain);
        // V never increases with depth: a positive bias can only raise it.
        if (bias > 0) {
            EXPECT_GE(a.v[0], unbiased.v[0]);
        } else {
            EXPECT_LE(a.v[0], unbiased.v[0]);
        }
        raised += a.v[0] > unbiased.v[0] + 1e-3 ? 1 : 0;
    }
    EXPECT_GT(raised, 50);
    // A bias as large as the depth moves the query in front of every vertex.
    const VisibilityFunction& f = m->image.at(10, 10);
    LookupOptions atCentre;
    atCentre.level = 0;
    atCentre.bias = 0.0;
    EXPECT_LT(ctx.raster(10.5, 10.5, f.z(2), atCentre).v[0], 1.0);
    atCentre.bias = f.z(2);
    EXPECT_EQ(ctx.raster(10.5, 10.5, f.z(2), atCentre).v[0], 1.0);
}

// --- Concurrency and the cache ------------------------------------------

struct Query {
    double rx, ry, z;
    LookupOptions options;
};

std::vector<Query> randomQueries(std::uint32_t w, std::uint32_t h, int n, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> ux(-3.0, w + 3.0), uy(-3.0, h + 3.0), uz(0.0, 6.0), uw(0.5, 12.0);
    std::uniform_int_distribution<int> filter(0, 2), level(-3, 3);
    std::vector<Query> q(static_cast<std::size_t>(n));
    for (Query& x : q) {
        x.rx = ux(rng);
        x.ry = uy(rng);
        x.z = uz(rng);
        x.options.filter = static_cast<PixelFilter>(filter(rng));
        x.options.filterWidth = uw(rng);
        x.options.level = levelOption(level(rng));
        x.options.bias = 0.01 * static_cast<double>(filter(rng));
    }
    return q;
}

// Decoded size of every tile of every level of a file: through a cache of
// budget 0, which keeps only the most recent tile, so bytesInUse is its size.
std::vector<std::size_t> decodedTileBytes(const std::string& path) {
    dsm::ReaderOptions ro;
    ro.cache = dsm::TileCache::create(0);
    const auto map = DeepShadowMap::open(path, ro);
    std::vector<std::size_t> sizes;
    const std::uint32_t T = map->info().tileSize;
    for (unsigned l = 0; l < map->info().levels.size(); ++l)
        for (std::uint32_t ty = 0; ty < map->info().levels[l].tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < map->info().levels[l].tilesX; ++tx) {
                (void)map->pixel(l, tx * T, ty * T);
                sizes.push_back(ro.cache->stats().bytesInUse);
            }
    return sizes;
}

TEST(LookupThreads, EightThreadsWithOwnContextsAgreeExactlyWithOneThread) {
    TempDir dir;
    const auto path = dir / "shared.dsm";
    WriterOptions o;
    o.tileSize = 8;
    o.channels = 3;
    o.maxLayers = 2;
    o.tolerance = 0.005;
    const Image image = randomImage(48, 40, 9);
    dsm::test::writeMap(path, o, image);
    const std::vector<std::size_t> sizes = decodedTileBytes(path.string());
    const std::size_t largest = *std::max_element(sizes.begin(), sizes.end());
    dsm::ReaderOptions ro;
    ro.cache = dsm::TileCache::create(3 * largest);  // a few tiles: constant eviction
    const auto map = DeepShadowMap::open(path.string(), ro);
    const std::vector<Query> queries = randomQueries(48, 40, 800, 10);

    std::vector<LookupResult> expected(queries.size());
    {
        LookupContext ctx(map);
        for (std::size_t i = 0; i < queries.size(); ++i)
            expected[i] = ctx.raster(queries[i].rx, queries[i].ry, queries[i].z, queries[i].options);
    }
    ro.cache->resetStats();
    constexpr int kThreads = 8;
    std::vector<std::vector<LookupResult>> results(kThreads, std::vector<LookupResult>(queries.size()));
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
        threads.emplace_back([&, t] {
            LookupContext ctx(map);
            // Each thread takes the queries in its own order, so the threads'
            // cursors and tiles differ at every moment.
            std::vector<std::size_t> order(queries.size());
            for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
            std::mt19937_64 rng(100 + static_cast<std::uint64_t>(t));
            if (t > 0) std::shuffle(order.begin(), order.end(), rng);
            for (std::size_t i : order)
                results[static_cast<std::size_t>(t)][i] =
                    ctx.raster(queries[i].rx, queries[i].ry, queries[i].z, queries[i].options);
        });
    }
    for (std::thread& th : threads) th.join();
    int mismatches = 0;
    for (int t = 0; t < kThreads; ++t)
        for (std::size_t i = 0; i < queries.size(); ++i) {
            const LookupResult& a = expected[i];
            const LookupResult& b = results[static_cast<std::size_t>(t)][i];
            if (a.v != b.v || a.pixelsUsed != b.pixelsUsed || a.errorBound != b.errorBound || a.channels != b.channels)
                ++mismatches;
        }
    EXPECT_EQ(mismatches, 0);
    const dsm::TileCacheStats s = ro.cache->stats();
    EXPECT_GT(s.evictions, 0u) << "the cache was not small enough to be exercised";
    EXPECT_LE(s.peakBytesInUse, ro.cache->budget() + largest);
}

TEST(ReaderCache, RandomPixelAccessStaysWithinTheBudget) {
    TempDir dir;
    const auto path = dir / "big.dsm";
    WriterOptions o;
    o.tileSize = 8;
    o.counts = true;
    o.tolerance = 0.02;
    std::mt19937_64 rng(11);
    const Image image = dsm::test::makeImage(96, 80, [&](std::uint32_t, std::uint32_t) {
        return dsm::test::randomFunction(rng, 1, true, 1, 8);
    });
    dsm::test::writeMap(path, o, image);
    const std::vector<std::size_t> sizes = decodedTileBytes(path.string());
    const std::size_t total = std::accumulate(sizes.begin(), sizes.end(), std::size_t(0));
    const std::size_t largest = *std::max_element(sizes.begin(), sizes.end());
    const std::size_t budget = total / 12;
    ASSERT_GE(total, 10 * budget);
    ASSERT_GT(budget, largest);  // room for a few tiles

    dsm::ReaderOptions ro;
    ro.cache = dsm::TileCache::create(budget);
    const auto map = DeepShadowMap::open(path.string(), ro);
    const auto& levels = map->info().levels;
    EXPECT_EQ(&map->cache(), ro.cache.get());
    std::uniform_int_distribution<unsigned> level(0, static_cast<unsigned>(levels.size() - 1));
    std::uint64_t accesses = 0;
    for (int i = 0; i < 4000; ++i) {
        const unsigned l = level(rng) % 3 == 0 ? level(rng) : 0;  // mostly level 0
        const std::uint32_t x = std::uniform_int_distribution<std::uint32_t>(0, levels[l].width - 1)(rng);
        const std::uint32_t y = std::uniform_int_distribution<std::uint32_t>(0, levels[l].height - 1)(rng);
        {
            const dsm::PixelFunction p = map->pixel(l, x, y);
            if (l == 0) {
                ASSERT_TRUE(dsm::test::sameFunction(p.view(), image.at(x, y), true)) << x << "," << y;
            }
        }
        ++accesses;
        const dsm::TileCacheStats s = ro.cache->stats();
        ASSERT_LE(s.bytesInUse, budget + largest) << "after access " << accesses;
        ASSERT_EQ(s.hits + s.misses, accesses);
    }
    const dsm::TileCacheStats s = ro.cache->stats();
    EXPECT_GT(s.evictions, 0u);
    EXPECT_GT(s.hits, 0u);
    EXPECT_EQ(s.tilesRead, s.misses);
    EXPECT_LE(s.peakBytesInUse, budget + largest);
    // The directory is not read through the cache.
    (void)map->tile(0, 1, 1);
    EXPECT_EQ(ro.cache->stats().hits + ro.cache->stats().misses, accesses);
}

}  // namespace
