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

// The content of the sample, as listed in the spec.
void writeTinySample(const std::string& path) {
    dsm::WriterOptions o;
    o.width = 2;
    o.height = 2;
    o.tileSize = 2;
    o.channels = 1;
    o.mipLevels = 1;
    o.zlibLevel = 0;
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

}  // namespace

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
