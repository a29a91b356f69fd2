// MapWriter's promises (writer.h): output goes to a temporary file beside the
// path and is renamed into place by finish() only; a writer destroyed without
// finish(), or one whose writeTile() or finish() threw, leaves no file at the
// path, no temporary file, and an existing file at the path untouched. Invalid
// pixels are refused with an error naming the file, tile and pixel; missing and
// duplicate tiles and bad options are refused.
#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <mutex>
#include <random>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

using dsm::MapWriter;
using dsm::VisibilityFunction;
using dsm::WriterOptions;
using dsm::test::TempDir;
using Names = std::vector<std::string>;

VisibilityFunction ramp(float z0, int channels = 1, bool counts = false) {
    VisibilityFunction f(channels, counts);
    const float a[3] = {1.0f, 0.9f, 0.8f}, b[3] = {0.4f, 0.3f, 0.2f};
    f.append(z0, a, 2);
    f.append(z0 + 1.0f, b, 3);
    return f;
}

std::vector<VisibilityFunction> tile(const MapWriter& w, std::uint32_t tx, std::uint32_t ty, float z0 = 1.0f,
                                     int channels = 1, bool counts = false) {
    return std::vector<VisibilityFunction>(std::size_t(w.tileWidth(tx)) * w.tileHeight(ty), ramp(z0, channels, counts));
}

WriterOptions smallOptions() {
    WriterOptions o;
    o.width = 12;
    o.height = 8;
    o.tileSize = 4;  // 3 x 2 tiles
    return o;
}

void writeAll(MapWriter& w, float z0 = 1.0f) {
    for (std::uint32_t ty = 0; ty < w.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < w.tilesX(); ++tx) w.writeTile(tx, ty, tile(w, tx, ty, z0));
}

std::string messageOf(const std::function<void()>& action) {
    try {
        action();
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "no error";
}

TEST(WriterSafety, DestroyedWithoutFinishLeavesNoFile) {
    TempDir dir;
    const auto path = dir / "map.dsm";
    {
        MapWriter w(path.string(), smallOptions());
        w.writeTile(0, 0, tile(w, 0, 0));
        w.writeTile(2, 1, tile(w, 2, 1));
        // Meanwhile: one temporary file beside the path, nothing at the path.
        const Names during = dsm::test::listDirectory(dir.path());
        ASSERT_EQ(during.size(), 1u);
        EXPECT_EQ(during[0].rfind(".map.dsm.tmp", 0), 0u) << during[0];
        EXPECT_FALSE(std::filesystem::exists(path));
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{});
    {
        MapWriter w(path.string(), smallOptions());  // nothing written at all
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{});
}

TEST(WriterSafety, FinishRenamesIntoPlaceAndLeavesNoTemporaryFile) {
    TempDir dir;
    const auto path = dir / "map.dsm";
    {
        MapWriter w(path.string(), smallOptions());
        writeAll(w);
        w.finish();
        EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{"map.dsm"});
        EXPECT_THROW(w.finish(), dsm::Error);                     // twice
        EXPECT_THROW(w.writeTile(0, 0, tile(w, 0, 0)), dsm::Error);  // after finishing
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{"map.dsm"});
    EXPECT_NO_THROW(dsm::validate(path.string()));
}

struct BadPixel {
    std::string name;
    WriterOptions options;
    VisibilityFunction pixel;
    std::string expected;  // part of the message
};

// gtest prints parameters by name.
void PrintTo(const BadPixel& c, std::ostream* os) { *os << c.name; }

std::vector<BadPixel> badPixels() {
    std::vector<BadPixel> out;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    {
        VisibilityFunction f(1);
        f.append(1.0f, 0.5f);
        f.append(nan, 0.25f);
        out.push_back({"nan_depth", smallOptions(), f, "depth nan is not finite"});
    }
    {
        VisibilityFunction f(1);
        f.append(1.0f, 0.5f);
        f.append(2.0f, 0.75f);
        out.push_back({"increasing_visibility", smallOptions(), f, "increases"});
    }
    {
        VisibilityFunction f(1);
        f.append(-1.0f, 0.5f);
        out.push_back({"negative_depth", smallOptions(), f, "negative"});
    }
    {
        VisibilityFunction f(1);
        f.append(1.0f, 1.5f);
        out.push_back({"value_above_one", smallOptions(), f, "outside [0, 1]"});
    }
    {
        VisibilityFunction f(1);
        f.append(2.0f, 0.5f);
        f.append(1.0f, 0.25f);
        out.push_back({"decreasing_depth", smallOptions(), f, "less than the previous depth"});
    }
    out.push_back({"rgb_pixel_in_mono_map", smallOptions(), ramp(1.0f, 3), "RGB function in a monochrome map"});
    {
        VisibilityFunction f(1);
        f.append(1.0f, 0.1f);
        f.beginLayer();
        f.append(2.0f, 0.5f);
        f.beginLayer();
        f.append(3.0f, 0.5f);
        WriterOptions o = smallOptions();
        o.maxLayers = 2;
        out.push_back({"too_many_layers", o, f, "3 layers exceed the map's 2"});
        out.push_back({"layers_in_single_layer_map", smallOptions(), f, "3 layers exceed the map's 1"});
    }
    {
        WriterOptions o = smallOptions();
        o.counts = true;
        out.push_back({"counts_missing", o, ramp(1.0f), "has none"});
    }
    return out;
}

class WriterBadPixel : public ::testing::TestWithParam<BadPixel> {};

TEST_P(WriterBadPixel, IsRefusedNamingTileAndPixelAndLeavesNoFile) {
    const BadPixel& bad = GetParam();
    TempDir dir;
    const auto path = dir / "map.dsm";
    const bool counts = bad.options.counts;
    {
        MapWriter w(path.string(), bad.options);
        w.writeTile(0, 0, tile(w, 0, 0, 1.0f, 1, counts));
        std::vector<VisibilityFunction> pixels = tile(w, 2, 1, 1.0f, 1, counts);
        pixels[2 * 4 + 1] = bad.pixel;  // row 2, column 1 of tile 2,1: pixel (9, 6)
        const std::string m = messageOf([&] { w.writeTile(2, 1, pixels); });
        EXPECT_NE(m.find(path.string()), std::string::npos) << m;
        EXPECT_NE(m.find("tile 2,1"), std::string::npos) << m;
        EXPECT_NE(m.find("pixel 9,6"), std::string::npos) << m;
        EXPECT_NE(m.find(bad.expected), std::string::npos) << m;
        EXPECT_FALSE(std::filesystem::exists(path));
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{});
}

INSTANTIATE_TEST_SUITE_P(Kinds, WriterBadPixel, ::testing::ValuesIn(badPixels()),
                         [](const ::testing::TestParamInfo<BadPixel>& i) { return i.param.name; });

TEST(WriterSafety, FinishWithAMissingTileNamesItAndLeavesNoFile) {
    TempDir dir;
    const auto path = dir / "map.dsm";
    {
        MapWriter w(path.string(), smallOptions());
        for (std::uint32_t ty = 0; ty < 2; ++ty)
            for (std::uint32_t tx = 0; tx < 3; ++tx)
                if (!(tx == 1 && ty == 1)) w.writeTile(tx, ty, tile(w, tx, ty));
        const std::string m = messageOf([&] { w.finish(); });
        EXPECT_NE(m.find(path.string()), std::string::npos) << m;
        EXPECT_NE(m.find("tile 1,1"), std::string::npos) << m;
        EXPECT_NE(m.find("never written"), std::string::npos) << m;
        EXPECT_FALSE(std::filesystem::exists(path));
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{});
}

TEST(WriterSafety, WritingATileTwiceIsRefused) {
    TempDir dir;
    const auto path = dir / "map.dsm";
    {
        MapWriter w(path.string(), smallOptions());
        w.writeTile(1, 0, tile(w, 1, 0));
        const std::string m = messageOf([&] { w.writeTile(1, 0, tile(w, 1, 0, 2.0f)); });
        EXPECT_NE(m.find(path.string()), std::string::npos) << m;
        EXPECT_NE(m.find("tile 1,0"), std::string::npos) << m;
        EXPECT_NE(m.find("written twice"), std::string::npos) << m;
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{});
}

TEST(WriterSafety, WrongTilesAreRefused) {
    TempDir dir;
    const auto path = dir / "map.dsm";
    {
        MapWriter w(path.string(), smallOptions());
        EXPECT_NE(messageOf([&] { w.writeTile(3, 0, tile(w, 0, 0)); }).find("outside the 3x2 tiles"), std::string::npos);
        EXPECT_NE(messageOf([&] { w.writeTile(0, 2, tile(w, 0, 0)); }).find("tile 0,2"), std::string::npos);
        std::vector<VisibilityFunction> shortTile(15, ramp(1.0f));
        const std::string m = messageOf([&] { w.writeTile(0, 1, shortTile); });
        EXPECT_NE(m.find("tile 0,1"), std::string::npos) << m;
        EXPECT_NE(m.find("15 pixels given"), std::string::npos) << m;
        // A refused tile is not counted as written: it can still be written.
        writeAll(w);
        w.finish();
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{"map.dsm"});
    EXPECT_NO_THROW(dsm::validate(path.string()));
}

TEST(WriterSafety, AnExistingFileIsUntouchedUntilFinishSucceeds) {
    TempDir dir;
    const auto path = dir / "map.dsm";
    {
        MapWriter old(path.string(), smallOptions());
        writeAll(old, 1.0f);
        old.finish();
    }
    const std::vector<std::uint8_t> before = dsm::test::readFile(path);
    ASSERT_FALSE(before.empty());

    // A writer that fails in writeTile, then is destroyed.
    {
        MapWriter w(path.string(), smallOptions());
        w.writeTile(0, 0, tile(w, 0, 0, 5.0f));
        EXPECT_EQ(dsm::test::readFile(path), before);
        std::vector<VisibilityFunction> bad = tile(w, 1, 0, 5.0f);
        bad[0] = ramp(1.0f, 3);
        EXPECT_THROW(w.writeTile(1, 0, bad), dsm::Error);
        EXPECT_EQ(dsm::test::readFile(path), before);
    }
    EXPECT_EQ(dsm::test::readFile(path), before);
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{"map.dsm"});

    // A writer that fails in finish().
    {
        MapWriter w(path.string(), smallOptions());
        w.writeTile(2, 1, tile(w, 2, 1, 5.0f));
        EXPECT_THROW(w.finish(), dsm::Error);
        EXPECT_EQ(dsm::test::readFile(path), before);
    }
    EXPECT_EQ(dsm::test::readFile(path), before);
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{"map.dsm"});

    // A writer that is simply abandoned after writing every tile.
    {
        MapWriter w(path.string(), smallOptions());
        writeAll(w, 5.0f);
        EXPECT_EQ(dsm::test::readFile(path), before);
    }
    EXPECT_EQ(dsm::test::readFile(path), before);
    {
        const auto map = dsm::DeepShadowMap::open(path.string());
        EXPECT_EQ(map->pixel(0, 7, 7)->z(0), 1.0f);
    }

    // One that succeeds replaces the file.
    {
        MapWriter w(path.string(), smallOptions());
        writeAll(w, 5.0f);
        EXPECT_EQ(dsm::test::readFile(path), before);
        w.finish();
    }
    EXPECT_NE(dsm::test::readFile(path), before);
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{"map.dsm"});
    const auto map = dsm::DeepShadowMap::open(path.string());
    EXPECT_EQ(map->pixel(0, 7, 7)->z(0), 5.0f);
}

TEST(WriterSafety, AnExistingNonMapFileIsUntouchedByAFailedWriter) {
    TempDir dir;
    const auto path = dir / "precious.dsm";
    const std::vector<std::uint8_t> text = {'k', 'e', 'e', 'p', '\n'};
    dsm::test::writeFile(path, text);
    {
        MapWriter w(path.string(), smallOptions());
        w.writeTile(0, 0, tile(w, 0, 0));
    }
    EXPECT_EQ(dsm::test::readFile(path), text);
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{"precious.dsm"});
}

TEST(WriterSafety, BadOptionsAreRefusedWithoutLeavingFiles) {
    TempDir dir;
    const auto path = (dir / "map.dsm").string();
    auto refused = [&](WriterOptions o, const std::string& expected) {
        const std::string m = messageOf([&] { MapWriter w(path, o); });
        EXPECT_NE(m.find(path), std::string::npos) << m;
        EXPECT_NE(m.find(expected), std::string::npos) << m;
    };
    WriterOptions o = smallOptions();
    o.width = 0;
    refused(o, "image size 0x8");
    o = smallOptions();
    o.tileSize = 6;
    refused(o, "tile size 6");
    o.tileSize = 1;
    refused(o, "tile size 1");
    o.tileSize = 8192;
    refused(o, "tile size 8192");
    o = smallOptions();
    o.channels = 2;
    refused(o, "channel count 2");
    o = smallOptions();
    o.maxLayers = 0;
    refused(o, "layer count 0");
    o.maxLayers = 256;
    refused(o, "layer count 256");
    o = smallOptions();
    o.zlibLevel = 10;
    refused(o, "zlib level 10");
    o = smallOptions();
    o.tolerance = -0.1;
    refused(o, "tolerance");
    o = smallOptions();
    o.camera.screenWindow = {1.0, 1.0, -1.0, 1.0};
    refused(o, "screen window");
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{});
    // A directory that does not exist.
    const std::string nowhere = (dir / "missing" / "map.dsm").string();
    const std::string m = messageOf([&] { MapWriter w(nowhere, smallOptions()); });
    EXPECT_NE(m.find(nowhere), std::string::npos) << m;
}

// Tiles prepared on several threads (MapWriter::prepareTile()) while the
// writer appends the ones ready, in row order, give the file writeTile()
// gives, byte for byte: an odd-sized map of small tiles with value steps,
// counts, mip levels, RGB and empty tiles, so that the coarser levels average
// edge pixels and tiles of no pixels. Run under ThreadSanitizer too.
std::vector<VisibilityFunction> randomTile(const MapWriter& w, std::uint32_t tx, std::uint32_t ty) {
    std::mt19937 rng(1000 * ty + tx);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<VisibilityFunction> pixels(std::size_t(w.tileWidth(tx)) * w.tileHeight(ty));
    if ((tx + 2 * ty) % 5 == 0) {
        for (VisibilityFunction& f : pixels) f = VisibilityFunction(1, true);  // a tile of empty pixels
        return pixels;
    }
    for (VisibilityFunction& f : pixels) {
        const int channels = rng() % 4 == 0 ? 3 : 1;
        f = VisibilityFunction(channels, true);
        float z = 1.0f + unit(rng), v[3] = {1.0f, 1.0f, 1.0f};
        const int vertices = static_cast<int>(rng() % 6);
        for (int i = 0; i < vertices; ++i) {
            for (int c = 0; c < channels; ++c) v[c] *= unit(rng);
            f.append(z, v, 1 + rng() % 9);
            z += 0.01f + unit(rng);
        }
    }
    return pixels;
}

WriterOptions preparedOptions() {
    WriterOptions o;
    o.width = 37;
    o.height = 22;
    o.tileSize = 4;  // 10 x 6 tiles, the last of each row and column partial
    o.channels = 3;
    o.counts = true;
    o.tolerance = 0.05;
    o.quantiseValues = true;
    return o;
}

std::string contentsOf(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

TEST(PreparedTiles, PreparedOnThreadsGiveTheFileWriteTileGives) {
    TempDir dir;
    const auto serialPath = dir / "serial.dsm", preparedPath = dir / "prepared.dsm";
    {
        MapWriter w(serialPath.string(), preparedOptions());
        for (std::uint32_t ty = 0; ty < w.tilesY(); ++ty)
            for (std::uint32_t tx = 0; tx < w.tilesX(); ++tx) w.writeTile(tx, ty, randomTile(w, tx, ty));
        w.finish();
    }
    {
        MapWriter w(preparedPath.string(), preparedOptions());
        const std::uint32_t tiles = w.tilesX() * w.tilesY();
        std::vector<std::vector<VisibilityFunction>> pixels(tiles);
        std::vector<dsm::PreparedTile> prepared(tiles);
        std::vector<std::atomic<bool>> ready(tiles);
        std::atomic<std::uint32_t> next{0};
        std::atomic<bool> failed{false};
        std::mutex failureMutex;
        std::string failure;
        std::vector<std::thread> workers;
        for (int k = 0; k < 3; ++k)
            workers.emplace_back([&] {
                try {
                    for (std::uint32_t i; (i = next++) < tiles;) {
                        const std::uint32_t tx = i % w.tilesX(), ty = i / w.tilesX();
                        pixels[i] = randomTile(w, tx, ty);
                        w.prepareTile(tx, ty, pixels[i], prepared[i]);
                        ready[i].store(true, std::memory_order_release);
                    }
                } catch (const std::exception& e) {
                    const std::lock_guard<std::mutex> lock(failureMutex);
                    failure = e.what();
                    failed = true;
                }
            });
        // The writer's thread appends each tile as soon as it and those before it are ready.
        for (std::uint32_t i = 0; i < tiles && !failed; ++i) {
            while (!ready[i].load(std::memory_order_acquire) && !failed) std::this_thread::yield();
            if (!failed) w.writePreparedTile(prepared[i]);
        }
        for (std::thread& t : workers) t.join();
        ASSERT_FALSE(failed) << failure;
        w.finish();
    }
    const std::string serial = contentsOf(serialPath), fromPrepared = contentsOf(preparedPath);
    ASSERT_GT(serial.size(), 1000u);
    EXPECT_TRUE(serial == fromPrepared) << serial.size() << " bytes against " << fromPrepared.size();
    EXPECT_NO_THROW(dsm::validate(preparedPath.string()));
}

TEST(PreparedTiles, TilesNotReadyOrWrittenBeforeAreRefused) {
    TempDir dir;
    const auto path = dir / "map.dsm";
    {
        MapWriter w(path.string(), preparedOptions());
        dsm::PreparedTile never;
        std::string m = messageOf([&] { w.writePreparedTile(never); });
        EXPECT_NE(m.find(path.string()), std::string::npos) << m;
        EXPECT_NE(m.find("not prepared"), std::string::npos) << m;

        // Written once only.
        std::vector<VisibilityFunction> pixels = randomTile(w, 1, 0);
        dsm::PreparedTile t;
        w.prepareTile(1, 0, pixels, t);
        w.writePreparedTile(t);
        m = messageOf([&] { w.writePreparedTile(t); });
        EXPECT_NE(m.find("written already"), std::string::npos) << m;

        // A tile written by writeTile() before.
        w.writeTile(2, 0, randomTile(w, 2, 0));
        pixels = randomTile(w, 2, 0);
        w.prepareTile(2, 0, pixels, t);
        m = messageOf([&] { w.writePreparedTile(t); });
        EXPECT_NE(m.find("tile 2,0"), std::string::npos) << m;
        EXPECT_NE(m.find("written twice"), std::string::npos) << m;

        // A failed preparation names the tile and pixel, leaves the tile not
        // ready and its pixels as they were.
        pixels = randomTile(w, 3, 0);
        pixels.back() = ramp(1.0f, 3, false);  // no counts in a map of counts
        const std::vector<VisibilityFunction> before = pixels;
        m = messageOf([&] { w.prepareTile(3, 0, pixels, t); });
        EXPECT_NE(m.find("tile 3,0 pixel 15,3"), std::string::npos) << m;
        EXPECT_NE(m.find("sample counts"), std::string::npos) << m;
        for (std::size_t p = 0; p < pixels.size(); ++p)
            ASSERT_TRUE(pixels[p].view().allValues().size() == before[p].view().allValues().size() &&
                        std::equal(pixels[p].view().allValues().begin(), pixels[p].view().allValues().end(),
                                   before[p].view().allValues().begin()))
                << "pixel " << p;
        m = messageOf([&] { w.writePreparedTile(t); });
        EXPECT_NE(m.find("not prepared"), std::string::npos) << m;
        m = messageOf([&] { w.prepareTile(10, 0, pixels, t); });
        EXPECT_NE(m.find("outside the 10x6 tiles"), std::string::npos) << m;
    }
    EXPECT_EQ(dsm::test::listDirectory(dir.path()), Names{});
}

}  // namespace
