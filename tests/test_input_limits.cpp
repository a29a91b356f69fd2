// The library's side of the input limits (docs/robustness.md): thread counts
// clamped to the cores, files that are not regular refused without a blocking
// open, deep EXR headers checked against the file size before OpenEXR
// allocates, and EXR error bounds refused below what float32 resolves.
#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <limits>
#include <string>

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
