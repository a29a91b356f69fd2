// OutputFile and the output checks (dsm/output_file.h): the target shows the
// old file or the complete new one; a failure or a destroyed OutputFile leaves
// no temporary; outputs that are directories, inputs or each other are
// refused; temporaries over the age limit are found and removed.
#include <dsm/error.h>
#include <dsm/output_file.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <vector>

#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;
using dsm::ErrorCode;
using dsm::OutputFile;
using dsm::test::TempDir;

std::string contents(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void put(const fs::path& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

std::vector<std::string> entries(const fs::path& directory) {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(directory)) names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

ErrorCode codeOf(const std::function<void()>& action) {
    try {
        action();
    } catch (const dsm::Error& e) {
        return e.code();
    }
    ADD_FAILURE() << "no dsm::Error thrown";
    return ErrorCode::internal;
}

TEST(OutputFile, CommitReplacesTheTargetWithEverythingWritten) {
    TempDir dir;
    const fs::path target = dir / "out.bin";
    put(target, "old");
    {
        OutputFile file(target.string());
        EXPECT_EQ(fs::path(file.temporaryPath()).parent_path(), dir.path());
        EXPECT_EQ(fs::path(file.temporaryPath()).filename().string().rfind(".out.bin.tmp-", 0), 0u);
        const std::string big(3 << 20, 'x');  // larger than the buffer
        file.write("head", 4);
        file.write(big.data(), big.size());
        file.write("tail", 4);
        file.writeAt(0, "HEAD", 4);
        EXPECT_EQ(file.size(), big.size() + 8);
        EXPECT_EQ(contents(target), "old");  // nothing shows before commit()
        file.commit();
    }
    const std::string written = contents(target);
    ASSERT_EQ(written.size(), (3u << 20) + 8);
    EXPECT_EQ(written.substr(0, 4), "HEAD");
    EXPECT_EQ(written.substr(written.size() - 4), "tail");
    EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"out.bin"});
}

TEST(OutputFile, WithoutCommitTheTemporaryGoesAndTheTargetStays) {
    TempDir dir;
    const fs::path target = dir / "out.png";
    put(target, "old");
    {
        OutputFile file(target.string(), ".png");
        EXPECT_EQ(fs::path(file.temporaryPath()).extension(), ".png");
        file.write("new", 3);
    }
    EXPECT_EQ(contents(target), "old");
    EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"out.png"});
}

TEST(OutputFile, WriteAtBeyondTheEndIsRefused) {
    TempDir dir;
    OutputFile file((dir / "out.bin").string());
    file.write("ab", 2);
    EXPECT_EQ(codeOf([&] { file.writeAt(1, "xy", 2); }), ErrorCode::io);
}

TEST(OutputChecks, PathsThatCannotBeOutputsAreRefused) {
    TempDir dir;
    EXPECT_EQ(codeOf([&] { dsm::checkOutputPath(""); }), ErrorCode::argument);
    EXPECT_EQ(codeOf([&] { dsm::checkOutputPath(dir.path().string()); }), ErrorCode::argument);
    EXPECT_EQ(codeOf([&] { dsm::checkOutputPath(dir.path().string() + "/"); }), ErrorCode::argument);
    EXPECT_EQ(codeOf([&] { dsm::checkOutputPath((dir / "..").string()); }), ErrorCode::argument);
    EXPECT_EQ(codeOf([&] { dsm::checkOutputPath("/dev/null"); }), ErrorCode::argument);
    EXPECT_EQ(codeOf([&] { dsm::checkOutputPath((dir / "missing" / "out.dsm").string()); }), ErrorCode::io);
    put(dir / "file", "x");
    EXPECT_EQ(codeOf([&] { dsm::checkOutputPath((dir / "file" / "out.dsm").string()); }), ErrorCode::io);
    EXPECT_NO_THROW(dsm::checkOutputPath((dir / "new.dsm").string()));
    EXPECT_NO_THROW(dsm::checkOutputPath((dir / "file").string()));
    // The constructor checks too, and leaves nothing behind.
    EXPECT_EQ(codeOf([&] { OutputFile file(dir.path().string()); }), ErrorCode::argument);
    EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"file"});
}

TEST(OutputChecks, AnOutputThatIsAnInputIsRefusedThroughLinks) {
    TempDir dir;
    const std::string input = (dir / "in.json").string();
    put(input, "{}");
    fs::create_symlink(input, dir / "symbolic");
    fs::create_hard_link(input, dir / "hard");
    for (const std::string& output : {input, (dir / "symbolic").string(), (dir / "hard").string(),
                                      (dir / "." / "in.json").string()}) {
        SCOPED_TRACE(output);
        EXPECT_EQ(codeOf([&] { dsm::refuseOutputOverInputs(output, {"/nonexistent", input}); }), ErrorCode::argument);
    }
    put(dir / "other", "{}");
    EXPECT_NO_THROW(dsm::refuseOutputOverInputs((dir / "other").string(), {input}));
    EXPECT_NO_THROW(dsm::refuseOutputOverInputs((dir / "new").string(), {input}));
}

TEST(OutputChecks, TwoOutputsNamingOneFileAreRefused) {
    TempDir dir;
    const std::string a = (dir / "a.dsm").string();
    EXPECT_EQ(codeOf([&] { dsm::refuseSharedOutputs({a, (dir / "." / "a.dsm").string()}); }), ErrorCode::argument);
    put(a, "x");
    fs::create_symlink(a, dir / "link.json");
    EXPECT_EQ(codeOf([&] { dsm::refuseSharedOutputs({a, (dir / "link.json").string()}); }), ErrorCode::argument);
    EXPECT_NO_THROW(dsm::refuseSharedOutputs({a, (dir / "b.json").string()}));
}

TEST(StaleTemporaries, OnlyOldTemporariesOfTheSameNameAreFoundAndRemoved) {
    TempDir dir;
    const fs::path target = dir / "m.dsm";
    const auto old = fs::file_time_type::clock::now() - std::chrono::hours(48);
    for (const char* name : {".m.dsm.tmp-old1", ".m.dsm.tmp-old2", ".other.dsm.tmp-old", "m.dsm"}) {
        put(dir / name, "x");
        fs::last_write_time(dir / name, old);
    }
    put(dir / ".m.dsm.tmp-fresh", "x");
    const std::vector<std::string> expected{(dir / ".m.dsm.tmp-old1").string(), (dir / ".m.dsm.tmp-old2").string()};
    EXPECT_EQ(dsm::staleTemporaries(target.string()), expected);
    EXPECT_EQ(dsm::removeStaleTemporaries(target.string()), 2u);
    EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{".m.dsm.tmp-fresh", ".other.dsm.tmp-old", "m.dsm"}));
    // A commit clears them as well.
    put(dir / ".m.dsm.tmp-old3", "x");
    fs::last_write_time(dir / ".m.dsm.tmp-old3", old);
    OutputFile file(target.string());
    file.commit();
    EXPECT_FALSE(fs::exists(dir / ".m.dsm.tmp-old3"));
    EXPECT_TRUE(fs::exists(dir / ".m.dsm.tmp-fresh"));
}

}  // namespace
