// Mip levels of written maps (spec section 5; Lokovic & Veach §5.3): every
// pixel of level L > 0 lies within the level's recorded tolerance of the exact
// coverage-weighted average of the light-centre functions of the stored level
// L-1 pixels under it (weights = level-0 pixels each child covers); every level
// lies within its recorded error bound of the exact area average of the level-0
// functions it covers, the 1 x 1 top of a full odd-sized pyramid included;
// counts add up; all-monochrome blocks stay monochrome; empty blocks stay empty.
#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <random>
#include <ostream>
#include <string>
#include <vector>

#include "map_fixtures.h"
#include "oracle.h"
#include "temp_dir.h"

namespace {

using dsm::DeepShadowMap;
using dsm::LevelInfo;
using dsm::VisibilityFunction;
using dsm::VisibilityView;
using dsm::WriterOptions;
using dsm::test::Image;
using dsm::test::TempDir;

constexpr double kSlack = 1e-7;  // float rounding of the stored values (2^-25 ~ 3e-8) and double sums

using PixelMaker = std::function<VisibilityFunction(std::mt19937_64&, std::uint32_t, std::uint32_t)>;

struct MipCase {
    std::string name;
    std::uint32_t width = 1, height = 1, tileSize = 4;
    int channels = 1;
    bool counts = false;
    int maxLayers = 1;
    double tolerance = 0.01;
    double factor = 0.5;
    PixelMaker pixel;
};

// gtest prints parameters by name.
void PrintTo(const MipCase& c, std::ostream* os) { *os << c.name; }

// Light-centre value and left limit of a (single-layer, possibly monochrome)
// function at z for channel c of a `channels`-channel average.
double valueOf(const VisibilityFunction& f, double z, int c) {
    return dsm::test::valueAt(f, z, std::min(c, f.channels() - 1));
}
double leftOf(const VisibilityFunction& f, double z, int c) {
    return dsm::test::leftLimit(f, z, std::min(c, f.channels() - 1));
}

// Largest |approx - exact| where exact is the weighted average of `inputs`
// (single-layer functions with `channels` channels): at the vertices of the
// exact average (tests::naiveAverage: left limits and values), at approx's own
// vertices, between consecutive probes and beyond the last. Both sides are
// piecewise linear between these depths, so this is the L-infinity distance.
double deviation(const std::vector<VisibilityFunction>& inputs, const std::vector<double>& weights, int channels,
                 const VisibilityFunction& approx) {
    const std::vector<dsm::test::ExactVertex> exact = dsm::test::naiveAverage(inputs, weights, channels);
    double total = 0.0;
    for (double w : weights) total += w;
    auto direct = [&](double z, int c, bool left) {
        double s = 0.0;
        for (std::size_t k = 0; k < inputs.size(); ++k)
            s += weights[k] * (left ? dsm::test::leftLimit(inputs[k], z, c) : dsm::test::valueAt(inputs[k], z, c));
        return s / total;
    };
    double worst = 0.0;
    std::vector<double> probes;
    for (const dsm::test::ExactVertex& v : exact) {
        probes.push_back(v.z);
        for (int c = 0; c < channels; ++c) {
            worst = std::max(worst, std::abs(v.left[c] - leftOf(approx, v.z, c)));
            worst = std::max(worst, std::abs(v.right[c] - valueOf(approx, v.z, c)));
        }
    }
    for (float z : approx.depths()) probes.push_back(z);
    std::sort(probes.begin(), probes.end());
    probes.erase(std::unique(probes.begin(), probes.end()), probes.end());
    const std::size_t n = probes.size();
    for (std::size_t i = 0; i + 1 < n; ++i) probes.push_back(0.5 * (probes[i] + probes[i + 1]));
    if (n > 0) {
        probes.push_back(probes[n - 1] + 1.0);
        probes.push_back(probes[0] * 0.5);
    }
    for (double z : probes)
        for (int c = 0; c < channels; ++c) {
            worst = std::max(worst, std::abs(direct(z, c, true) - leftOf(approx, z, c)));
            worst = std::max(worst, std::abs(direct(z, c, false) - valueOf(approx, z, c)));
        }
    return worst;
}

std::uint64_t layerZeroCount(const VisibilityView& f) {
    std::uint64_t total = 0;
    for (std::size_t i = 0; i < f.lightEnd(); ++i) total += f.count(i);
    return total;
}

Image makeImage(const MipCase& c) {
    std::mt19937_64 rng(0xC0FFEEu + c.width * 17u + c.height);
    return dsm::test::makeImage(c.width, c.height, [&](std::uint32_t x, std::uint32_t y) { return c.pixel(rng, x, y); });
}

WriterOptions optionsFor(const MipCase& c) {
    WriterOptions o;
    o.tileSize = c.tileSize;
    o.channels = c.channels;
    o.counts = c.counts;
    o.maxLayers = c.maxLayers;
    o.tolerance = c.tolerance;
    o.levelToleranceFactor = c.factor;
    o.mipLevels.reset();  // full pyramid
    return o;
}

class Mipmap : public ::testing::TestWithParam<MipCase> {
protected:
    void SetUp() override {
        const MipCase& c = GetParam();
        image_ = makeImage(c);
        path_ = (dir_ / "map.dsm").string();
        dsm::test::writeMap(path_, optionsFor(c), image_, 11);
        map_ = DeepShadowMap::open(path_);
        ASSERT_EQ(map_->info().levels.size(), dsm::fullLevelCount(c.width, c.height));
    }
    TempDir dir_;
    Image image_;
    std::string path_;
    std::shared_ptr<DeepShadowMap> map_;
};

TEST_P(Mipmap, EachLevelIsWithinItsToleranceOfTheExactAverageOfTheStoredFinerLevel) {
    const MipCase& c = GetParam();
    const auto& levels = map_->info().levels;
    const int channels = c.channels;
    for (unsigned l = 1; l < levels.size(); ++l) {
        const LevelInfo& L = levels[l];
        const LevelInfo& F = levels[l - 1];
        double worstSeen = 0.0;
        for (std::uint32_t py = 0; py < L.height; ++py) {
            for (std::uint32_t px = 0; px < L.width; ++px) {
                std::vector<VisibilityFunction> inputs;
                std::vector<double> weights;
                bool anyVertices = false, anyRgb = false;
                std::uint64_t childCounts = 0;
                for (std::uint32_t dy = 0; dy < 2; ++dy)
                    for (std::uint32_t dx = 0; dx < 2; ++dx) {
                        const std::uint32_t cx = 2 * px + dx, cy = 2 * py + dy;
                        if (cx >= F.width || cy >= F.height) continue;
                        const dsm::PixelFunction child = map_->pixel(l - 1, cx, cy);
                        inputs.push_back(dsm::test::lightCentre(child.view(), channels));
                        weights.push_back(dsm::test::coveredPixels(cx, l - 1, c.width) *
                                          dsm::test::coveredPixels(cy, l - 1, c.height));
                        anyVertices = anyVertices || !child->empty();
                        anyRgb = anyRgb || child->channels() == 3;
                        childCounts += layerZeroCount(child.view());
                    }
                const dsm::PixelFunction parent = map_->pixel(l, px, py);
                const VisibilityFunction approx = parent->toFunction();
                const std::string where = "level " + std::to_string(l) + " pixel " + std::to_string(px) + "," +
                                          std::to_string(py);
                if (!anyVertices) {
                    EXPECT_TRUE(approx.empty()) << where << ": the average of empty pixels is empty";
                    continue;
                }
                EXPECT_EQ(approx.layerCount(), 1u) << where;
                if (!anyRgb) {
                    EXPECT_EQ(approx.channels(), 1) << where << ": monochrome children, RGB parent";
                }
                if (c.counts) {
                    EXPECT_EQ(approx.totalCount(), childCounts) << where << ": counts do not add up";
                }
                const double d = deviation(inputs, weights, channels, approx);
                worstSeen = std::max(worstSeen, d);
                EXPECT_LE(d, L.tolerance + kSlack) << where << " (tolerance " << L.tolerance << ")";
            }
        }
        RecordProperty("worst_level_" + std::to_string(l), std::to_string(worstSeen));
    }
}

// Every pixel of every level against the exact area average of the level-0
// functions it covers, at depths spread over the map's range and at the
// pixel's own vertices: within the level's recorded error bound.
TEST_P(Mipmap, EveryLevelIsWithinItsErrorBoundOfTheAreaAverageOfLevelZero) {
    const MipCase& c = GetParam();
    const auto& levels = map_->info().levels;
    const int channels = c.channels;
    std::vector<VisibilityFunction> centre;
    centre.reserve(image_.pixels.size());
    float maxZ = 0.0f;
    for (const VisibilityFunction& f : image_.pixels) {
        centre.push_back(dsm::test::lightCentre(f, channels));
        if (!f.empty()) maxZ = std::max(maxZ, f.z(f.size() - 1));
    }
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> depth(0.0, maxZ + 0.5);
    std::vector<double> depths(24);
    for (double& z : depths) z = depth(rng);
    for (unsigned l = 1; l < levels.size(); ++l) {
        const LevelInfo& L = levels[l];
        const std::uint32_t span = 1u << l;
        for (std::uint32_t py = 0; py < L.height; ++py) {
            for (std::uint32_t px = 0; px < L.width; ++px) {
                const dsm::PixelFunction p = map_->pixel(l, px, py);
                std::vector<double> probes = depths;
                for (float z : p->depths()) probes.push_back(z);
                const std::uint32_t x1 = std::min(c.width, (px + 1) * span), y1 = std::min(c.height, (py + 1) * span);
                double worst = 0.0;
                for (double z : probes) {
                    for (int ch = 0; ch < channels; ++ch) {
                        double sum = 0.0;
                        for (std::uint32_t y = py * span; y < y1; ++y)
                            for (std::uint32_t x = px * span; x < x1; ++x)
                                sum += dsm::test::valueAt(centre[std::size_t(y) * c.width + x], z, ch);
                        const double exact = sum / (double(x1 - px * span) * double(y1 - py * span));
                        worst = std::max(worst, std::abs(exact - p->evaluate(z, std::min(ch, p->channels() - 1))));
                    }
                }
                EXPECT_LE(worst, L.errorBound + 1e-9)
                    << "level " << l << " pixel " << px << "," << py << " (error bound " << L.errorBound << ")";
            }
        }
    }
}

MipCase make(std::string name, std::uint32_t w, std::uint32_t h, std::uint32_t tile, PixelMaker pixel) {
    MipCase c;
    c.name = std::move(name);
    c.width = w;
    c.height = h;
    c.tileSize = tile;
    c.pixel = std::move(pixel);
    return c;
}

VisibilityFunction monoPixel(std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
    if ((x * 3 + y * 5) % 13 == 0) return VisibilityFunction(1);
    return dsm::test::randomFunction(rng, 1, false, 1, 9);
}

std::vector<MipCase> cases() {
    std::vector<MipCase> out;
    {
        MipCase c = make("mono_odd_37x21_tile8", 37, 21, 8, monoPixel);
        c.tolerance = 0.02;
        out.push_back(c);
    }
    {
        MipCase c = make("rgb_and_mono_19x10_tile4", 19, 10, 4, [](std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
            // RGB pixels only in the left half: the right half's blocks are all monochrome.
            if ((x + y) % 7 == 3) return VisibilityFunction(x < 8 ? 3 : 1);
            return dsm::test::randomFunction(rng, (x < 8 && (x + y) % 2 == 0) ? 3 : 1, false, 1, 6);
        });
        c.channels = 3;
        out.push_back(c);
    }
    {
        MipCase c = make("layers_counts_13x9_tile2", 13, 9, 2, [](std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
            if ((x + 2 * y) % 10 == 0) return VisibilityFunction(1, true);
            return dsm::test::randomFunction(rng, 1, true, 1 + static_cast<int>((x * y) % 3), 4);
        });
        c.counts = true;
        c.maxLayers = 3;
        c.tolerance = 0.005;
        out.push_back(c);
    }
    {
        MipCase c = make("lossless_counts_9x17_tile4", 9, 17, 4, [](std::mt19937_64& rng, std::uint32_t, std::uint32_t) {
            return dsm::test::randomFunction(rng, 1, true, 1, 7);
        });
        c.counts = true;
        c.tolerance = 0.0;
        out.push_back(c);
    }
    {
        MipCase c = make("strip_1x23_tile2_constant_tolerance", 1, 23, 2, monoPixel);
        c.tolerance = 0.03;
        c.factor = 1.0;
        out.push_back(c);
    }
    {
        MipCase c = make("rgb_layers_11x7_tile8", 11, 7, 8, [](std::mt19937_64& rng, std::uint32_t x, std::uint32_t y) {
            return dsm::test::randomFunction(rng, 3, false, 1 + static_cast<int>((x + y) % 2), 4);
        });
        c.channels = 3;
        c.maxLayers = 2;
        c.tolerance = 0.05;
        out.push_back(c);
    }
    return out;
}

INSTANTIATE_TEST_SUITE_P(Maps, Mipmap, ::testing::ValuesIn(cases()),
                         [](const ::testing::TestParamInfo<MipCase>& i) { return i.param.name; });

// The 1 x 1 top of a full pyramid over an odd-sized map is the area average of
// all level-0 light-centre functions (each level-0 pixel weighs the same),
// within the top level's error bound.
TEST(MipmapTop, CoarsestLevelOfAnOddSizedMapIsTheAreaAverage) {
    TempDir dir;
    std::mt19937_64 rng(77);
    const Image image = dsm::test::makeImage(37, 21, [&](std::uint32_t x, std::uint32_t y) {
        return dsm::test::randomFunction(rng, 1, false, 1 + static_cast<int>((x + y) % 2), 6);
    });
    WriterOptions o;
    o.tileSize = 8;
    o.maxLayers = 2;
    o.tolerance = 0.01;
    dsm::test::writeMap(dir / "odd.dsm", o, image);
    const auto map = DeepShadowMap::open((dir / "odd.dsm").string());
    const auto& levels = map->info().levels;
    ASSERT_EQ(levels.size(), 7u);  // 37x21 19x11 10x6 5x3 3x2 2x1 1x1
    ASSERT_EQ(levels.back().width, 1u);
    ASSERT_EQ(levels.back().height, 1u);
    const dsm::PixelFunction top = map->pixel(static_cast<unsigned>(levels.size() - 1), 0, 0);
    std::vector<double> depths = {0.0, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0, 100.0};
    for (float z : top->depths()) depths.push_back(z);
    double worst = 0.0;
    for (double z : depths) {
        double sum = 0.0;
        for (const VisibilityFunction& f : image.pixels) sum += dsm::test::lightCentreValue(f, z, 0);
        const double exact = sum / static_cast<double>(image.pixels.size());
        worst = std::max(worst, std::abs(top->evaluate(z) - exact));
    }
    EXPECT_LE(worst, levels.back().errorBound + 1e-9);
    // The bound is not vacuous: 7 levels of halving tolerances sum to < 0.02.
    EXPECT_LT(levels.back().errorBound, 0.02);

    // The corner pixel of level 1 covers the single level-0 pixel (36, 20).
    const dsm::PixelFunction edge = map->pixel(1, 18, 10);  // covers only level-0 pixel (36, 20)
    const VisibilityFunction only = dsm::test::lightCentre(image.at(36, 20), 1);
    for (double z : depths) EXPECT_LE(std::abs(edge->evaluate(z) - dsm::test::valueAt(only, z)), levels[1].tolerance + kSlack);
}

}  // namespace
