// The product of visibility functions (dsm/visibility_product.h) and the
// merging of maps (dsm/merge.h): the error bound of spec/merge.md measured
// against dense exact evaluation, counts, channels, steps and layers; map
// products against a map of ones and against a whole-scene build; stitching
// region builds byte for byte; the errors for maps that do not fit together.
#include <dsm/dsm.h>
#include <dsm/merge.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>
#include <dsm/soft_shadow.h>
#include <dsm/visibility_product.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace dsm::test {
namespace {

constexpr double kStoreRounding = 0x1p-25;
// Double arithmetic in the product and the oracle.
constexpr double kArithmetic = 1e-12;

// Depths at which to compare: every vertex depth of the functions, the double
// just below it (the left limit side), and 16 points inside every gap between
// consecutive depths, plus points beyond the last.
std::vector<double> probeDepths(std::span<const VisibilityView> functions) {
    std::vector<double> knots{0.0};
    for (const VisibilityView& f : functions)
        for (float z : f.depths()) knots.push_back(z);
    std::sort(knots.begin(), knots.end());
    knots.erase(std::unique(knots.begin(), knots.end()), knots.end());
    std::vector<double> probes;
    for (std::size_t i = 0; i < knots.size(); ++i) {
        probes.push_back(knots[i]);
        if (knots[i] > 0.0) probes.push_back(std::nextafter(knots[i], 0.0));
        const double next = i + 1 < knots.size() ? knots[i + 1] : knots[i] + 1.0;
        for (int k = 1; k < 16; ++k) probes.push_back(knots[i] + (next - knots[i]) * k / 16.0);
    }
    return probes;
}

// max over depths and channels of |out(z) - prod_i F_i(z)|, by the oracle.
double productError(std::span<const VisibilityView> factors, const VisibilityFunction& out, int channels) {
    std::vector<VisibilityView> all(factors.begin(), factors.end());
    all.push_back(out.view());
    double worst = 0.0;
    for (double z : probeDepths(all))
        for (int c = 0; c < channels; ++c) {
            double exact = 1.0;
            for (const VisibilityView& f : factors)
                if (!f.empty()) exact *= lightCentreValue(f, z, c);
            const double got = out.empty() ? 1.0 : out.evaluate(z, std::min(c, out.channels() - 1));
            worst = std::max(worst, std::abs(got - exact));
        }
    return worst;
}

std::uint64_t totalCount(const VisibilityView& f, bool lightCentreOnly) {
    std::uint64_t sum = 0;
    const std::size_t end = lightCentreOnly ? f.lightEnd() : f.size();
    for (std::size_t i = 0; i < end; ++i) sum += f.count(i);
    return sum;
}

// ---------------------------------------------------------------------------
// Functions

TEST(VisibilityProduct, RandomFunctionsStayWithinTheBound) {
    std::mt19937_64 rng(20251126);
    std::uniform_int_distribution<int> vertices(1, 12), factorCount(2, 3);
    std::bernoulli_distribution rgb(0.5), layered(0.2);
    const double tolerances[] = {0.0, 0.01, 0.05, 0.2};
    double worstSlack = -1.0, worstMeasured = 0.0;
    for (int trial = 0; trial < 400; ++trial) {
        std::vector<VisibilityFunction> owned;
        const int n = factorCount(rng);
        for (int i = 0; i < n; ++i)
            owned.push_back(randomFunction(rng, rgb(rng) ? 3 : 1, true, layered(rng) ? 2 : 1, vertices(rng),
                                           0.5f + 0.3f * float(i)));
        std::vector<VisibilityView> factors(owned.begin(), owned.end());
        VisibilityProductOptions options;
        options.tolerance = tolerances[trial % 4];
        options.keepCounts = true;
        const VisibilityProduct p = multiplyVisibility(factors, options);
        ASSERT_NO_THROW(p.function.validate());
        int channels = 1;
        for (const auto& f : owned) channels = std::max(channels, f.channels());
        const double bound = p.interpolationError + std::max(options.tolerance, kStoreRounding) + kArithmetic;
        const double measured = productError(factors, p.function, channels);
        ASSERT_LE(measured, bound) << "trial " << trial << " tolerance " << options.tolerance;
        // Chord errors stay under the requested limit per pairwise product.
        const double perPair = std::max(options.tolerance / 16.0, 0x1p-20);
        ASSERT_LE(p.interpolationError, (n - 1) * perPair * (1.0 + 1e-9)) << "trial " << trial;
        // Counts: every light-centre sample of every factor, once.
        std::uint64_t counted = 0;
        for (const auto& f : owned) counted += totalCount(f.view(), true);
        ASSERT_EQ(p.function.totalCount(), counted) << "trial " << trial;
        ASSERT_EQ(p.function.layerCount(), 1u);
        ASSERT_LE(p.function.size(), p.productVertices);
        worstMeasured = std::max(worstMeasured, measured);
        worstSlack = std::max(worstSlack, measured / bound);
    }
    std::cout << "[ measured ] largest |V_out - prod F| " << worstMeasured << ", largest share of the bound "
              << worstSlack << "\n";
}

TEST(VisibilityProduct, TwoRampsGiveTheParabolaWithinTheChordLimit) {
    // (1 - z)^2 on [0, 1]: both factors change over one segment, curvature 1.
    VisibilityFunction ramp(1, false);
    ramp.append(0.0f, 1.0f);
    ramp.append(1.0f, 0.0f);
    const VisibilityView factors[] = {ramp.view(), ramp.view()};
    for (double limit : {1e-2, 1e-3, 1e-4}) {
        VisibilityProductOptions options;
        options.tolerance = 0.0;
        options.maxInterpolationError = limit;
        const VisibilityProduct p = multiplyVisibility(factors, options);
        // n equal pieces with 1 / (4 n^2) <= limit (a little more for the
        // rounding of depths to float32): n + 1 vertices.
        const auto pieces = static_cast<std::size_t>(std::ceil(std::sqrt(1.0 / (4.0 * limit))));
        EXPECT_GE(p.productVertices, pieces + 1) << limit;
        EXPECT_LE(p.productVertices, pieces + 2) << limit;
        EXPECT_LE(p.interpolationError, limit);
        EXPECT_GT(p.interpolationError, 0.0);
        double worst = 0.0;
        for (int k = 0; k <= 10000; ++k) {
            const double z = k / 10000.0;
            worst = std::max(worst, std::abs(p.function.evaluate(z) - (1 - z) * (1 - z)));
        }
        EXPECT_LE(worst, p.interpolationError + kStoreRounding + kArithmetic);
        EXPECT_GT(worst, 0.5 * p.interpolationError);  // the chord error is real and measured
    }
}

TEST(VisibilityProduct, StepsMultiplyExactlyAtEveryDepth) {
    VisibilityFunction a(1, false), b(1, false);
    a.append(1.0f, 1.0f);
    a.append(1.0f, 0.5f);
    a.append(3.0f, 0.5f);
    a.append(3.0f, 0.25f);
    b.append(2.0f, 1.0f);
    b.append(2.0f, 0.5f);
    b.append(3.0f, 0.5f);
    b.append(3.0f, 0.1f);
    const VisibilityView factors[] = {a.view(), b.view()};
    const VisibilityProduct p = multiplyVisibility(factors);
    EXPECT_EQ(p.interpolationError, 0.0);
    for (double z : {0.0, 0.999, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0})
        EXPECT_NEAR(p.function.evaluate(z), a.evaluate(z) * b.evaluate(z), kStoreRounding) << z;
    EXPECT_FLOAT_EQ(p.function.evaluate(3.0), 0.025f);
    // No segment where both change: no subdivision, at most two vertices a depth.
    EXPECT_LE(p.productVertices, 2 * 3u);
}

TEST(VisibilityProduct, EmptyFunctionsAreOne) {
    std::mt19937_64 rng(7);
    const VisibilityFunction f = randomFunction(rng, 3, true, 1, 10);
    const VisibilityFunction empty(1, false), emptyRgb(3, true);
    const VisibilityView withEmpty[] = {empty.view(), f.view(), emptyRgb.view()};
    VisibilityProductOptions options;
    options.keepCounts = true;
    const VisibilityProduct p = multiplyVisibility(withEmpty, options);
    EXPECT_EQ(p.interpolationError, 0.0);
    EXPECT_LE(productError(std::span<const VisibilityView>(&withEmpty[1], 1), p.function, 3), kStoreRounding);
    EXPECT_EQ(p.function.totalCount(), f.totalCount());

    const VisibilityView onlyEmpty[] = {empty.view(), emptyRgb.view()};
    const VisibilityProduct none = multiplyVisibility(onlyEmpty);
    EXPECT_TRUE(none.function.empty());
    EXPECT_EQ(none.function.channels(), 1);
    EXPECT_TRUE(multiplyVisibility({}).function.empty());
}

TEST(VisibilityProduct, MonochromeTimesRgbMultipliesEveryChannel) {
    std::mt19937_64 rng(11);
    const VisibilityFunction mono = randomFunction(rng, 1, false, 1, 8);
    VisibilityFunction rgb(3, false);
    const float near[] = {1.0f, 0.9f, 0.8f}, far[] = {0.2f, 0.5f, 0.7f};
    rgb.append(0.6f, near);
    rgb.append(4.0f, far);
    const VisibilityView factors[] = {mono.view(), rgb.view()};
    const VisibilityProduct p = multiplyVisibility(factors);
    EXPECT_EQ(p.function.channels(), 3);
    EXPECT_LE(productError(factors, p.function, 3), p.interpolationError + kStoreRounding + kArithmetic);

    const VisibilityView monoOnly[] = {mono.view(), mono.view()};
    EXPECT_EQ(multiplyVisibility(monoOnly).function.channels(), 1);
}

TEST(VisibilityProduct, LayeredFactorsContributeTheirLightCentreFunction) {
    std::mt19937_64 rng(5);
    const VisibilityFunction layered = randomFunction(rng, 1, true, 3, 5);
    const VisibilityFunction plain = randomFunction(rng, 1, true, 1, 5, 0.7f);
    ASSERT_EQ(layered.layerCount(), 3u);
    const VisibilityView factors[] = {layered.view(), plain.view()};
    VisibilityProductOptions options;
    options.keepCounts = true;
    const VisibilityProduct p = multiplyVisibility(factors, options);
    EXPECT_EQ(p.function.layerCount(), 1u);
    EXPECT_LE(productError(factors, p.function, 1), p.interpolationError + kStoreRounding + kArithmetic);
    EXPECT_EQ(p.function.totalCount(), totalCount(layered.view(), true) + totalCount(plain.view(), true));
    // Beyond layer 0 the light-centre visibility is 0, so is the product.
    EXPECT_EQ(p.function.evaluate(layered.z(layered.layerBegin(1) - 1)), 0.0);
}

TEST(VisibilityProduct, RejectsBadOptions) {
    VisibilityProductOptions options;
    options.tolerance = -1.0;
    EXPECT_THROW(multiplyVisibility({}, options), Error);
    options.tolerance = std::nan("");
    EXPECT_THROW(multiplyVisibility({}, options), Error);
}

// ---------------------------------------------------------------------------
// Maps

WriterOptions smallMapOptions(int channels, bool counts) {
    WriterOptions w;
    w.tileSize = 8;
    w.channels = channels;
    w.counts = counts;
    w.tolerance = 0.01;
    return w;
}

std::string messageOf(const std::vector<std::string>& inputs, const std::string& output, const MergeOptions& options) {
    try {
        mergeMaps(inputs, output, options);
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}

TEST(MergeProduct, TimesAMapOfOnesKeepsTheValues) {
    TempDir dir;
    std::mt19937_64 rng(3);
    const Image image = makeImage(20, 13, [&](std::uint32_t x, std::uint32_t) {
        return x % 5 == 0 ? VisibilityFunction(3, true) : randomFunction(rng, x % 2 ? 3 : 1, true, 1, 9);
    });
    const Image ones = makeImage(20, 13, [&](std::uint32_t x, std::uint32_t y) {
        VisibilityFunction f(1, true);
        if ((x + y) % 3) {
            f.append(0.2f + 0.1f * float(y), 1.0f, 2);
            f.append(3.0f, 1.0f, 1);
        }
        return f;
    });
    writeMap(dir / "a.dsm", smallMapOptions(3, true), image);
    writeMap(dir / "ones.dsm", smallMapOptions(1, true), ones);
    MergeOptions options;
    options.tolerance = 0.0;
    const MergeReport report = mergeMaps({(dir / "a.dsm").string(), (dir / "ones.dsm").string()},
                                         (dir / "out.dsm").string(), options);
    EXPECT_EQ(report.interpolationError, 0.0);  // one factor is constant on every segment
    const auto out = DeepShadowMap::open((dir / "out.dsm").string());
    EXPECT_EQ(out->info().channels, 3);
    EXPECT_TRUE(out->info().hasCounts);
    EXPECT_EQ(out->info().levels.size(), fullLevelCount(20, 13));
    for (std::uint32_t y = 0; y < 13; ++y)
        for (std::uint32_t x = 0; x < 20; ++x) {
            const VisibilityView& want = image.at(x, y).view();
            const VisibilityView got = out->pixel(0, x, y).view();
            const VisibilityView factors[] = {want};
            ASSERT_LE(productError(factors, got.toFunction(), 3), kStoreRounding) << x << "," << y;
            ASSERT_EQ(got.toFunction().totalCount(), image.at(x, y).totalCount() + ones.at(x, y).totalCount());
        }
    // The metadata records the inputs and the combined bound.
    const auto metadata = nlohmann::json::parse(out->info().metadata);
    EXPECT_EQ(metadata["merge"]["mode"], "product");
    EXPECT_EQ(metadata["merge"]["inputs"].size(), 2u);
    const double inputs = 2 * std::max(0.01, kStoreRounding);
    EXPECT_DOUBLE_EQ(metadata["merge"]["input_error_bound"].get<double>(), inputs);
    EXPECT_DOUBLE_EQ(metadata["merge"]["error_bound"].get<double>(), inputs + kStoreRounding);
    EXPECT_NO_THROW(validate((dir / "out.dsm").string()));
}

TEST(MergeProduct, GivenOptionsOutOfRangeAreRefused) {
    TempDir dir;
    std::mt19937_64 rng(5);
    writeMap(dir / "a.dsm", smallMapOptions(1, false),
             makeImage(8, 8, [&](std::uint32_t, std::uint32_t) { return randomFunction(rng, 1, false, 1, 3); }));
    const std::vector<std::string> inputs{(dir / "a.dsm").string()};
    const std::string out = (dir / "out.dsm").string();
    MergeOptions options;
    options.zlibLevel = -1;  // unset is automatic; a given level must be 0..9
    EXPECT_NE(messageOf(inputs, out, options).find("zlib level -1 is not in [0, 9]"), std::string::npos);
    options.zlibLevel.reset();
    options.tolerance = -1.0;
    EXPECT_NE(messageOf(inputs, out, options).find("tolerance -1 is not a finite value >= 0"), std::string::npos);
    options.tolerance.reset();
    options.maxInterpolationError = 0.0;
    EXPECT_NE(messageOf(inputs, out, options).find("interpolation error 0 is not a finite value > 0"),
              std::string::npos);
    EXPECT_FALSE(std::filesystem::exists(out));
    options.maxInterpolationError.reset();
    EXPECT_EQ(messageOf(inputs, out, options), "(no error)");
}

TEST(MergeProduct, MismatchedMapsNameTheFieldBothValuesAndBothFiles) {
    TempDir dir;
    std::mt19937_64 rng(9);
    const auto random = [&](std::uint32_t, std::uint32_t) { return randomFunction(rng, 1, false, 1, 4); };
    writeMap(dir / "a.dsm", smallMapOptions(1, false), makeImage(16, 16, random));
    writeMap(dir / "wide.dsm", smallMapOptions(1, false), makeImage(24, 16, random));
    WriterOptions tiles = smallMapOptions(1, false);
    tiles.tileSize = 4;
    writeMap(dir / "tiles.dsm", tiles, makeImage(16, 16, random));
    WriterOptions camera = smallMapOptions(1, false);
    camera.camera.screenWindow = {-1.0, 1.0, -0.5, 0.5};
    writeMap(dir / "camera.dsm", camera, makeImage(16, 16, random));
    const std::string a = (dir / "a.dsm").string(), out = (dir / "out.dsm").string();

    std::string m = messageOf({a, (dir / "wide.dsm").string()}, out, {});
    EXPECT_NE(m.find("size is 24x16 but 16x16"), std::string::npos) << m;
    EXPECT_NE(m.find("wide.dsm'"), std::string::npos) << m;
    EXPECT_NE(m.find("a.dsm'"), std::string::npos) << m;
    m = messageOf({a, (dir / "tiles.dsm").string()}, out, {});
    EXPECT_NE(m.find("tile size is 4 but 8"), std::string::npos) << m;
    m = messageOf({a, (dir / "camera.dsm").string()}, out, {});
    EXPECT_NE(m.find("screen window is [-1,1,-0.5,0.5] but [-1,1,-1,1]"), std::string::npos) << m;
    EXPECT_FALSE(std::filesystem::exists(out));
    m = messageOf({a, a}, a, {});
    EXPECT_NE(m.find("the output is also an input"), std::string::npos) << m;
}

// Two halves of a scene built separately against the whole scene, with the
// same sample positions (same seed and resolution). With one sample per pixel
// and a box filter one pixel wide every pixel is one ray, whose transmittance
// is exactly the product of the halves': the merged map must be within the
// recorded bound plus the whole map's own bound. With 4 samples and the
// Gaussian filter the product of filtered halves differs from the filtered
// product (an average of products is not a product of averages): measured
// and printed only.
TEST(MergeProduct, HalvesOfASceneAgainstTheWholeScene) {
    TempDir dir;
    const Scene whole = loadScene(DSM_SOURCE_DIR "/examples/leaves.json");
    Scene leaves = whole, ground = whole;
    leaves.objects.clear();
    ground.objects.clear();
    for (const SceneObject& o : whole.objects) (o.name == "ground" ? ground : leaves).objects.push_back(o);
    ASSERT_FALSE(ground.objects.empty());
    ASSERT_FALSE(leaves.objects.empty());
    for (int spp : {1, 4}) {
        BuildOptions b;
        b.width = b.height = 32;
        b.samplesPerPixel = static_cast<std::uint32_t>(spp);
        b.tileSize = 16;
        b.threads = 1;
        b.tolerance = 0.01;
        if (spp == 1) {
            b.filter = PixelFilter::Box;
            b.filterWidth = 1.0;
        }
        const std::string tag = std::to_string(spp);
        buildMap(whole, b, (dir / ("whole" + tag + ".dsm")).string());
        buildMap(leaves, b, (dir / ("leaves" + tag + ".dsm")).string());
        buildMap(ground, b, (dir / ("ground" + tag + ".dsm")).string());
        const MergeReport r = mergeMaps({(dir / ("leaves" + tag + ".dsm")).string(),
                                         (dir / ("ground" + tag + ".dsm")).string()},
                                        (dir / ("merged" + tag + ".dsm")).string(), {});
        const auto merged = DeepShadowMap::open((dir / ("merged" + tag + ".dsm")).string());
        const auto reference = DeepShadowMap::open((dir / ("whole" + tag + ".dsm")).string());
        EXPECT_EQ(merged->info().channels, 3);  // RGB leaves times the monochrome ground
        double worst = 0.0;
        for (std::uint32_t y = 0; y < 32; ++y)
            for (std::uint32_t x = 0; x < 32; ++x) {
                const VisibilityView got = merged->pixel(0, x, y).view();
                const VisibilityView want = reference->pixel(0, x, y).view();
                const VisibilityView both[] = {got, want};
                for (double z : probeDepths(both))
                    for (int c = 0; c < 3; ++c)
                        worst = std::max(worst, std::abs(got.evaluate(z, std::min(c, got.channels() - 1)) -
                                                         want.evaluate(z, std::min(c, want.channels() - 1))));
            }
        const double bound = r.errorBound + reference->info().levels[0].errorBound + kArithmetic;
        std::cout << "[ measured ] " << spp << " spp: largest |merged - whole| " << worst << ", bound " << bound
                  << " (interpolation " << r.interpolationError << ")\n";
        if (spp == 1) {
            EXPECT_LE(worst, bound);
        }
    }
}

// ---------------------------------------------------------------------------
// Stitch

struct RegionBuild {
    Scene scene = loadScene(DSM_SOURCE_DIR "/examples/leaves.json");
    BuildOptions options;
    RegionBuild() {
        options.width = 37;
        options.height = 29;
        options.samplesPerPixel = 4;
        options.tileSize = 8;
        options.threads = 1;
        options.mtsmLayers = 2;  // counts and layers must survive as well
    }
    std::string build(const std::filesystem::path& path, std::array<std::uint32_t, 4> region) const {
        BuildOptions o = options;
        o.region = region;
        buildMap(scene, o, path.string());
        return path.string();
    }
};

// `parts` stitched into `out` (dsm-merge --mode stitch); returns out's path.
std::string stitch(const std::vector<std::string>& parts, const std::filesystem::path& out) {
    MergeOptions options;
    options.mode = MergeMode::Stitch;
    mergeMaps(parts, out.string(), options);
    return out.string();
}

TEST(MergeStitch, RegionBuildsBecomeTheFullBuildByteForByte) {
    TempDir dir;
    const RegionBuild b;
    const std::string full = b.build(dir / "full.dsm", {0, 0, 0, 0});
    // Two parts on a tile boundary, and three not aligned to tiles.
    const std::vector<std::vector<std::array<std::uint32_t, 4>>> splits = {
        {{0, 0, 16, 29}, {16, 0, 37, 29}},
        {{0, 0, 13, 29}, {13, 0, 37, 11}, {13, 11, 37, 29}},
    };
    for (std::size_t s = 0; s < splits.size(); ++s) {
        std::vector<std::string> parts;
        for (std::size_t i = 0; i < splits[s].size(); ++i)
            parts.push_back(b.build(dir / ("part" + std::to_string(s) + std::to_string(i) + ".dsm"), splits[s][i]));
        std::reverse(parts.begin(), parts.end());  // the order of the inputs does not matter
        const std::string out = stitch(parts, dir / ("stitched" + std::to_string(s) + ".dsm"));
        EXPECT_EQ(readFile(out), readFile(full)) << "split " << s;
    }
}

// Parts written with zstd stitch into the zstd build, tiles of the same codec and level.
TEST(MergeStitch, ZstdPartsBecomeTheZstdBuildByteForByte) {
    TempDir dir;
    RegionBuild b;
    b.options.codec = dsm::TileCodec::Zstd;
    b.options.zstdLevel = 12;
    const std::string full = b.build(dir / "full.dsm", {0, 0, 0, 0});
    const std::vector<std::string> parts = {b.build(dir / "left.dsm", {0, 0, 13, 29}),
                                            b.build(dir / "right.dsm", {13, 0, 37, 29})};
    const std::string out = stitch(parts, dir / "stitched.dsm");
    EXPECT_EQ(DeepShadowMap::open(out)->info().codec, dsm::TileCodec::Zstd);
    EXPECT_EQ(readFile(out), readFile(full));
}

// Parts of a build with centred segments stitch into that build: the mip
// levels are rebuilt with centred segments too, as the metadata records.
TEST(MergeStitch, CentredPartsBecomeTheCentredBuildByteForByte) {
    TempDir dir;
    RegionBuild b;
    b.options.centredCompression = true;
    const std::string full = b.build(dir / "full.dsm", {0, 0, 0, 0});
    const std::vector<std::string> parts = {b.build(dir / "left.dsm", {0, 0, 13, 29}),
                                            b.build(dir / "right.dsm", {13, 0, 37, 29})};
    EXPECT_EQ(readFile(stitch(parts, dir / "stitched.dsm")), readFile(full));
}

// A part whose tile has no vertex in its region stores that tile as empty,
// without pixel flags, while the full build's tile holds vertices elsewhere and
// pixels without vertices made as RGB. The writer stores every pixel without
// vertices as monochrome, so the stitch still gives the full build's bytes.
// The scene is one scripts/soak-scenes found (an RGB map, a filter narrower
// than a pixel, so that some pixels catch no sample).
TEST(MergeStitch, RgbPartsWithAnEmptyTileBecomeTheFullBuildByteForByte) {
    TempDir dir;
    const Scene scene = dsm::parseScene(R"({
      "light": {"type": "spot", "position": [-5.6694082810413295, 5.372457428154316, -4.989261545331091],
                "direction": [6.570777264271524, -5.582391320455543, 4.229185594036345],
                "fov": 128.59215803351785, "near": 4.9541781484759815, "resolution": [7, 22]},
      "objects": [
        {"type": "sphere", "center": [-0.8415343809572021, -1.1732564902699396, -1.3743557664937507],
         "radius": 2.090525567397186, "opacity": [0.10144711365884151, 0.36897738780950406, 0.538761378699722]},
        {"type": "hair", "hairball": {"center": [-0.9855515179699892, 0.414219899396816, -0.7169484825362746],
                                      "radius": 0.7730856808254819, "count": 49, "length": 0.6093191906252517,
                                      "curl": 6.869809352378073, "width": 0.01, "segments": 9, "seed": 615},
         "opacity": [0.7207399249517827, 0.3532989783980076, 0.9576806390696524]}]})",
                                        "", "soak");
    BuildOptions options;
    options.samplesPerPixel = 2;
    options.filter = dsm::PixelFilter::Triangle;
    options.filterWidth = 0.5;
    options.tileSize = 64;
    options.mtsmLayers = 2;
    options.seed = 61;
    options.threads = 1;
    const auto build = [&](const std::filesystem::path& path, std::array<std::uint32_t, 4> region) {
        BuildOptions o = options;
        o.region = region;
        buildMap(scene, o, path.string());
        return path.string();
    };
    const std::string full = build(dir / "full.dsm", {0, 0, 0, 0});
    const std::string top = build(dir / "top.dsm", {0, 0, 7, 12});
    ASSERT_TRUE(DeepShadowMap::open(top)->tile(0, 0, 0).empty());  // the case this test is about
    const std::vector<std::string> parts = {top, build(dir / "bottom.dsm", {0, 12, 7, 22})};
    EXPECT_TRUE(readFile(stitch(parts, dir / "stitched.dsm")) == readFile(full));
}

// A compression this version does not know cannot have its mip levels rebuilt.
TEST(MergeStitch, AnUnknownCompressionSettingIsRefused) {
    TempDir dir;
    std::mt19937_64 rng(3);
    WriterOptions w = smallMapOptions(1, false);
    w.metadata = R"({"settings": {"region": [0, 0, 8, 8], "compression": "cubic"}})";
    writeMap(dir / "cubic.dsm", w,
             makeImage(8, 8, [&](std::uint32_t, std::uint32_t) { return randomFunction(rng, 1, false, 1, 3); }));
    MergeOptions options;
    options.mode = MergeMode::Stitch;
    const std::string out = (dir / "out.dsm").string();
    const std::string m = messageOf({(dir / "cubic.dsm").string()}, out, options);
    EXPECT_NE(m.find("settings.compression \"cubic\" is not \"centred\""), std::string::npos) << m;
    EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(MergeStitch, OverlapsAndHolesAreListed) {
    TempDir dir;
    const RegionBuild b;
    const std::string left = b.build(dir / "left.dsm", {0, 0, 20, 29});
    const std::string right = b.build(dir / "right.dsm", {18, 0, 37, 29});
    const std::string top = b.build(dir / "top.dsm", {20, 0, 37, 10});
    MergeOptions options;
    options.mode = MergeMode::Stitch;
    const std::string out = (dir / "out.dsm").string();
    std::string m = messageOf({left, right}, out, options);
    EXPECT_NE(m.find("1 pair of regions overlap"), std::string::npos) << m;
    EXPECT_NE(m.find("region 0,0,20,29 and '" + right + "' region 18,0,37,29 share 18,0,20,29"), std::string::npos)
        << m;
    m = messageOf({left, top}, out, options);
    EXPECT_NE(m.find("leave 323 of 1073 pixels uncovered, in 1 rectangle"), std::string::npos) << m;
    EXPECT_NE(m.find("20,10,37,29"), std::string::npos) << m;
    EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(MergeStitch, PartsOfDifferentBuildsAreRefused) {
    TempDir dir;
    RegionBuild b;
    const std::string left = b.build(dir / "left.dsm", {0, 0, 20, 29});
    b.options.seed = 2;
    const std::string right = b.build(dir / "right.dsm", {20, 0, 37, 29});
    b.options.seed = 1;
    b.options.mtsmLayers = 1;
    b.options.counts = true;
    const std::string plain = b.build(dir / "plain.dsm", {20, 0, 37, 29});
    MergeOptions options;
    options.mode = MergeMode::Stitch;
    const std::string out = (dir / "out.dsm").string();
    std::string m = messageOf({left, right}, out, options);
    EXPECT_NE(m.find("metadata settings.seed is 2 but 1"), std::string::npos) << m;
    m = messageOf({left, plain}, out, options);
    EXPECT_NE(m.find("layer count is 1 but 2"), std::string::npos) << m;

    // A map without settings.region is not a region build.
    std::mt19937_64 rng(1);
    writeMap(dir / "written.dsm", smallMapOptions(1, false),
             makeImage(8, 8, [&](std::uint32_t, std::uint32_t) { return randomFunction(rng, 1, false, 1, 3); }));
    m = messageOf({(dir / "written.dsm").string()}, out, options);
    EXPECT_NE(m.find("no settings.region"), std::string::npos) << m;
    EXPECT_FALSE(std::filesystem::exists(out));
}

// ---------------------------------------------------------------------------
// Layers (MTSM) of a product: spec/merge.md, "Layers"

namespace layers {

VisibilityFunction steps(std::initializer_list<std::initializer_list<std::pair<float, float>>> layerSteps) {
    VisibilityFunction f(1, true);
    bool first = true;
    for (const auto& layer : layerSteps) {
        if (!first) f.beginLayer();
        first = false;
        float v = 1.0f;
        for (const auto& [z, after] : layer) {
            f.append(z, v, 0);  // a surface: a step at z, counted once
            f.append(z, after, 1);
            v = after;
        }
    }
    f.validate();
    return f;
}

// Counts of each layer.
std::vector<std::uint64_t> layerCounts(const VisibilityView& f) {
    std::vector<std::uint64_t> out;
    for (std::size_t l = 0; l < f.layerCount(); ++l) {
        std::uint64_t sum = 0;
        for (std::size_t i = f.layerBegin(l); i < f.layerEnd(l); ++i) sum += f.count(i);
        out.push_back(sum);
    }
    return out;
}

}  // namespace layers

// A is opaque at 2 and keeps what lies behind in its layer 1; B is a single
// complete layer. The product's layer 1 restarts at 2 with A's layer 1 (a
// boundary of A: exact) times B divided by its value at 2.
TEST(VisibilityProductLayers, RestartAtABoundaryAndInsideALayer) {
    const VisibilityFunction a = layers::steps({{{1.5f, 0.8f}, {2.0f, 0.0f}}, {{3.0f, 0.5f}}});
    const VisibilityFunction b = layers::steps({{{1.0f, 0.6f}, {4.0f, 0.3f}}});
    const VisibilityView factors[] = {a.view(), b.view()};
    VisibilityProductOptions options;
    options.tolerance = 0.01;
    options.keepCounts = true;
    options.maxLayers = 3;
    const VisibilityProduct p = multiplyVisibility(factors, options);
    ASSERT_NO_THROW(p.function.validate());
    ASSERT_EQ(p.function.layerCount(), 2u);
    const VisibilityFunction& f = p.function;
    // Layer 0: the light-centre product, ending where A blocks everything.
    EXPECT_NEAR(f.evaluateLayer(0, 1.2), 0.6, 1e-6);
    EXPECT_NEAR(f.evaluateLayer(0, 1.7), 0.48, 1e-6);
    EXPECT_NEAR(f.evaluateLayer(0, 2.0), 0.0, 1e-6);
    EXPECT_EQ(f.z(f.layerEnd(0) - 1), 2.0f);
    // Layer 1: A's layer 1 (0.5 from 3) times B / B(2) = 0.5 from 4.
    EXPECT_NEAR(f.evaluateLayer(1, 2.5), 1.0, 1e-6);
    EXPECT_NEAR(f.evaluateLayer(1, 3.5), 0.5, 1e-6);
    EXPECT_NEAR(f.evaluateLayer(1, 4.5), 0.25, 1e-6);
    // Each sample once per layer: A's 2 and B's first in layer 0; A's layer-1
    // surface and B's second surface in layer 1.
    EXPECT_EQ(layers::layerCounts(f), (std::vector<std::uint64_t>{3, 2}));
    // The light-centre bound of layer 0 is unchanged.
    EXPECT_LE(productError(factors, f, 1), p.interpolationError + std::max(0.01, kStoreRounding) + kArithmetic);

    // One layer asked for: today's light-centre product.
    options.maxLayers = 1;
    EXPECT_EQ(multiplyVisibility(factors, options).function.layerCount(), 1u);
}

// An occluder hidden behind an opaque one of the other factor appears in
// layer 1. A has layers to spare, so nothing lies behind its opaque end; with
// its budget used up, what lies behind is unknown and the product stops.
TEST(VisibilityProductLayers, HiddenOccluderAppearsInLayerOne) {
    const VisibilityFunction a = layers::steps({{{1.0f, 0.5f}, {2.0f, 0.0f}}});
    const VisibilityFunction b = layers::steps({{{3.0f, 0.4f}, {5.0f, 0.0f}}});
    const VisibilityView factors[] = {a.view(), b.view()};
    VisibilityProductOptions options;
    options.tolerance = 0.01;
    options.keepCounts = true;
    options.maxLayers = 3;
    const VisibilityProduct p = multiplyVisibility(factors, options);
    ASSERT_EQ(p.function.layerCount(), 2u);
    EXPECT_NEAR(p.function.evaluate(1.5), 0.5, 1e-6);
    EXPECT_EQ(p.function.evaluate(2.5), 0.0);  // the light-centre view sees nothing behind A
    EXPECT_NEAR(p.function.evaluateLayer(1, 4.0), 0.4, 1e-6);
    EXPECT_NEAR(p.function.evaluateLayer(1, 5.0), 0.0, 1e-6);
    EXPECT_EQ(layers::layerCounts(p.function), (std::vector<std::uint64_t>{2, 2}));

    const int budgets[] = {1, 3};
    options.factorLayers = budgets;
    EXPECT_EQ(multiplyVisibility(factors, options).function.layerCount(), 1u);
    const int wrongSize[] = {3};
    options.factorLayers = wrongSize;
    EXPECT_THROW(multiplyVisibility(factors, options), Error);
    options.factorLayers = {};
    options.maxLayers = 0;
    EXPECT_THROW(multiplyVisibility(factors, options), Error);
}

// Random layered factors: the output is valid, has at most maxLayers layers,
// and its light-centre function keeps the proved bound.
TEST(VisibilityProductLayers, RandomLayeredFactorsKeepTheLightCentreBound) {
    std::mt19937_64 rng(77);
    std::uniform_int_distribution<int> vertices(1, 10), layerCount(1, 3);
    std::bernoulli_distribution rgb(0.5);
    const double tolerances[] = {0.0, 0.01, 0.05, 0.2};
    std::size_t layered = 0;
    for (int trial = 0; trial < 300; ++trial) {
        std::vector<VisibilityFunction> owned;
        for (int i = 0; i < 2 + trial % 2; ++i)
            owned.push_back(randomFunction(rng, rgb(rng) ? 3 : 1, true, layerCount(rng), vertices(rng),
                                           0.5f + 0.3f * float(i)));
        std::vector<VisibilityView> factors(owned.begin(), owned.end());
        VisibilityProductOptions options;
        options.tolerance = tolerances[trial % 4];
        options.keepCounts = true;
        options.maxLayers = 3;
        const VisibilityProduct p = multiplyVisibility(factors, options);
        ASSERT_NO_THROW(p.function.validate()) << "trial " << trial;
        ASSERT_LE(p.function.layerCount(), 3u);
        int channels = 1;
        for (const auto& f : owned) channels = std::max(channels, f.channels());
        const double bound = p.interpolationError + std::max(options.tolerance, kStoreRounding) + kArithmetic;
        ASSERT_LE(productError(factors, p.function, channels), bound) << "trial " << trial;
        layered += p.function.layerCount() > 1;
    }
    EXPECT_GT(layered, 30u);  // the test exercises restarts
}

// Two halves of a scene of quads (opaque and semi-transparent, RGB and grey,
// interleaved in depth, one hidden behind an opaque quad of the other half)
// built with 3 MTSM layers at 1 spp and a one-pixel box filter, where a
// pixel's function is one ray's: the product's layers must be the joint
// build's, layer by layer. Then soft shadows from both maps.
class MergeLayers : public ::testing::Test {
protected:
    using Map = std::shared_ptr<DeepShadowMap>;
    static constexpr double kRadius = 0.5;

    static std::string quad(double cx, double h, double cz, double hx, double hz, const char* opacity) {
        char text[400];
        std::snprintf(text, sizeof text,
                      R"({"type": "quad", "center": [%g, %g, %g], "u": [%g, 0, 0], "v": [0, 0, %g], "opacity": %s})",
                      cx, h, cz, hx, hz, opacity);
        return text;
    }
    static std::string scene(const std::vector<std::string>& objects) {
        std::string list;
        for (const std::string& o : objects) list += (list.empty() ? "" : ",\n") + o;
        char light[300];
        std::snprintf(light, sizeof light,
                      R"({"type": "spot", "position": [0, 10, 0], "direction": [0, -1, 0], "up": [0, 0, 1],
                          "fov": 60, "resolution": 40, "area_radius": %g})",
                      kRadius);
        return std::string(R"({"light": )") + light + R"(, "objects": [)" + list + "]}";
    }
    // A: grey and coloured quads, one opaque.
    static std::vector<std::string> halfA() {
        return {quad(-1, 7, 0, 2.5, 3, "0.5"), quad(-2, 5, 1, 2, 2, "1"), quad(1, 2.5, -1, 2, 2, "[0.7, 0.5, 0.3]"),
                quad(-0.5, 4, 1, 1.5, 1.5, "0.9")};
    }
    // B: a dense pair that ends B's own layer 0 semi-transparently, the
    // occluder hidden behind A's opaque quad, and the ground.
    static std::vector<std::string> halfB() {
        return {quad(1, 6, -1, 2.5, 3, "0.9"), quad(0, 4.5, 1, 1.5, 1.5, "0.95"), quad(-2, 3.5, 1, 2, 2, "0.6"),
                R"({"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "size": 40})"};
    }

    struct Built {
        Map merged, joint;
        MergeReport report;
    };
    // Builds the halves and the whole with `o` and merges the halves.
    static Built buildAndMerge(const BuildOptions& o, const std::string& tag) {
        const std::vector<std::string> a = halfA(), b = halfB();
        std::vector<std::string> both = a;
        both.insert(both.end(), b.begin(), b.end());
        const auto path = [&](const char* name) { return (dir_->path() / (name + tag + ".dsm")).string(); };
        buildMap(parseScene(scene(a), dir_->path().string(), "a"), o, path("a"));
        buildMap(parseScene(scene(b), dir_->path().string(), "b"), o, path("b"));
        buildMap(parseScene(scene(both), dir_->path().string(), "joint"), o, path("joint"));
        Built built;
        built.report = mergeMaps({path("a"), path("b")}, path("merged"), {});
        built.merged = DeepShadowMap::open(path("merged"));
        built.joint = DeepShadowMap::open(path("joint"));
        return built;
    }
    static BuildOptions options(std::uint32_t spp) {
        BuildOptions o;
        o.samplesPerPixel = spp;
        if (spp == 1) {
            o.filter = PixelFilter::Box;
            o.filterWidth = 1.0;
        }
        o.tolerance = 0.01;
        o.mtsmLayers = 3;
        o.tileSize = 16;
        o.threads = 1;
        return o;
    }

    static void SetUpTestSuite() {
        dir_ = new TempDir();
        const Built built = buildAndMerge(options(1), "1");
        report_ = new MergeReport(built.report);
        merged_ = new Map(built.merged);
        joint_ = new Map(built.joint);
    }
    static void TearDownTestSuite() {
        delete merged_;
        delete joint_;
        delete report_;
        delete dir_;
    }
    // The level-0 pixel under a world point.
    static std::pair<std::uint32_t, std::uint32_t> pixelUnder(double x, double z) {
        const MapInfo& info = (*joint_)->info();
        double rx = 0.0, ry = 0.0, depth = 0.0;
        info.camera.lightToRaster(info.camera.worldToLightSpace({x, 0.0, z}), int(info.width), int(info.height), rx,
                                  ry, depth);
        return {std::uint32_t(rx), std::uint32_t(ry)};
    }
    static double depthOf(double height) { return (*joint_)->info().camera.worldToLightSpace({0.0, height, 0.0})[2]; }

    struct ShadowDifference {
        double worst = 0.0, mean = 0.0, worstOneLayer = 0.0;
    };
    // Soft shadows on a grid of ground points from `merged` (all layers, and
    // layer 0 alone) against `joint` (all layers), the same light rays.
    static ShadowDifference softShadows(const Map& mergedMap, const Map& jointMap) {
        const auto tracer = [](const Map& map) {
            return std::make_shared<SoftShadowTracer>(map, AreaLight::disk(map->info().camera, kRadius));
        };
        SoftShadowContext merged(tracer(mergedMap)), joint(tracer(jointMap));
        SoftShadowOptions o;
        o.samples = 64;
        o.bias = 0.05;
        SoftShadowOptions lightCentreOnly = o;
        lightCentreOnly.layers = 1;  // what a product without layers gives
        ShadowDifference out;
        int n = 0;
        for (double x = -4.0; x <= 4.0; x += 0.5)
            for (double z = -3.0; z <= 3.0; z += 0.75) {
                const Vec3 p{x, 0.0, z};
                const SoftShadowResult a = merged.visibility(p, o), b = joint.visibility(p, o);
                const SoftShadowResult one = merged.visibility(p, lightCentreOnly);
                for (int c = 0; c < 3; ++c) {
                    const double d = std::abs(a.v[c] - b.v[c]);
                    out.worst = std::max(out.worst, d);
                    out.worstOneLayer = std::max(out.worstOneLayer, std::abs(one.v[c] - b.v[c]));
                    out.mean += d;
                    ++n;
                }
            }
        out.mean /= n;
        return out;
    }

    static TempDir* dir_;
    static MergeReport* report_;
    static Map* merged_;
    static Map* joint_;
};
TempDir* MergeLayers::dir_ = nullptr;
MergeReport* MergeLayers::report_ = nullptr;
MergeLayers::Map* MergeLayers::merged_ = nullptr;
MergeLayers::Map* MergeLayers::joint_ = nullptr;

TEST_F(MergeLayers, EveryLayerMatchesTheJointBuild) {
    EXPECT_EQ((*merged_)->info().maxLayers, 3);
    EXPECT_EQ(report_->maxLayers, 3);
    EXPECT_TRUE((*merged_)->info().hasCounts);
    EXPECT_NO_THROW(validate((*merged_)->path()));
    const auto metadata = nlohmann::json::parse((*merged_)->info().metadata);
    EXPECT_EQ(metadata["merge"]["layers"], "restarted from the inputs' layers");
    const MapInfo& info = (*joint_)->info();
    double worst = 0.0;
    std::size_t layeredPixels = 0, deepest = 0, countMismatches = 0;
    for (std::uint32_t y = 0; y < info.height; ++y)
        for (std::uint32_t x = 0; x < info.width; ++x) {
            const VisibilityView got = (*merged_)->pixel(0, x, y).view();
            const VisibilityView want = (*joint_)->pixel(0, x, y).view();
            ASSERT_EQ(got.layerCount(), want.layerCount()) << "pixel " << x << "," << y;
            layeredPixels += want.layerCount() > 1;
            deepest = std::max(deepest, want.layerCount());
            countMismatches += layers::layerCounts(got) != layers::layerCounts(want);
            const VisibilityView both[] = {got, want};
            for (std::size_t l = 0; l < want.layerCount(); ++l)
                for (double z : probeDepths(both))
                    for (int c = 0; c < 3; ++c)
                        worst = std::max(worst, std::abs(got.evaluateLayer(l, z, std::min(c, got.channels() - 1)) -
                                                         want.evaluateLayer(l, z, std::min(c, want.channels() - 1))));
        }
    std::cout << "[ measured ] " << layeredPixels << " of " << info.width * info.height
              << " pixels layered (up to " << deepest << " layers); largest |merged - joint| over all layers "
              << worst << "; pixels whose per-layer counts differ " << countMismatches << "\n";
    EXPECT_GT(layeredPixels, info.width * info.height / 4);
    EXPECT_EQ(deepest, 3u);
    EXPECT_EQ(countMismatches, 0u);
    // Per ray every restart is exact: the differences are the tolerances' (the
    // inputs', the product's and the joint build's; 0.0025 is measured, where
    // B's layer 0 ends at 0.005 and its light-centre function at 0).
    EXPECT_LE(worst, 3 * 0.01 + kArithmetic);
}

TEST_F(MergeLayers, HiddenOccluderIsInLayerOne) {
    // Under A's 0.5 and opaque quads (heights 7 and 5) and B's 0.6 quad behind
    // them (3.5), and no other quad.
    const auto [x, y] = pixelUnder(-3.6, 2.4);
    const VisibilityView got = (*merged_)->pixel(0, x, y).view();
    ASSERT_GE(got.layerCount(), 2u);
    EXPECT_EQ(got.evaluate(depthOf(4.0)), 0.0);
    EXPECT_NEAR(got.evaluateLayer(1, depthOf(4.0)), 1.0, 1e-6);
    // Within the inputs' tolerance 0.01: their values are stored on its value step.
    EXPECT_NEAR(got.evaluateLayer(1, depthOf(2.0)), 0.4, 0.01);
    EXPECT_NEAR(got.evaluateLayer(1, depthOf(-1.0)), 0.0, 1e-6);  // the ground
}

TEST_F(MergeLayers, SoftShadowsAgreeWithTheJointBuild) {
    const ShadowDifference d = softShadows(*merged_, *joint_);
    std::cout << "[ measured ] 1 spp: soft shadows merged vs joint: largest difference " << d.worst << ", mean "
              << d.mean << "; from layer 0 alone the largest is " << d.worstOneLayer << "\n";
    EXPECT_LE(d.worst, 0.02);
    EXPECT_GT(d.worstOneLayer, 5 * d.worst);  // the hidden occluder matters here
}

// With 4 samples per pixel and the Gaussian filter a pixel averages rays that
// meet different occluders: restarts inside a layer divide averages (the
// ratio of averages, not the average of ratios) and the filtered product is
// not the filtered joint build. Measured, with a loose sanity limit.
TEST_F(MergeLayers, FilteredPixelsAreApproximate) {
    const Built built = buildAndMerge(options(4), "4");
    EXPECT_NO_THROW(validate(built.merged->path()));
    EXPECT_EQ(built.merged->info().maxLayers, 3);
    const ShadowDifference d = softShadows(built.merged, built.joint);
    std::cout << "[ measured ] 4 spp, Gaussian: soft shadows merged vs joint: largest difference " << d.worst
              << ", mean " << d.mean << "; from layer 0 alone the largest is " << d.worstOneLayer << "\n";
    EXPECT_LE(d.worst, 0.25);
}

}  // namespace
}  // namespace dsm::test
