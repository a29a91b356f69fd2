// The committed sample spec/samples/tiny.dsm is the example of
// spec/dsm-format.md ("Annotated sample"). The reader must read it as the spec
// describes, and the writer must reproduce it byte for byte from the same
// content, so any change to the on-disk layout shows up here.
#include <gtest/gtest.h>

#include <dsm/dsm.h>

#include <cstdlib>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

const std::string kSample = std::string(DSM_SOURCE_DIR) + "/spec/samples/tiny.dsm";
const std::string kRichSample = std::string(DSM_SOURCE_DIR) + "/spec/samples/rich.dsm";
// The same content written by the first 1.1 writer (depth steps within each
// pixel, no PREDICTED_DEPTHS): readers keep reading such files.
const std::string kRichFirstCodingSample = std::string(DSM_SOURCE_DIR) + "/spec/samples/rich-first-coding.dsm";

// The content of the sample, as listed in the spec.
void writeTinySample(const std::string& path) {
    dsm::WriterOptions o;
    o.width = 2;
    o.height = 2;
    o.tileSize = 2;
    o.channels = 1;
    o.mipLevels = 1;
    o.zlibLevel = 0;
    o.formatMinor = 0;  // the 1.0 sample: 1.1 readers still read it
    o.tolerance = 0.125;
    o.filter = dsm::PixelFilter::Gaussian;
    o.filterWidth = 2.0;
    o.camera.projection = dsm::Projection::Orthographic;
    o.camera.screenWindow = {-1.0, 1.0, -1.0, 1.0};
    o.camera.nearPlane = 0.0;
    o.metadata = R"({"sample":"tiny"})";
    dsm::MapWriter writer(path, o);
    std::vector<dsm::VisibilityFunction> pixels(4);
    pixels[0].append(1.0f, 0.5f);   // (0,0): a half-opaque surface at z = 1
    // (1,0): empty, fully lit
    pixels[2].append(2.0f, 1.0f);   // (0,1): a ramp from z = 2 to z = 3
    pixels[2].append(3.0f, 0.0f);
    pixels[3].append(0.5f, 0.25f);  // (1,1)
    writer.writeTile(0, 0, pixels);
    writer.finish();
}

// The content of the 1.1 sample, as listed in the spec: RGB and monochrome
// pixels, counts, two layers (the second starting at the first's last
// depth), values on the level's step, four levels, empty, stored and
// compressed tiles, an area light.
dsm::VisibilityFunction richPixel(std::uint32_t x, std::uint32_t y) {
    dsm::VisibilityFunction f(3, true);
    const auto rgb = [&](float z, float r, float g, float b, std::uint32_t n) {
        const float v[3] = {r, g, b};
        f.append(z, v, n);
    };
    const auto mono = [&](float z, float v, std::uint32_t n) {
        if (f.channels() != 1) f = dsm::VisibilityFunction(1, true);
        f.append(z, v, n);
    };
    if (x == 0 && y == 0) {
        rgb(1.0f, 0.75f, 0.5f, 0.25f, 2);
        rgb(2.0f, 0.0f, 0.0f, 0.0f, 1);
    } else if (x == 1 && y == 0) {
        mono(1.5f, 0.5f, 1);
        mono(2.0f, 0.0f, 1);
        f.beginLayer();  // behind the opaque depth 2, starting at it
        mono(2.0f, 0.5f, 0);
        mono(3.0f, 0.25f, 1);
    } else if (x == 0 && y == 1) {
        for (int i = 0; i < 24; ++i) mono(1.0f + 0.125f * float(i), 1.0f - 0.03125f * float(i + 1), 1);
    } else if (x == 2 && y == 0) {
        mono(4.0f, 0.5f, 3);
    } else if (x == 0 && y == 2) {
        mono(0.5f, 0.75f, 1);
    } else if (x == 4 && y == 2) {
        rgb(1.0f, 1.0f, 0.5f, 0.0f, 1);
    }
    return f;
}

void writeRichSample(const std::string& path) {
    dsm::WriterOptions o;
    o.width = 5;
    o.height = 3;
    o.tileSize = 2;
    o.channels = 3;
    o.counts = true;
    o.maxLayers = 2;
    o.tolerance = 0.125;
    o.quantiseValues = true;
    o.zlibLevel = 9;
    o.filter = dsm::PixelFilter::Box;
    o.filterWidth = 1.0;
    o.camera.projection = dsm::Projection::Perspective;
    o.camera.screenWindow = {-0.5, 0.5, -0.5, 0.5};
    o.camera.nearPlane = 1.0;
    o.areaLightRadius = 0.5;
    o.areaLightPlaneDepth = 1.0;
    o.metadata = R"({"sample":"rich"})";
    dsm::test::writeMap(path, o, dsm::test::makeImage(o.width, o.height, richPixel));
}

}  // namespace

namespace {

void expectRichSampleAsSpecified(const std::string& sample, bool predictedDepths) {
    SCOPED_TRACE(sample);
    const auto map = dsm::DeepShadowMap::open(sample);
    const dsm::MapInfo& info = map->info();
    EXPECT_EQ(info.versionMinor, 1);
    EXPECT_TRUE(info.codedTiles);
    EXPECT_EQ(info.predictedDepths, predictedDepths);
    EXPECT_EQ(info.codecLevel, 9);
    EXPECT_EQ(info.areaLightRadius, 0.5);
    EXPECT_EQ(info.areaLightPlaneDepth, 1.0);
    EXPECT_EQ(info.channels, 3);
    EXPECT_TRUE(info.hasCounts);
    EXPECT_EQ(info.maxLayers, 2);
    ASSERT_EQ(info.levels.size(), 4u);
    EXPECT_EQ(info.levels[0].valueStep, 0.015625);
    EXPECT_EQ(info.levels[1].valueStep, 0.0078125);  // tolerance 0.0625
    // Every kind of tile: empty, stored, compressed.
    int empty = 0, stored = 0, compressed = 0;
    for (unsigned l = 0; l < info.levels.size(); ++l)
        for (std::uint32_t ty = 0; ty < info.levels[l].tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < info.levels[l].tilesX; ++tx) {
                const dsm::TileSummary t = map->tile(l, tx, ty);
                (t.empty() ? empty : t.storedBytes < t.rawBytes ? compressed : stored)++;
            }
    EXPECT_GT(empty, 0);
    EXPECT_GT(stored, 0);
    EXPECT_GT(compressed, 0);
    for (std::uint32_t y = 0; y < 3; ++y)
        for (std::uint32_t x = 0; x < 5; ++x) {
            const dsm::VisibilityFunction want = richPixel(x, y);
            if (want.empty())
                EXPECT_TRUE(map->pixel(0, x, y)->empty()) << "pixel " << x << "," << y;
            else
                EXPECT_TRUE(dsm::test::sameFunction(map->pixel(0, x, y).view(), want, true))
                    << "pixel " << x << "," << y;
        }
    EXPECT_EQ(map->pixel(0, 1, 0)->layerBegin(1), 2u);
    EXPECT_NO_THROW(dsm::validate(sample));
}

}  // namespace

TEST(Conformance, ReaderReadsTheRichSampleAsSpecified) { expectRichSampleAsSpecified(kRichSample, true); }

TEST(Conformance, ReaderReadsTheRichSampleOfTheFirstCodingAsSpecified) {
    expectRichSampleAsSpecified(kRichFirstCodingSample, false);
}

// Every level of the first coding's sample, mip levels included, reads as the
// same map written today: both depth codings give the same depths.
TEST(Conformance, FirstCodingSampleReadsAsTheMapWrittenToday) {
    dsm::test::TempDir dir;
    const std::string path = (dir / "rich.dsm").string();
    writeRichSample(path);
    const auto today = dsm::DeepShadowMap::open(path);
    const auto first = dsm::DeepShadowMap::open(kRichFirstCodingSample);
    ASSERT_TRUE(today->info().predictedDepths);
    ASSERT_FALSE(first->info().predictedDepths);
    ASSERT_EQ(first->info().levels.size(), today->info().levels.size());
    std::size_t compared = 0;
    for (unsigned l = 0; l < today->info().levels.size(); ++l) {
        const dsm::LevelInfo& L = today->info().levels[l];
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x) {
                const dsm::VisibilityFunction want = today->pixel(l, x, y).view().toFunction();
                ASSERT_TRUE(dsm::test::sameFunction(first->pixel(l, x, y).view(), want, true))
                    << "level " << l << " pixel " << x << "," << y;
                compared += want.size();
            }
    }
    EXPECT_GT(compared, 20u);
}

// Only the samples this writer produces: rich-first-coding.dsm is kept as the
// first 1.1 writer wrote it, which no writer of today reproduces.
TEST(Conformance, WriterReproducesTheRichSampleByteForByte) {
    dsm::test::TempDir dir;
    const std::string path = (dir / "rich.dsm").string();
    writeRichSample(path);
    if (std::getenv("DSM_REGENERATE_SAMPLES")) writeRichSample(kRichSample);
    const auto expected = dsm::test::readFile(kRichSample);
    const auto actual = dsm::test::readFile(path);
    ASSERT_EQ(actual.size(), expected.size());
    EXPECT_TRUE(actual == expected) << "the writer's bytes differ from spec/samples/rich.dsm";
}

TEST(Conformance, ReaderReadsTheSampleAsSpecified) {
    const auto map = dsm::DeepShadowMap::open(kSample);
    const dsm::MapInfo& info = map->info();
    EXPECT_EQ(info.versionMajor, 1);
    EXPECT_EQ(info.versionMinor, 0);
    EXPECT_EQ(info.width, 2u);
    EXPECT_EQ(info.height, 2u);
    EXPECT_EQ(info.tileSize, 2u);
    EXPECT_EQ(info.channels, 1);
    EXPECT_FALSE(info.hasCounts);
    EXPECT_EQ(info.maxLayers, 1);
    EXPECT_EQ(info.camera.projection, dsm::Projection::Orthographic);
    EXPECT_EQ(info.filter, dsm::PixelFilter::Gaussian);
    EXPECT_EQ(info.filterWidth, 2.0);
    ASSERT_EQ(info.levels.size(), 1u);
    EXPECT_EQ(info.levels[0].tolerance, 0.125);
    EXPECT_EQ(info.levels[0].vertexCount, 4u);
    EXPECT_EQ(info.levels[0].nonEmptyPixels, 3u);
    EXPECT_EQ(info.levels[0].storedBytes, 56u);
    EXPECT_EQ(info.metadata, R"({"sample":"tiny"})");
    EXPECT_EQ(info.fileBytes, 457u);

    EXPECT_EQ(map->pixel(0, 0, 0)->size(), 1u);
    EXPECT_EQ(map->pixel(0, 0, 0)->z(0), 1.0f);
    EXPECT_EQ(map->pixel(0, 0, 0)->value(0), 0.5f);
    EXPECT_TRUE(map->pixel(0, 1, 0)->empty());
    EXPECT_EQ(map->pixel(0, 0, 1)->size(), 2u);
    EXPECT_DOUBLE_EQ(map->pixel(0, 0, 1)->evaluate(2.5), 0.5);
    EXPECT_EQ(map->pixel(0, 1, 1)->value(0), 0.25f);
    const dsm::TileSummary t = map->tile(0, 0, 0);
    EXPECT_EQ(t.offset, 272u);
    EXPECT_EQ(t.storedBytes, 56u);
    EXPECT_EQ(t.rawBytes, 56u);
    EXPECT_EQ(t.minZ, 0.5f);
    EXPECT_EQ(t.maxZ, 3.0f);
    EXPECT_NO_THROW(dsm::validate(kSample));
}

TEST(Conformance, WriterReproducesTheSampleByteForByte) {
    dsm::test::TempDir dir;
    const std::string path = (dir / "tiny.dsm").string();
    writeTinySample(path);
    if (std::getenv("DSM_REGENERATE_SAMPLES")) writeTinySample(kSample);
    const auto expected = dsm::test::readFile(kSample);
    const auto actual = dsm::test::readFile(path);
    ASSERT_EQ(actual.size(), expected.size());
    EXPECT_TRUE(actual == expected) << "the writer's bytes differ from spec/samples/tiny.dsm";
}
