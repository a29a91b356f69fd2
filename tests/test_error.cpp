// dsm::Error's file and detail (dsm/error.h): the class itself, and the file
// that libdsm's entry points attach to their errors, so that a program learns
// which file failed without reading the message: a missing or damaged map
// (opened, validated, or failing on a tile read), a map read from memory under
// a name, a missing or refused EXR, bad scenes, maps that cannot be merged and
// outputs that cannot be written.
#include <dsm/dsm.h>
#include <dsm/exr_deep.h>
#include <dsm/map_images.h>
#include <dsm/merge.h>
#include <dsm/output_file.h>
#include <dsm/scene.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

using dsm::Error;
using dsm::ErrorCode;
using dsm::test::TempDir;

static_assert(std::is_nothrow_copy_constructible_v<Error>, "exceptions are copied while thrown");

// The dsm::Error that `action` throws; fails the test when it throws none.
Error errorOf(const std::function<void()>& action) {
    try {
        action();
    } catch (const Error& e) {
        return e;
    }
    ADD_FAILURE() << "no dsm::Error thrown";
    return Error(ErrorCode::internal, "none thrown");
}

// The error names `file`, and its detail is the end of its message without
// the quoted file, starting with `detailStart`.
void expectNames(const Error& e, const std::string& file, const std::string& detailStart) {
    EXPECT_EQ(e.file(), file) << e.what();
    const std::string detail = e.detail();
    EXPECT_EQ(detail.rfind(detailStart, 0), 0u) << "detail: " << detail;
    EXPECT_EQ(detail.find("'" + file + "'"), std::string::npos) << "detail quotes the file: " << detail;
    const std::string message = e.what();
    ASSERT_GE(message.size(), detail.size());
    EXPECT_EQ(message.substr(message.size() - detail.size()), detail);
}

// A small valid map at `path`: width x height, tiles of 4, one channel.
void writeSmallMap(const std::string& path, std::uint32_t width, std::uint32_t height) {
    std::mt19937_64 rng(7);
    const dsm::test::Image image = dsm::test::makeImage(width, height, [&](std::uint32_t, std::uint32_t) {
        return dsm::test::randomFunction(rng, 1, false, 1, 5, 1.0f);
    });
    dsm::WriterOptions options;
    options.tileSize = 4;
    options.tolerance = 0.01;
    dsm::test::writeMap(path, options, image);
}

TEST(ErrorFile, AnErrorWithoutAFileHasItsWholeMessageAsDetail) {
    const Error e(ErrorCode::argument, "merge: no input maps");
    EXPECT_TRUE(e.file().empty());
    EXPECT_STREQ(e.detail(), "merge: no input maps");
    EXPECT_STREQ(e.detail(), e.what());
}

TEST(ErrorFile, TheDetailFollowsTheQuotedFileAndItsSeparator) {
    expectNames(Error(ErrorCode::corrupt, "'a.dsm': metadata CRC-32 mismatch", "a.dsm"), "a.dsm",
                "metadata CRC-32 mismatch");
    expectNames(Error(ErrorCode::corrupt, "'a.dsm' level 1 tile 0,2: CRC-32 mismatch", "a.dsm"), "a.dsm",
                "level 1 tile 0,2: CRC-32 mismatch");
    expectNames(Error(ErrorCode::scene, "scene 'a.json': /light: missing", "a.json"), "a.json", "/light: missing");
    // A file name that itself holds a quote and a colon.
    expectNames(Error(ErrorCode::io, "'it's: here.dsm': cannot open", "it's: here.dsm"), "it's: here.dsm",
                "cannot open");
}

TEST(ErrorFile, AMessageThatDoesNotStartWithTheFileKeepsItAllAsDetail) {
    const Error e(ErrorCode::argument, "2 pairs of regions overlap: 'a.dsm' region 0,0,4,4", "a.dsm");
    EXPECT_EQ(e.file(), "a.dsm");
    EXPECT_STREQ(e.detail(), e.what());
    const Error quoted(ErrorCode::argument, "'b.dsm' and 'a.dsm' overlap", "a.dsm");
    EXPECT_STREQ(quoted.detail(), quoted.what());
    EXPECT_TRUE(Error(ErrorCode::argument, "'b.dsm' and 'a.dsm' overlap").withFile("a.dsm").file().empty());
}

TEST(ErrorFile, CopiesShareTheFileAndTheDetail) {
    const Error e(ErrorCode::io, "'x.dsm': cannot open: No such file or directory", "x.dsm");
    const Error copy = e;
    EXPECT_EQ(copy.file(), "x.dsm");
    EXPECT_STREQ(copy.detail(), "cannot open: No such file or directory");
    EXPECT_EQ(copy.code(), ErrorCode::io);
}

TEST(ErrorFile, WithFileNamesOnlyTheFileTheMessageStartsWith) {
    const Error plain(ErrorCode::corrupt, "'in.dsm' level 0 tile 1,1: unexpected end of file");
    const Error named = plain.withFile("in.dsm");
    EXPECT_EQ(named.code(), ErrorCode::corrupt);
    EXPECT_STREQ(named.what(), plain.what());
    expectNames(named, "in.dsm", "level 0 tile 1,1: unexpected end of file");

    EXPECT_TRUE(plain.withFile("other.dsm").file().empty());
    EXPECT_TRUE(plain.withFile("in").file().empty());  // a prefix of the name is not the name
    EXPECT_TRUE(plain.withFile("").file().empty());
    // A file already carried stays.
    EXPECT_EQ(named.withFile("other.dsm").file(), "in.dsm");
}

TEST(ErrorFile, AMissingMapNamesItsPath) {
    TempDir dir;
    const std::string path = (dir / "missing.dsm").string();
    expectNames(errorOf([&] { dsm::DeepShadowMap::open(path); }), path, "cannot open");
    expectNames(errorOf([&] { dsm::validate(path); }), path, "cannot open");
}

TEST(ErrorFile, ADamagedMapNamesItsPathOnOpenValidateAndTileReads) {
    TempDir dir;
    const std::string path = (dir / "damaged.dsm").string();
    writeSmallMap(path, 8, 8);
    std::vector<std::uint8_t> bytes = dsm::test::readFile(path);

    // A tile's data: open() succeeds; validate() and reading the tile fail.
    const dsm::TileSummary tile = dsm::DeepShadowMap::open(path)->tile(0, 1, 1);
    ASSERT_FALSE(tile.empty());
    bytes[tile.offset + 2] ^= 0x40;
    dsm::test::writeFile(path, bytes);
    expectNames(errorOf([&] { dsm::validate(path); }), path, "level 0 tile 1,1");
    const auto map = dsm::DeepShadowMap::open(path);
    expectNames(errorOf([&] { map->pixel(0, 5, 5); }), path, "level 0 tile 1,1");
    dsm::LookupContext lookups(map);
    dsm::LookupOptions levelZero;
    levelZero.level = 0;
    expectNames(errorOf([&] { lookups.raster(5.5, 5.5, 1.0, levelZero); }), path, "level 0 tile 1,1");
    expectNames(errorOf([&] { dsm::opacityImage(*map, 0); }), path, "level 0 tile 1,1");
    // Arguments about the map name it too.
    expectNames(errorOf([&] { map->pixel(7, 0, 0); }), path, "level 7 does not exist");
    expectNames(errorOf([&] { dsm::opacityImage(*map, 9); }), path, "level 9 does not exist");

    // The header: open() fails.
    bytes[0] ^= 0xFF;
    dsm::test::writeFile(path, bytes);
    expectNames(errorOf([&] { dsm::DeepShadowMap::open(path); }), path, "");
}

TEST(ErrorFile, AMapReadFromMemoryNamesTheNameItWasGiven) {
    const std::vector<std::uint8_t> garbage(300, 0x5A);
    const Error e = errorOf(
        [&] { dsm::DeepShadowMap::open(dsm::MapInput::memory(garbage.data(), garbage.size()), "buffer.dsm"); });
    expectNames(e, "buffer.dsm", "");
    EXPECT_EQ(e.code(), ErrorCode::format);
}

TEST(ErrorFile, DeepExrImportAndExportNameTheFileAtFault) {
    TempDir dir;
    const std::string map = (dir / "map.dsm").string();
    writeSmallMap(map, 8, 4);
    const std::string missingExr = (dir / "missing.exr").string();
    const std::string output = (dir / "out.dsm").string();
    expectNames(errorOf([&] { dsm::importDeepExr(missingExr, output, {}); }), missingExr, "cannot open");

    const std::string notExr = (dir / "text.exr").string();
    std::ofstream(notExr) << "not an image\n";
    expectNames(errorOf([&] { dsm::importDeepExr(notExr, output, {}); }), notExr, "");
    EXPECT_FALSE(std::filesystem::exists(output));

    dsm::ExrExportOptions level;
    level.level = 9;
    expectNames(errorOf([&] { dsm::exportDeepExr(map, (dir / "out.exr").string(), level); }), map,
                "level 9 does not exist");
    const std::string exrInMissingDirectory = (dir / "no" / "out.exr").string();
    expectNames(errorOf([&] { dsm::exportDeepExr(map, exrInMissingDirectory, {}); }), exrInMissingDirectory,
                "cannot write");
}

TEST(ErrorFile, SceneErrorsNameTheSceneFile) {
    TempDir dir;
    const std::string light = R"("light": {"type": "spot", "position": [0, 0, 0], "direction": [0, 0, 1]})";
    expectNames(errorOf([&] { dsm::parseScene("{" + light + R"(, "objects": 3})", "", "given.json"); }), "given.json",
                "/objects: expected");
    expectNames(errorOf([&] { dsm::parseScene("{ nope", "", "broken.json"); }), "broken.json", "invalid JSON");

    const std::string missing = (dir / "missing.json").string();
    expectNames(errorOf([&] { dsm::loadScene(missing); }), missing, "does not exist");

    // A file the scene names: the error is the scene's, at the key naming it.
    const std::string scene = (dir / "scene.json").string();
    std::ofstream(scene) << "{" << light << R"(, "objects": [{"type": "mesh", "file": "nope.obj"}]})";
    const Error e = errorOf([&] { dsm::loadScene(scene); });
    expectNames(e, scene, "/objects/0/file: OBJ file");

    // A path too long to quote in full is still carried whole.
    const std::string longPath = (dir / (std::string(400, 'd') + ".json")).string();
    expectNames(errorOf([&] { dsm::loadScene(longPath); }), longPath, "does not exist");

    std::istringstream in(R"({"light": 1})");
    expectNames(errorOf([&] { dsm::readScene(in, "", "<stdin>"); }), "<stdin>", "/light");
}

TEST(ErrorFile, MergeErrorsNameTheInputOrOutputAtFault) {
    TempDir dir;
    const std::string a = (dir / "a.dsm").string(), b = (dir / "b.dsm").string();
    writeSmallMap(a, 8, 8);
    writeSmallMap(b, 8, 4);
    const std::string output = (dir / "out.dsm").string();
    const Error mismatch = errorOf([&] { dsm::mergeMaps({a, b}, output, {}); });
    expectNames(mismatch, b, "the size is 8x4 but 8x8 in '" + a + "'");
    const std::string missing = (dir / "missing.dsm").string();
    expectNames(errorOf([&] { dsm::mergeMaps({a, missing}, output, {}); }), missing, "cannot open");
    expectNames(errorOf([&] { dsm::mergeMaps({a, b}, a, {}); }), a, "the output is also an input");
    EXPECT_TRUE(errorOf([&] { dsm::mergeMaps({}, output, {}); }).file().empty());
}

TEST(ErrorFile, OutputsThatCannotBeWrittenNameThemselves) {
    TempDir dir;
    const std::string inMissingDirectory = (dir / "none" / "out.dsm").string();
    expectNames(errorOf([&] { dsm::checkOutputPath(inMissingDirectory); }), inMissingDirectory, "cannot write");
    expectNames(errorOf([&] { dsm::OutputFile file(dir.path().string()); }), dir.path().string(), "");

    dsm::WriterOptions options;
    options.width = 4;
    options.height = 4;
    options.tileSize = 4;
    expectNames(errorOf([&] { dsm::MapWriter writer(inMissingDirectory, options); }), inMissingDirectory,
                "cannot write");
    const std::string out = (dir / "out.dsm").string();
    options.tileSize = 3;
    expectNames(errorOf([&] { dsm::MapWriter writer(out, options); }), out, "tile size 3");
    options.tileSize = 4;
    dsm::MapWriter writer(out, options);
    expectNames(errorOf([&] { writer.finish(); }), out, "level 0 tile 0,0 was never written");
    expectNames(errorOf([&] { writer.writeTile(3, 0, {}); }), out, "level 0 tile 3,0: outside");

    const std::string taken = (dir / "taken.dsm").string();
    std::ofstream(taken) << "x";
    expectNames(errorOf([&] { dsm::refuseOutputOverInputs(taken, {taken}); }), taken, "the output is also an input");
    const std::string sameAsOut = (dir / "." / "out.dsm").string();
    expectNames(errorOf([&] { dsm::refuseSharedOutputs({out, taken, sameAsOut}); }), sameAsOut, "is also the output");
}

}  // namespace
