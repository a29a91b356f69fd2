// The library's side of the input limits (docs/robustness.md): thread counts
// clamped to the cores, files that are not regular refused without a blocking
// open, deep EXR headers checked against the file size before OpenEXR
// allocates, and EXR error bounds refused below what float32 resolves.
#include <dsm/build.h>
#include <dsm/dsm.h>
#include <dsm/exr.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <limits>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <sys/stat.h>

#include "temp_dir.h"

namespace dsm {
namespace {

/// The ErrorCode `action` throws dsm::Error with; fails the test otherwise.
template <class Action>
ErrorCode codeOf(Action&& action) {
    try {
        action();
    } catch (const Error& e) {
        return e.code();
    }
    ADD_FAILURE() << "no dsm::Error thrown";
    return ErrorCode::internal;
}

/// The arguments streamed into one string.
template <class... Parts>
std::string concatForTest(const Parts&... parts) {
    std::ostringstream out;
    (out << ... << parts);
    return out.str();
}

void appendLittleEndian(std::string& bytes, std::uint32_t value) {
    for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<char>((value >> (8 * i)) & 0xff));
}

void appendAttribute(std::string& bytes, const std::string& name, const std::string& type,
                     const std::string& value, std::uint32_t claimedSize) {
    bytes += name + '\0' + type + '\0';
    appendLittleEndian(bytes, claimedSize);
    bytes += value;
}

TEST(Threads, RequestsAboveTheCoresAreClamped) {
    const unsigned cores = availableCores();
    ASSERT_GE(cores, 1u);
    EXPECT_EQ(usableThreads(0), cores);
    EXPECT_EQ(usableThreads(1), 1u);
    EXPECT_EQ(usableThreads(70000), cores);
    EXPECT_EQ(usableThreads(std::numeric_limits<unsigned>::max()), cores);
}

TEST(RegularFiles, AFifoIsRefusedWithoutBlocking) {
    test::TempDir dir;
    const std::string fifo = (dir / "map.dsm").string();
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    // Nobody writes to the FIFO: a blocking open would never return.
    EXPECT_EQ(codeOf([&] { DeepShadowMap::open(fifo); }), ErrorCode::io);
    const std::string exr = (dir / "image.exr").string();
    ASSERT_EQ(::mkfifo(exr.c_str(), 0600), 0);
    EXPECT_EQ(codeOf([&] { importDeepExr(exr, (dir / "out.dsm").string()); }), ErrorCode::io);
    try {
        DeepShadowMap::open(fifo);
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
    }
}

TEST(ExrHeader, AnAttributeLargerThanTheFileIsCorrupt) {
    test::TempDir dir;
    const std::string exr = (dir / "huge.exr").string();
    std::string bytes = "\x76\x2f\x31\x01";
    appendLittleEndian(bytes, 2 | 0x800);  // version 2, deep data
    appendAttribute(bytes, "type", "string", "deepscanline", 12);
    appendAttribute(bytes, "comments", "string", std::string(16, 'x'), 0x6c000000u);  // 1.8 GB claimed
    bytes.resize(4096, '\0');
    std::ofstream(exr, std::ios::binary) << bytes;
    try {
        importDeepExr(exr, (dir / "out.dsm").string());
        ADD_FAILURE() << "no dsm::Error thrown";
    } catch (const Error& e) {
        EXPECT_EQ(e.code(), ErrorCode::corrupt);
        EXPECT_NE(std::string(e.what()).find("header attribute 'comments' (string) claims 1811939328 bytes"),
                  std::string::npos)
            << e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "out.dsm"));
}

/// The message importing a deep EXR made of `attributes` (one header, or
/// several for a multi-part file) throws; fails the test unless it is
/// ErrorCode::corrupt and no map was written.
std::string corruptHeaderMessage(const std::vector<std::string>& headers) {
    test::TempDir dir;
    const std::string exr = (dir / "header.exr").string();
    std::string bytes = "\x76\x2f\x31\x01";
    appendLittleEndian(bytes, headers.size() > 1 ? 2 | 0x800 | 0x1000 : 2 | 0x800);  // deep, multi-part
    for (const std::string& header : headers) bytes += header + '\0';
    if (headers.size() > 1) bytes += '\0';
    bytes.resize(bytes.size() + 4096, '\0');
    std::ofstream(exr, std::ios::binary) << bytes;
    std::string message;
    try {
        importDeepExr(exr, (dir / "out.dsm").string());
        ADD_FAILURE() << "no dsm::Error thrown";
    } catch (const Error& e) {
        EXPECT_EQ(e.code(), ErrorCode::corrupt) << e.what();
        message = e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "out.dsm"));
    return message;
}

std::string attribute(const std::string& name, const std::string& type, const std::string& value,
                      std::uint32_t claimedSize) {
    std::string bytes;
    appendAttribute(bytes, name, type, value, claimedSize);
    return bytes;
}

std::string attribute(const std::string& name, const std::string& type, const std::string& value) {
    return attribute(name, type, value, std::uint32_t(value.size()));
}

/// One channel list entry: name\0, pixel type, pLinear + 3 pad bytes, sampling.
std::string channel(const std::string& name) {
    std::string bytes = name + '\0';
    appendLittleEndian(bytes, 2);
    appendLittleEndian(bytes, 0);
    appendLittleEndian(bytes, 1);
    appendLittleEndian(bytes, 1);
    return bytes;
}

const std::string kType = attribute("type", "string", "deepscanline");

// OpenEXR reads a channel list up to its empty name whatever size the file
// records; a list that disagrees would leave the rest of the header read out
// of step with the size check.
TEST(ExrHeader, AChannelListDisagreeingWithItsSizeIsCorrupt) {
    const std::string list = channel("A") + channel("Z") + '\0';  // 37 bytes
    const std::string longer = corruptHeaderMessage({kType + attribute("channels", "chlist", list, 20)});
    EXPECT_NE(longer.find("header attribute 'channels' (chlist) records 20 bytes but its channel list does not end"),
              std::string::npos)
        << longer;
    const std::string shorter =
        corruptHeaderMessage({kType + attribute("channels", "chlist", list + std::string(8, 'x'))});
    EXPECT_NE(shorter.find("header attribute 'channels' (chlist) records 45 bytes but its channel list ends after 37"),
              std::string::npos)
        << shorter;
    // The walk reaches an oversized attribute after a well-formed list.
    const std::string after = corruptHeaderMessage(
        {kType + attribute("channels", "chlist", list) + attribute("blob", "opaque", "x", 0x6c000000u)});
    EXPECT_NE(after.find("header attribute 'blob' (opaque) claims 1811939328 bytes"), std::string::npos) << after;
}

TEST(ExrHeader, AFixedSizeAttributeOfAnotherSizeIsCorrupt) {
    const struct {
        const char* type;
        std::uint32_t size, recorded;
    } cases[] = {{"box2i", 16, 13},      {"box2f", 16, 20}, {"v2f", 8, 4},   {"v2i", 8, 12},  {"float", 4, 1},
                 {"int", 4, 8},          {"compression", 1, 4}, {"lineOrder", 1, 0}, {"tiledesc", 9, 12},
                 {"m44f", 64, 16},       {"double", 8, 4}, {"chromaticities", 32, 8}, {"keycode", 28, 4}};
    for (const auto& c : cases) {
        const std::string message =
            corruptHeaderMessage({kType + attribute("odd", c.type, std::string(c.recorded, '\0'))});
        EXPECT_NE(message.find(concatForTest("header attribute 'odd' (", c.type, ") records ", c.recorded,
                                             " bytes but a ", c.type, " holds ", c.size)),
                  std::string::npos)
            << message;
    }
}

TEST(ExrHeader, VariableSizeAttributesMustFillTheirSize) {
    std::string strings;
    appendLittleEndian(strings, 3);
    strings += "abc";
    std::string overrun = strings;
    appendLittleEndian(overrun, 9);
    overrun += "de";
    EXPECT_NE(corruptHeaderMessage({kType + attribute("names", "stringvector", overrun)})
                  .find("'names' (stringvector) records 13 bytes but a string in it runs past them"),
              std::string::npos);
    EXPECT_NE(corruptHeaderMessage({kType + attribute("names", "stringvector", strings + "de")})
                  .find("'names' (stringvector) records 9 bytes but its strings do not fill them"),
              std::string::npos);
    EXPECT_NE(corruptHeaderMessage({kType + attribute("weights", "floatvector", std::string(6, '\0'))})
                  .find("'weights' (floatvector) records 6 bytes but that is not a whole number of floats"),
              std::string::npos);
    std::string preview;
    appendLittleEndian(preview, 2);
    appendLittleEndian(preview, 3);
    EXPECT_NE(corruptHeaderMessage({kType + attribute("preview", "preview", preview + std::string(20, '\0'))})
                  .find("'preview' (preview) records 28 bytes but its preview image needs 32"),
              std::string::npos);
    EXPECT_NE(corruptHeaderMessage({kType + attribute("ids", "idmanifest", "ab")})
                  .find("'ids' (idmanifest) records 2 bytes but an idmanifest needs at least 4"),
              std::string::npos);
}

// Each part of a multi-part file has its own header, read in turn.
TEST(ExrHeader, EveryPartOfAMultiPartFileIsChecked) {
    const std::string part0 = kType + attribute("name", "string", "first");
    const std::string part1 = kType + attribute("name", "string", "second") +
                              attribute("dataWindow", "box2i", std::string(13, '\0'));
    const std::string message = corruptHeaderMessage({part0, part1});
    EXPECT_NE(message.find("part 1 header attribute 'dataWindow' (box2i) records 13 bytes but a box2i holds 16"),
              std::string::npos)
        << message;
}

TEST(ExrErrorBounds, NanAndBoundsBelowFloat32AreRefused) {
    test::TempDir dir;
    const std::string in = (dir / "in.exr").string(), out = (dir / "out.dsm").string();
    for (double bound : {std::numeric_limits<double>::quiet_NaN(), 1e-9, 1e-300, 2.0,
                         std::numeric_limits<double>::infinity()}) {
        ExrImportOptions import;
        import.maxLinearError = bound;
        EXPECT_EQ(codeOf([&] { importDeepExr(in, out, import); }), ErrorCode::argument) << bound;
        ExrExportOptions exportOptions;
        exportOptions.maxDeviation = bound;
        EXPECT_EQ(codeOf([&] { exportDeepExr((dir / "in.dsm").string(), (dir / "out.exr").string(),
                                             exportOptions); }),
                  ErrorCode::argument)
            << bound;
    }
    ExrImportOptions nanTolerance;
    nanTolerance.tolerance = std::numeric_limits<double>::quiet_NaN();
    EXPECT_EQ(codeOf([&] { importDeepExr(in, out, nanTolerance); }), ErrorCode::argument);
}

}  // namespace
}  // namespace dsm
