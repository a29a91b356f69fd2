// Deep OpenEXR interop (dsm/exr_deep.h, spec/exr-interop.md): the deviation
// formula, the exported samples against the map measured densely through
// OpenEXR's exponential reading, messy samples against hand-computed answers,
// the camera attributes, and whole files both ways.
#include <dsm/dsm.h>
#include <dsm/exr_deep.h>
#include <gtest/gtest.h>

#include <ImathBox.h>
#include <ImathMatrix.h>
#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfPartType.h>
#include <ImfStandardAttributes.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "temp_dir.h"

namespace dsm {
namespace {

// ---------------------------------------------------------------------------
// Oracles

/// OpenEXR's reading of deep samples at depth z, straight from "Interpreting
/// OpenEXR Deep Pixels": the product over all samples of 1 - alpha_i(z).
/// channel -1 is A, 0..2 are AR, AG, AB.
double exrTransmittance(const std::vector<DeepSample>& samples, double z, int channel) {
    double t = 1.0;
    for (const DeepSample& s : samples) {
        const double a = channel < 0 ? s.alpha : s.alphaRGB[std::size_t(channel)];
        if (!(s.zBack > s.z)) {
            if (z >= s.z) t *= 1.0 - a;
        } else if (z > s.z) {
            const double x = z >= s.zBack ? 1.0 : (z - s.z) / (double(s.zBack) - s.z);
            t *= std::pow(1.0 - a, x);
        }
    }
    return t;
}

/// Depths that probe a function: every vertex, `perSegment` points inside
/// every gap between distinct depths, and beyond both ends.
std::vector<double> probeDepths(std::vector<double> knots, int perSegment) {
    std::sort(knots.begin(), knots.end());
    knots.erase(std::unique(knots.begin(), knots.end()), knots.end());
    std::vector<double> out;
    if (knots.empty()) return {0.0, 1.0};
    out.push_back(knots.front() * 0.5);
    for (std::size_t i = 0; i < knots.size(); ++i) {
        out.push_back(knots[i]);
        if (i + 1 < knots.size())
            for (int k = 1; k <= perSegment; ++k)
                out.push_back(knots[i] + (knots[i + 1] - knots[i]) * k / (perSegment + 1));
    }
    out.push_back(knots.back() + 1.0);
    return out;
}

/// A varied function: steps, slopes, flats, sometimes down to 0.
VisibilityFunction randomFunction(std::mt19937& rng, int channels) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    VisibilityFunction f(channels);
    double v[3] = {1.0, 1.0, 1.0};
    double z = 0.5 + 4.0 * unit(rng);
    const int n = 1 + int(rng() % 10);
    for (int i = 0; i < n; ++i) {
        const double kind = unit(rng);
        if (kind > 0.3) z += 0.01 + 2.0 * unit(rng);  // else a vertical step at z
        for (int c = 0; c < channels; ++c) {
            const double drop = kind < 0.1 ? 1.0 : unit(rng) * (kind < 0.5 ? 0.9 : 0.4);
            v[c] = unit(rng) < 0.15 ? v[c] : v[c] * (1.0 - drop);
        }
        float values[3];
        for (int c = 0; c < channels; ++c) values[c] = float(v[c]);
        f.append(float(z), values);
    }
    return f;
}

double valueOf(const VisibilityView& f, double z, int channel) {
    return f.evaluate(z, std::min(channel, f.channels() - 1));
}

/// Largest |EXR reading - V| over the probes, in every channel and the mean.
double measuredDeviation(const VisibilityView& f, const std::vector<DeepSample>& samples, int perSegment = 200) {
    std::vector<double> knots(f.depths().begin(), f.depths().end());
    for (const DeepSample& s : samples) knots.push_back(s.z), knots.push_back(s.zBack);
    double worst = 0.0;
    for (double z : probeDepths(knots, perSegment)) {
        if (f.channels() == 1) {
            worst = std::max(worst, std::abs(exrTransmittance(samples, z, -1) - f.evaluate(z)));
            continue;
        }
        double mean = 0.0;
        for (int c = 0; c < 3; ++c) {
            const double v = f.evaluate(z, c);
            mean += v / 3.0;
            worst = std::max(worst, std::abs(exrTransmittance(samples, z, c) - v));
        }
        worst = std::max(worst, std::abs(exrTransmittance(samples, z, -1) - mean));
    }
    return worst;
}

// ---------------------------------------------------------------------------
// The deviation formula

TEST(ExrDeviation, ClosedFormMatchesDenseMaximum) {
    for (double v0 : {1.0, 0.6, 0.05})
        for (double ratio : {0.999, 0.9, 0.5, 0.1, 1e-3, 1e-8}) {
            const double v1 = v0 * ratio;
            double dense = 0.0;
            for (int k = 0; k <= 100000; ++k) {
                const double t = k / 100000.0;
                dense = std::max(dense, (v0 + t * (v1 - v0)) - v0 * std::pow(ratio, t));
            }
            EXPECT_NEAR(exponentialDeviation(v0, v1), dense, 1e-6 * v0) << "v0 " << v0 << " ratio " << ratio;
        }
}

TEST(ExrDeviation, Limits) {
    EXPECT_EQ(exponentialDeviation(0.7, 0.7), 0.0);
    EXPECT_DOUBLE_EQ(exponentialDeviation(0.7, 0.0), 0.7);  // exponential drops at once to 0
    for (double r : {0.99, 0.9999, 1.0 - 1e-7}) {  // both sides of the series' threshold
        const double u = -std::log(r);
        EXPECT_NEAR(exponentialDeviation(1.0, r), u * u / 8.0, 0.01 * u * u / 8.0) << r;
        EXPECT_NEAR(exponentialDeviation(1.0, r), u * u / 8.0 - u * u * u / 16.0, 1e-3 * u * u * u) << r;
    }
    EXPECT_EQ(exponentialDeviation(0.0, 0.0), 0.0);
}

// ---------------------------------------------------------------------------
// Export of functions, measured

TEST(ExrExportSamples, DeviationBoundHoldsMeasuredDensely) {
    std::mt19937 rng(12345);
    for (int channels : {1, 3})
        for (double bound : {1e-2, 1e-3, 1e-4}) {
            double worst = 0.0;
            for (int i = 0; i < 150; ++i) {
                const VisibilityFunction f = randomFunction(rng, channels);
                const auto samples = deepSamplesFromVisibility(f, bound);
                worst = std::max(worst, measuredDeviation(f, samples));
            }
            std::printf("[ measured ] channels %d bound %g: largest |T_exr - V| %.6g\n", channels, bound, worst);
            EXPECT_LE(worst, bound + 2e-6) << "channels " << channels;
            EXPECT_GT(worst, bound * 0.3) << "the bound is never approached: the test measures nothing";
        }
}

TEST(ExrExportSamples, SteepDropToZeroNearFloatResolution) {
    // From a real map: the last piece used to end at V = 0 from just above the
    // bound, its wanted end lost in the rounding of depth to float.
    VisibilityFunction f(1);
    f.append(8.32186794f, 0.495564759f);
    f.append(8.33637142f, 0.0f);
    const auto samples = deepSamplesFromVisibility(f, 1e-3);
    EXPECT_LE(measuredDeviation(f, samples, 2000), 1e-3 + 1e-6);
}

TEST(ExrExportSamples, TidyAndTelescoping) {
    std::mt19937 rng(777);
    for (int channels : {1, 3})
        for (int i = 0; i < 200; ++i) {
            const VisibilityFunction f = randomFunction(rng, channels);
            const auto samples = deepSamplesFromVisibility(f, 1e-3);
            for (std::size_t k = 1; k < samples.size(); ++k) {  // sorted and non-overlapping
                const DeepSample &a = samples[k - 1], &b = samples[k];
                EXPECT_TRUE(a.z < b.z || (a.z == b.z && a.zBack <= b.zBack)) << "sample " << k;
                EXPECT_LE(std::max(a.z, a.zBack), b.z) << "sample " << k;
            }
            // Flattening: the product of (1 - alpha) is V beyond the last vertex.
            for (int c = -1; c < channels; ++c) {
                double product = 1.0;
                for (const DeepSample& s : samples) product *= 1.0 - (c < 0 ? s.alpha : s.alphaRGB[std::size_t(c)]);
                double expected = 0.0;
                if (c >= 0) expected = f.value(f.size() - 1, c);
                else
                    for (int k = 0; k < channels; ++k) expected += f.value(f.size() - 1, k) / channels;
                EXPECT_NEAR(product, expected, 1e-5) << "channel " << c;
            }
        }
}

TEST(ExrExportSamples, StepsArePointSamplesFlatsNothing) {
    VisibilityFunction f(1);
    f.append(2.0f, 0.5f);  // step from 1 to 0.5 at 2
    f.append(3.0f, 0.5f);  // flat
    f.append(3.0f, 0.2f);  // step at 3
    const auto samples = deepSamplesFromVisibility(f, 1e-3);
    ASSERT_EQ(samples.size(), 2u);
    EXPECT_EQ(samples[0].z, 2.0f);
    EXPECT_EQ(samples[0].zBack, 2.0f);
    EXPECT_NEAR(samples[0].alpha, 0.5f, 1e-7);
    EXPECT_EQ(samples[1].z, 3.0f);
    EXPECT_NEAR(samples[1].alpha, 1.0 - 0.2 / 0.5, 1e-6);
}

TEST(ExrExportSamples, LayeredFunctionEndsBlack) {
    VisibilityFunction f(1);
    f.append(1.0f, 1.0f);
    f.append(2.0f, 0.01f);
    f.beginLayer();
    f.append(3.0f, 0.5f);
    const auto samples = deepSamplesFromVisibility(f, 1e-3);
    EXPECT_EQ(exrTransmittance(samples, 2.0, -1), 0.0);
    EXPECT_LE(measuredDeviation(f, samples), 1e-3 + 1e-6);
}

TEST(ExrExportSamples, RejectsNonPositiveBound) {
    VisibilityFunction f(1);
    f.append(1.0f, 0.5f);
    EXPECT_THROW(deepSamplesFromVisibility(f, 0.0), Error);
}

// ---------------------------------------------------------------------------
// Import of samples

DeepSample sample(float z, float zBack, float alpha) { return {z, zBack, alpha, {alpha, alpha, alpha}}; }

/// Messy: unsorted, volumes overlapping each other and a point, two coincident
/// points. Hand-computed: A [1,3) alpha .5 and B [2,4) alpha .75 give
/// T = .5^((z-1)/2) * .25^((z-2)/2); the point at 2.5 multiplies by .8 and the
/// two at 5 by .5 * .5.
std::vector<DeepSample> messySamples() {
    return {sample(5.0f, 5.0f, 0.5f), sample(2.0f, 4.0f, 0.75f), sample(2.5f, 2.5f, 0.2f), sample(1.0f, 3.0f, 0.5f),
            sample(5.0f, 0.0f, 0.5f)};
}

TEST(ExrImportSamples, MessySamplesMatchHandComputedAnswer) {
    const double bound = 1e-4;
    const VisibilityFunction f = visibilityFromDeepSamples(messySamples(), 1, bound);
    struct Expect {
        double z, v;
    };
    const Expect expected[] = {{0.5, 1.0},
                               {1.0, 1.0},
                               {2.0, std::sqrt(0.5)},
                               {2.5, std::pow(0.5, 0.75) * std::pow(0.25, 0.25) * 0.8},
                               {3.0, 0.5 * 0.5 * 0.8},
                               {4.0, 0.5 * 0.25 * 0.8},
                               {4.99, 0.1},
                               {5.0, 0.025},
                               {9.0, 0.025}};
    for (const Expect& e : expected) EXPECT_NEAR(f.evaluate(e.z), e.v, 1e-6) << "z " << e.z;
    // Between the events, within the chord bound of the exponential.
    double worst = 0.0;
    for (int k = 0; k <= 4000; ++k) {
        const double z = 1.0 + 3.0 * k / 4000.0;
        const double a = std::pow(0.5, std::clamp((z - 1.0) / 2.0, 0.0, 1.0));
        const double b = std::pow(0.25, std::clamp((z - 2.0) / 2.0, 0.0, 1.0));
        const double exact = a * b * (z >= 2.5 ? 0.8 : 1.0);
        worst = std::max(worst, std::abs(f.evaluate(z) - exact));
    }
    std::printf("[ measured ] messy pixel: largest |V - T_exact| %.6g (bound %g)\n", worst, bound);
    EXPECT_LE(worst, bound + 1e-6);
    EXPECT_GT(worst, bound * 0.2);
}

TEST(ExrImportSamples, OrderDoesNotMatter) {
    auto samples = messySamples();
    const VisibilityFunction a = visibilityFromDeepSamples(samples, 1, 1e-4);
    std::mt19937 rng(3);
    for (int i = 0; i < 5; ++i) {
        std::shuffle(samples.begin(), samples.end(), rng);
        EXPECT_EQ(visibilityFromDeepSamples(samples, 1, 1e-4), a);
    }
}

TEST(ExrImportSamples, OpaqueVolumeIsAStepAtItsFront) {
    const std::vector<DeepSample> samples{sample(2.0f, 6.0f, 1.0f)};
    const VisibilityFunction f = visibilityFromDeepSamples(samples, 1, 1e-3);
    EXPECT_EQ(f.evaluate(1.999), 1.0);
    EXPECT_EQ(f.evaluate(2.0), 0.0);
}

TEST(ExrImportSamples, ExportedSamplesComeBack) {
    std::mt19937 rng(99);
    double worst = 0.0;
    for (int channels : {1, 3})
        for (int i = 0; i < 100; ++i) {
            const VisibilityFunction f = randomFunction(rng, channels);
            const VisibilityFunction back = visibilityFromDeepSamples(deepSamplesFromVisibility(f, 1e-3), channels, 1e-4);
            for (double z : probeDepths({f.depths().begin(), f.depths().end()}, 50))
                for (int c = 0; c < channels; ++c) worst = std::max(worst, std::abs(back.evaluate(z, c) - f.evaluate(z, c)));
        }
    EXPECT_LE(worst, 1e-3 + 1e-4 + 2e-6);
}

TEST(ExrImportSamples, BadSamplesNameTheSample) {
    std::vector<DeepSample> samples{sample(1.0f, 1.0f, 0.5f), sample(2.0f, 2.0f, 0.5f), sample(-1.0f, 1.0f, 0.5f)};
    try {
        visibilityFromDeepSamples(samples, 1, 1e-3);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("sample 2"), std::string::npos) << e.what();
    }
    samples[2] = sample(1.0f, 1.0f, 1.5f);
    EXPECT_THROW(visibilityFromDeepSamples(samples, 1, 1e-3), Error);
    samples[2] = sample(1.0f, 1.0f, std::nanf(""));
    EXPECT_THROW(visibilityFromDeepSamples(samples, 1, 1e-3), Error);
}

// ---------------------------------------------------------------------------
// Camera attributes

LightCamera testCamera(Projection projection) {
    LightCamera cam;
    cam.projection = projection;
    const double c = std::cos(0.3), s = std::sin(0.3);  // a rotation about y and a translation
    cam.worldToLight = {c, 0, -s, 1.5, 0, 1, 0, -0.25, s, 0, c, 4.0, 0, 0, 0, 1};
    cam.screenWindow = projection == Projection::Perspective ? std::array<double, 4>{-0.6, 0.4, -0.3, 0.5}
                                                             : std::array<double, 4>{-3.0, 5.0, -2.0, 2.0};
    return cam;
}

TEST(ExrCamera, WorldToNDCAgreesWithTheLightRaster) {
    for (Projection p : {Projection::Perspective, Projection::Orthographic}) {
        const LightCamera cam = testCamera(p);
        const StandardCameraMatrices m = standardCameraMatrices(cam);
        Imath::M44f toCamera, toNDC;
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                toCamera[i][j] = m.worldToCamera[std::size_t(i)][std::size_t(j)],
                toNDC[i][j] = m.worldToNDC[std::size_t(i)][std::size_t(j)];
        const int width = 40, height = 30;
        for (const auto& world : {std::array<double, 3>{0.1, 0.2, 0.3}, std::array<double, 3>{-1.0, 0.5, 2.0}}) {
            double rx, ry, z;
            ASSERT_TRUE(cam.lightToRaster(cam.worldToLightSpace(world), width, height, rx, ry, z));
            Imath::V3f ndc, camera;
            toNDC.multVecMatrix(Imath::V3f(float(world[0]), float(world[1]), float(world[2])), ndc);  // divides by w
            toCamera.multVecMatrix(Imath::V3f(float(world[0]), float(world[1]), float(world[2])), camera);
            EXPECT_NEAR(ndc.x * width, rx, 1e-3);
            EXPECT_NEAR(ndc.y * height, ry, 1e-3);
            EXPECT_NEAR(camera.z, z, 1e-5);  // OpenEXR's camera space looks along +z, as ours
        }
    }
}

TEST(ExrCamera, StandardMatricesGiveTheCameraBack) {
    for (Projection p : {Projection::Perspective, Projection::Orthographic}) {
        const LightCamera cam = testCamera(p);
        const StandardCameraMatrices m = standardCameraMatrices(cam);
        std::array<std::array<double, 4>, 4> c{}, n{};
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                c[std::size_t(i)][std::size_t(j)] = m.worldToCamera[std::size_t(i)][std::size_t(j)],
                n[std::size_t(i)][std::size_t(j)] = m.worldToNDC[std::size_t(i)][std::size_t(j)];
        const LightCamera back = cameraFromStandardMatrices(c, n);
        EXPECT_EQ(back.projection, p);
        for (std::size_t i = 0; i < 16; ++i) EXPECT_NEAR(back.worldToLight[i], cam.worldToLight[i], 1e-6);
        for (std::size_t i = 0; i < 4; ++i) EXPECT_NEAR(back.screenWindow[i], cam.screenWindow[i], 1e-5);
    }
    std::array<std::array<double, 4>, 4> identity{}, skew{};
    for (int i = 0; i < 4; ++i) identity[std::size_t(i)][std::size_t(i)] = 1.0;
    skew = identity;
    skew[0][1] = 0.5;  // not a projection along z
    skew[2][3] = 1.0, skew[3][3] = 0.0;
    EXPECT_THROW(cameraFromStandardMatrices(identity, skew), Error);
}

// ---------------------------------------------------------------------------
// Files

constexpr std::uint32_t kSize = 32;
constexpr double kTolerance = 0.01;

void writeTestMap(const std::filesystem::path& path, int channels) {
    WriterOptions o;
    o.width = kSize;
    o.height = kSize;
    o.tileSize = 16;
    o.channels = channels;
    o.tolerance = kTolerance;
    o.camera = testCamera(Projection::Perspective);
    o.camera.nearPlane = 0.125;
    o.metadata = R"({"test":"exr"})";
    MapWriter writer(path.string(), o);
    std::mt19937 rng(2024u + unsigned(channels));
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<VisibilityFunction> tile;
            for (std::uint32_t i = 0; i < writer.tileWidth(tx) * writer.tileHeight(ty); ++i)
                tile.push_back(i % 7 == 3 ? VisibilityFunction(channels) : randomFunction(rng, channels));
            writer.writeTile(tx, ty, tile);
        }
    writer.finish();
}

/// Largest |V_a - V_b| over level 0, at the vertices of both and between.
double mapDifference(const DeepShadowMap& a, const DeepShadowMap& b) {
    double worst = 0.0;
    for (std::uint32_t y = 0; y < a.info().height; ++y)
        for (std::uint32_t x = 0; x < a.info().width; ++x) {
            const PixelFunction fa = a.pixel(0, x, y), fb = b.pixel(0, x, y);
            std::vector<double> knots(fa->depths().begin(), fa->depths().end());
            knots.insert(knots.end(), fb->depths().begin(), fb->depths().end());
            for (double z : probeDepths(knots, 20))
                for (int c = 0; c < a.info().channels; ++c)
                    worst = std::max(worst, std::abs(valueOf(fa.view(), z, c) - valueOf(fb.view(), z, c)));
        }
    return worst;
}

TEST(ExrFiles, RoundTripStaysWithinTwoEpsilon) {
    test::TempDir dir;
    for (int channels : {1, 3})
        for (bool tiled : {false, true}) {
            const auto map = dir / "map.dsm", exr = dir / "map.exr", back = dir / "back.dsm";
            writeTestMap(map, channels);
            ExrExportOptions eo;
            eo.tiled = tiled;
            eo.tileSize = 16;
            const ExrExportReport er = exportDeepExr(map.string(), exr.string(), eo);
            EXPECT_EQ(er.maxDeviation, std::min(kTolerance / 2, 1e-3));
            EXPECT_LE(er.largestDeviation, er.maxDeviation);
            EXPECT_GT(er.volumeSamples, 0u);
            const ExrImportReport ir = importDeepExr(exr.string(), back.string());
            EXPECT_EQ(ir.cameraSource, "dsm attributes");
            EXPECT_EQ(ir.tolerance, kTolerance);
            const auto a = DeepShadowMap::open(map.string()), b = DeepShadowMap::open(back.string());
            EXPECT_EQ(b->info().camera, a->info().camera);  // exact through the dsm:* attributes
            // The map's metadata comes back, with the image's attributes under "exr".
            nlohmann::json metadata = nlohmann::json::parse(b->info().metadata);
            EXPECT_TRUE(metadata.contains("exr"));
            metadata.erase("exr");
            EXPECT_EQ(metadata, nlohmann::json::parse(a->info().metadata));
            EXPECT_EQ(b->info().channels, channels);
            EXPECT_GT(b->info().levels.size(), 1u);  // mip-mapped
            const double worst = mapDifference(*a, *b);
            std::printf("[ measured ] %s %s: dsm -> exr -> dsm largest |dV| %.6g = %.4g eps\n",
                        channels == 1 ? "mono" : "RGB", tiled ? "tiled" : "scanline", worst, worst / kTolerance);
            EXPECT_LE(worst, 2 * kTolerance);
            validate(back.string());
        }
}

TEST(ExrFiles, ExportsAMipLevel) {
    test::TempDir dir;
    writeTestMap(dir / "map.dsm", 1);
    ExrExportOptions eo;
    eo.level = 1;
    const ExrExportReport r = exportDeepExr((dir / "map.dsm").string(), (dir / "l1.exr").string(), eo);
    EXPECT_EQ(r.width, kSize / 2);
    const ExrImportReport back = importDeepExr((dir / "l1.exr").string(), (dir / "l1.dsm").string());
    EXPECT_EQ(back.width, kSize / 2);
    eo.level = 99;
    EXPECT_THROW(exportDeepExr((dir / "map.dsm").string(), (dir / "x.exr").string(), eo), Error);
    EXPECT_FALSE(std::filesystem::exists(dir / "x.exr"));
}

// OpenEXR 3.1 accepts a deep tile whose sample-count table (width x height
// x 4 bytes) fits 32 unsigned bits, then sizes the table through an int:
// 32768 x 30000 tiles asked it for a negative, so nearly 2^64-byte, buffer.
// A tile's area is bounded before OpenEXR reads the header.
TEST(ExrFiles, TilesLargerThanTheLimitAreRefusedBeforeOpenExrReadsThem) {
    test::TempDir dir;
    writeTestMap(dir / "map.dsm", 1);
    ExrExportOptions eo;
    eo.tiled = true;
    eo.tileSize = 16;
    exportDeepExr((dir / "map.dsm").string(), (dir / "tiled.exr").string(), eo);
    std::string bytes;
    {
        std::ifstream in(dir / "tiled.exr", std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), {});
    }
    const std::string tag = std::string("tiles") + '\0' + "tiledesc" + '\0';
    const std::size_t at = bytes.find(tag);
    ASSERT_NE(at, std::string::npos);
    const std::size_t sizes = at + tag.size() + 4;  // after the int32 attribute size
    const auto patched = [&](std::uint32_t width, std::uint32_t height) {
        std::string copy = bytes;
        for (int i = 0; i < 4; ++i) {
            copy[sizes + i] = char((width >> (8 * i)) & 0xff);
            copy[sizes + 4 + i] = char((height >> (8 * i)) & 0xff);
        }
        const auto path = dir / "patched.exr";
        std::ofstream(path, std::ios::binary) << copy;
        return path;
    };
    for (const auto& [width, height] : {std::pair<std::uint32_t, std::uint32_t>{131072, 131072},
                                        {32768, 30000}, {4097, 4096}, {1, 16777217},
                                        {0xffffffffu, 0xffffffffu}}) {
        const auto exr = patched(width, height);
        try {
            importDeepExr(exr.string(), (dir / "out.dsm").string());
            ADD_FAILURE() << "no dsm::Error for " << width << " x " << height;
        } catch (const Error& e) {
            EXPECT_EQ(e.code(), ErrorCode::limit) << e.what();
            EXPECT_NE(std::string(e.what()).find("header attribute 'tiles' (tiledesc) describes " +
                                                 std::to_string(width) + " x " + std::to_string(height) +
                                                 " pixel tiles; at most 16777216 pixels"),
                      std::string::npos)
                << e.what();
        }
        EXPECT_FALSE(std::filesystem::exists(dir / "out.dsm"));
    }
    // The unpatched file still imports.
    EXPECT_EQ(importDeepExr(patched(16, 16).string(), (dir / "out.dsm").string()).width, kSize);
}

TEST(ExrFiles, FailedExportLeavesNoFile) {
    test::TempDir dir;
    writeTestMap(dir / "map.dsm", 1);
    EXPECT_THROW(exportDeepExr((dir / "map.dsm").string(), (dir / "missing" / "x.exr").string()), Error);
    EXPECT_THROW(exportDeepExr((dir / "nothing.dsm").string(), (dir / "x.exr").string()), Error);
    for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
        EXPECT_EQ(entry.path().filename(), "map.dsm") << "left behind: " << entry.path();
}

/// A deep scanline EXR of `width` x 1 pixels: channels by name, every pixel
/// with the same samples; optional standard camera attributes.
void writeDeepExr(const std::filesystem::path& path, std::vector<DeepSample> samples, bool withZ,
                  const LightCamera* standardCamera) {
    const int width = 4;
    Imf::Header header(width, 1);
    header.compression() = Imf::ZIPS_COMPRESSION;
    header.setType(Imf::DEEPSCANLINE);
    if (withZ) header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
    header.channels().insert("ZBack", Imf::Channel(Imf::FLOAT));
    header.channels().insert("A", Imf::Channel(Imf::HALF));
    if (standardCamera) {
        const StandardCameraMatrices m = standardCameraMatrices(*standardCamera);
        Imath::M44f c, n;
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                c[i][j] = m.worldToCamera[std::size_t(i)][std::size_t(j)],
                n[i][j] = m.worldToNDC[std::size_t(i)][std::size_t(j)];
        Imf::addWorldToCamera(header, c);
        Imf::addWorldToNDC(header, n);
    }
    std::vector<unsigned> counts(width, unsigned(samples.size()));
    std::vector<float> z, zBack;
    std::vector<half> alpha;
    for (const DeepSample& s : samples) z.push_back(s.z), zBack.push_back(s.zBack), alpha.push_back(half(s.alpha));
    std::vector<char*> zp(width, reinterpret_cast<char*>(z.data())), bp(width, reinterpret_cast<char*>(zBack.data())),
        ap(width, reinterpret_cast<char*>(alpha.data()));
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), sizeof(unsigned), 0));
    if (withZ) fb.insert("Z", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(zp.data()), sizeof(char*), 0, sizeof(float)));
    fb.insert("ZBack", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(bp.data()), sizeof(char*), 0, sizeof(float)));
    fb.insert("A", Imf::DeepSlice(Imf::HALF, reinterpret_cast<char*>(ap.data()), sizeof(char*), 0, sizeof(half)));
    Imf::DeepScanLineOutputFile out(path.string().c_str(), header);
    out.setFrameBuffer(fb);
    out.writePixels(1);
}

TEST(ExrFiles, MessyFileWithStandardCamera) {
    test::TempDir dir;
    const LightCamera cam = testCamera(Projection::Perspective);
    writeDeepExr(dir / "messy.exr", messySamples(), true, &cam);
    const ExrImportReport r = importDeepExr((dir / "messy.exr").string(), (dir / "messy.dsm").string());
    EXPECT_EQ(r.cameraSource, "standard attributes");
    EXPECT_EQ(r.tolerance, kDefaultExrImportTolerance);
    const auto map = DeepShadowMap::open((dir / "messy.dsm").string());
    for (std::size_t i = 0; i < 4; ++i) EXPECT_NEAR(map->info().camera.screenWindow[i], cam.screenWindow[i], 1e-5);
    const PixelFunction f = map->pixel(0, 2, 0);
    EXPECT_NEAR(f->evaluate(3.0), 0.5 * 0.5 * 0.8, r.tolerance + r.maxLinearError + 1e-3);  // alpha is half here
    EXPECT_NEAR(f->evaluate(6.0), 0.025, r.tolerance + 1e-3);
}

TEST(ExrFiles, ImportErrorsNameFileAndCause) {
    test::TempDir dir;
    auto message = [&](const std::filesystem::path& exr, const ExrImportOptions& o = {}) {
        try {
            importDeepExr(exr.string(), (dir / "out.dsm").string(), o);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    writeDeepExr(dir / "noz.exr", {sample(1.0f, 1.0f, 0.5f)}, false, nullptr);
    const std::string noZ = message(dir / "noz.exr");
    EXPECT_NE(noZ.find("noz.exr"), std::string::npos) << noZ;
    EXPECT_NE(noZ.find("no Z channel"), std::string::npos) << noZ;

    writeDeepExr(dir / "nocam.exr", {sample(1.0f, 1.0f, 0.5f)}, true, nullptr);
    EXPECT_NE(message(dir / "nocam.exr").find("no light camera"), std::string::npos);
    ExrImportOptions fov;
    fov.fieldOfView = 60.0;
    EXPECT_EQ(message(dir / "nocam.exr", fov), "no error");

    {
        Imf::Header header(4, 4);
        header.channels().insert("A", Imf::Channel(Imf::FLOAT));
        Imf::OutputFile flat((dir / "flat.exr").string().c_str(), header);
        std::vector<float> a(16, 1.0f);
        Imf::FrameBuffer fb;
        fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(a.data()), sizeof(float), 4 * sizeof(float)));
        flat.setFrameBuffer(fb);
        flat.writePixels(4);
    }
    EXPECT_NE(message(dir / "flat.exr").find("not a deep image"), std::string::npos);
    EXPECT_NE(message(dir / "missing.exr").find("cannot open"), std::string::npos);
    std::FILE* text = std::fopen((dir / "text.exr").string().c_str(), "w");
    std::fputs("hello", text);
    std::fclose(text);
    EXPECT_NE(message(dir / "text.exr").find("not an OpenEXR file"), std::string::npos);
}

}  // namespace
}  // namespace dsm
