// Farm builds (dsm/farm.h, dsm/farm_jobs.h): the plan along map tiles, the
// build key and the content hash, part records and their verification,
// stitching, and the job descriptions' index ranges.
#include <dsm/error.h>
#include <dsm/farm.h>
#include <dsm/farm_jobs.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "sha256.h"
#include "temp_dir.h"

namespace fs = std::filesystem;

namespace {

std::string readFile(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

void appendTo(const fs::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary | std::ios::app);
    out << text;
}

/// The leaves example at 64 x 48 with tiles of 8 and 4 samples per pixel: small, RGB, and not
/// a multiple of the parts.
dsm::BuildOptions smallOptions() {
    dsm::BuildOptions o;
    o.width = 64;
    o.height = 48;
    o.tileSize = 8;
    o.samplesPerPixel = 4;
    o.threads = 1;
    return o;
}

dsm::Scene leaves() { return dsm::loadScene(std::string(DSM_SOURCE_DIR) + "/examples/leaves.json"); }

std::string errorOf(const std::function<void()>& f) {
    try {
        f();
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "(no error)";
}

}  // namespace

TEST(FarmPlan, GridForCountIsAsSquareAsTheCountAllows) {
    EXPECT_EQ(dsm::farmGridForCount(16).columns, 4u);
    EXPECT_EQ(dsm::farmGridForCount(16).rows, 4u);
    EXPECT_EQ(dsm::farmGridForCount(8).columns, 4u);
    EXPECT_EQ(dsm::farmGridForCount(8).rows, 2u);
    EXPECT_EQ(dsm::farmGridForCount(7).columns, 7u);
    EXPECT_EQ(dsm::farmGridForCount(7).rows, 1u);
    EXPECT_EQ(dsm::farmGridForCount(1).count(), 1u);
    EXPECT_THROW(dsm::farmGridForCount(0), dsm::Error);
    EXPECT_THROW(dsm::farmGridForCount(65537), dsm::Error);
}

TEST(FarmPlan, PartsFollowTileEdgesAndCoverTheMapOnce) {
    // 100 x 70 pixels in tiles of 16: 7 x 5 tiles, cut 3 x 2.
    const dsm::FarmPlan plan = dsm::planFarm(100, 70, 16, {3, 2});
    ASSERT_EQ(plan.parts.size(), 6u);
    std::vector<int> covered(100 * 70, 0);
    for (std::uint32_t i = 0; i < plan.parts.size(); ++i) {
        const auto& r = plan.parts[i].region;
        EXPECT_EQ(plan.parts[i].index, i);
        EXPECT_LT(r[0], r[2]);
        EXPECT_LT(r[1], r[3]);
        for (int k = 0; k < 4; ++k) {
            const std::uint32_t edge = k % 2 == 0 ? 100 : 70;
            EXPECT_TRUE(r[k] % 16 == 0 || r[k] == edge) << "part " << i << " edge " << k << " = " << r[k];
        }
        for (std::uint32_t y = r[1]; y < r[3]; ++y)
            for (std::uint32_t x = r[0]; x < r[2]; ++x) ++covered[y * 100 + x];
    }
    for (const int c : covered) ASSERT_EQ(c, 1);
    // Row-major: part 1 is right of part 0, part 3 below it; columns of 2, 2 and 3 tiles.
    EXPECT_EQ(plan.parts[1].region[0], plan.parts[0].region[2]);
    EXPECT_EQ(plan.parts[3].region[1], plan.parts[0].region[3]);
    EXPECT_EQ(plan.parts[0].region[2], 32u);
    EXPECT_EQ(plan.parts[1].region[2], 64u);
}

TEST(FarmPlan, RefusesMorePartsThanTiles) {
    const std::string message = errorOf([] { dsm::planFarm(64, 64, 32, {3, 1}); });
    EXPECT_NE(message.find("3x1 parts do not fit the 2x2 tiles"), std::string::npos) << message;
    EXPECT_THROW(dsm::planFarm(0, 64, 32, {1, 1}), dsm::Error);
}

TEST(FarmKey, Sha256MatchesTheStandardVectors) {
    dsm::detail::Sha256 abc;
    abc.update("abc");
    EXPECT_EQ(abc.hex(), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    dsm::detail::Sha256 two;  // two blocks
    two.update("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq");
    EXPECT_EQ(two.hex(), "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
    dsm::detail::Sha256 empty;
    EXPECT_EQ(empty.hex(), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

TEST(FarmKey, SceneHashFollowsTheContentOfTheSceneAndItsFilesNotTheirNames) {
    const dsm::test::TempDir dir;
    for (const char* sub : {"a", "b"}) {
        fs::create_directories(dir / sub);
        fs::copy_file(fs::path(DSM_SOURCE_DIR) / "examples/cloud-and-pipes.json", dir / sub / "scene.json");
        fs::copy_file(fs::path(DSM_SOURCE_DIR) / "examples/pipes.obj", dir / sub / "pipes.obj");
    }
    fs::rename(dir / "b" / "scene.json", dir / "b" / "other-name.json");
    const dsm::Scene a = dsm::loadScene((dir / "a" / "scene.json").string());
    const dsm::Scene b = dsm::loadScene((dir / "b" / "other-name.json").string());
    ASSERT_FALSE(a.files.empty());
    EXPECT_EQ(dsm::sceneContentHash(a), dsm::sceneContentHash(b));
    EXPECT_EQ(dsm::farmBuildKey(a, smallOptions(), {2, 2}), dsm::farmBuildKey(b, smallOptions(), {2, 2}));
    appendTo(dir / "b" / "pipes.obj", "# a comment changes the bytes\n");
    EXPECT_NE(dsm::sceneContentHash(a), dsm::sceneContentHash(dsm::loadScene((dir / "b" / "other-name.json").string())));
}

TEST(FarmKey, RecordsEveryOptionThatChangesTheBytes) {
    const dsm::Scene scene = leaves();
    const dsm::FarmBuildKey base = dsm::farmBuildKey(scene, smallOptions(), {2, 2});
    dsm::BuildOptions seed = smallOptions();
    seed.seed = 2;
    dsm::BuildOptions zlib = smallOptions();
    zlib.zlibLevel = 1;
    dsm::BuildOptions sampler = smallOptions();
    sampler.sampler = dsm::SamplerMethod::raytrace;  // the metadata records it
    dsm::BuildOptions threads = smallOptions();
    threads.threads = 2;  // does not change the bytes
    EXPECT_NE(dsm::farmBuildKey(scene, seed, {2, 2}), base);
    EXPECT_NE(dsm::farmBuildKey(scene, zlib, {2, 2}), base);
    EXPECT_NE(dsm::farmBuildKey(scene, sampler, {2, 2}), base);
    EXPECT_NE(dsm::farmBuildKey(scene, smallOptions(), {4, 1}), base);
    EXPECT_EQ(dsm::farmBuildKey(scene, threads, {2, 2}), base);
}

TEST(FarmParts, StitchedPartsEqualTheOneMachineBuildByteForByte) {
    const dsm::test::TempDir dir;
    const dsm::Scene scene = leaves();
    dsm::buildMap(scene, smallOptions(), (dir / "one.dsm").string());
    const dsm::FarmGrid grid{3, 2};
    for (std::uint32_t i = 0; i < grid.count(); ++i)
        EXPECT_FALSE(dsm::buildFarmPart(scene, smallOptions(), grid, i, dir.path().string()).skipped);
    dsm::stitchFarmParts(dir.path().string(), (dir / "farm.dsm").string());
    EXPECT_EQ(readFile(dir / "farm.dsm"), readFile(dir / "one.dsm"));
}

TEST(FarmParts, ASoundPartIsSkippedADamagedOneRebuilt) {
    const dsm::test::TempDir dir;
    const dsm::Scene scene = leaves();
    const dsm::FarmGrid grid{2, 1};
    const std::string parts = dir.path().string();
    const dsm::FarmBuildKey key = dsm::farmBuildKey(scene, smallOptions(), grid);
    EXPECT_EQ(dsm::checkFarmPart(parts, 1, key).state, dsm::FarmPartState::Missing);
    dsm::buildFarmPart(scene, smallOptions(), grid, 1, parts);
    EXPECT_EQ(dsm::checkFarmPart(parts, 1, key).state, dsm::FarmPartState::Done);
    EXPECT_TRUE(dsm::buildFarmPart(scene, smallOptions(), grid, 1, parts).skipped);

    const std::string good = readFile(dsm::farmPartPath(parts, 1));
    appendTo(dsm::farmPartPath(parts, 1), "x");
    const dsm::FarmPartCheck damaged = dsm::checkFarmPart(parts, 1, key);
    EXPECT_EQ(damaged.state, dsm::FarmPartState::Damaged);
    EXPECT_NE(damaged.reason.find("part-0001"), std::string::npos) << damaged.reason;
    EXPECT_FALSE(dsm::buildFarmPart(scene, smallOptions(), grid, 1, parts).skipped);
    EXPECT_EQ(readFile(dsm::farmPartPath(parts, 1)), good);

    std::ofstream(dsm::farmPartRecordPath(parts, 1)) << "{ not json";
    EXPECT_EQ(dsm::checkFarmPart(parts, 1, key).state, dsm::FarmPartState::Damaged);
}

TEST(FarmParts, StitchRefusesMissingAndMixedParts) {
    const dsm::test::TempDir dir;
    const dsm::Scene scene = leaves();
    const dsm::FarmGrid grid{2, 2};
    const std::string parts = dir.path().string(), output = (dir / "out.dsm").string();
    EXPECT_NE(errorOf([&] { dsm::stitchFarmParts(parts, output); }).find("holds no sound farm part"),
              std::string::npos);
    dsm::buildFarmPart(scene, smallOptions(), grid, 0, parts);
    dsm::buildFarmPart(scene, smallOptions(), grid, 2, parts);
    std::string message = errorOf([&] { dsm::stitchFarmParts(parts, output); });
    EXPECT_NE(message.find("2 of 4 parts missing (1, 3)"), std::string::npos) << message;
    EXPECT_FALSE(fs::exists(output));

    dsm::BuildOptions otherSeed = smallOptions();
    otherSeed.seed = 7;
    dsm::buildFarmPart(scene, otherSeed, grid, 1, parts);
    dsm::buildFarmPart(scene, smallOptions(), grid, 3, parts);
    message = errorOf([&] { dsm::stitchFarmParts(parts, output); });
    EXPECT_NE(message.find("parts of different builds"), std::string::npos) << message;
    EXPECT_NE(message.find("field 'seed' is 7 in"), std::string::npos) << message;
    EXPECT_NE(message.find("part-0001.dsm"), std::string::npos) << message;
    EXPECT_FALSE(fs::exists(output));

    // A part written with another tile codec is another build too.
    dsm::BuildOptions zstd = smallOptions();
    zstd.codec = dsm::TileCodec::Zstd;
    EXPECT_FALSE(dsm::buildFarmPart(scene, zstd, grid, 1, parts).skipped);
    message = errorOf([&] { dsm::stitchFarmParts(parts, output); });
    EXPECT_NE(message.find("field 'codec' is zstd in"), std::string::npos) << message;
    EXPECT_FALSE(fs::exists(output));

    // Rebuilt with the right seed, part 1 replaces the other build's.
    EXPECT_FALSE(dsm::buildFarmPart(scene, smallOptions(), grid, 1, parts).skipped);
    dsm::stitchFarmParts(parts, output);
    EXPECT_TRUE(fs::exists(output));
}

TEST(FarmParts, BuildRefusesAnIndexOutsideThePlanAndARegion) {
    const dsm::test::TempDir dir;
    const dsm::Scene scene = leaves();
    EXPECT_NE(errorOf([&] { dsm::buildFarmPart(scene, smallOptions(), {2, 2}, 4, dir.path().string()); })
                  .find("part index 4 is outside the 4 parts"),
              std::string::npos);
    dsm::BuildOptions region = smallOptions();
    region.region = {0, 0, 8, 8};
    EXPECT_THROW(dsm::buildFarmPart(scene, region, {2, 2}, 0, dir.path().string()), dsm::Error);
}

TEST(FarmJobs, IndexRangesRoundTrip) {
    EXPECT_EQ(dsm::farmIndexRanges({0, 1, 2, 3}), "0-3");
    EXPECT_EQ(dsm::farmIndexRanges({1, 3, 4, 5, 9}), "1,3-5,9");
    EXPECT_EQ(dsm::parseFarmIndexRanges("9,1,3-5,4", 16), (std::vector<std::uint32_t>{1, 3, 4, 5, 9}));
    EXPECT_EQ(dsm::parseFarmIndexRanges("5", 16), (std::vector<std::uint32_t>{5}));
    for (const char* bad : {"", "16", "3-1", "1,", "a", "1-2-3", "-1"})
        EXPECT_THROW(dsm::parseFarmIndexRanges(bad, 16), dsm::Error) << bad;
}

TEST(FarmJobs, DescriptionsRunThePartCommandForEachIndexAndTheStitchAfter) {
    dsm::FarmJob job;
    job.name = "demo";
    job.partCommand = {"/opt/dsm farm", "tile", "it's.json", "--index", dsm::kFarmIndexArgument};
    job.stitchCommand = {"/opt/dsm farm", "stitch", "/parts", "-o", "/out.dsm"};
    job.indices = {0, 1, 2, 3};
    job.logDirectory = "/parts/logs";
    const std::string slurm = dsm::slurmPartScript(job, {});
    EXPECT_NE(slurm.find("#SBATCH --array=0-3\n"), std::string::npos) << slurm;
    EXPECT_NE(slurm.find("exec '/opt/dsm farm' 'tile' 'it'\\''s.json' '--index' \"$SLURM_ARRAY_TASK_ID\""),
              std::string::npos)
        << slurm;
    EXPECT_NE(dsm::openCueOutline(job).find("\"--index\", \"#IFRAME#\"], range=\"0-3\""), std::string::npos);
    EXPECT_NE(dsm::openJdTemplate(job).find("\"{{Task.Param.Index}}\""), std::string::npos);
    EXPECT_NE(dsm::openJdTemplate(job).find("- dependsOn: parts"), std::string::npos);
}
