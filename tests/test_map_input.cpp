// Maps read through MapInput (memory, the caller's reads) answer exactly as
// maps read from their path; read failures and damaged bytes are reported as
// dsm::Error with their ErrorCode; the reader's failures carry the right code;
// and LookupContext's try* lookups never throw, giving the documented failure
// value and the reason instead.
#include <dsm/dsm.h>
#include <gtest/gtest.h>

#include <atomic>
#include <bit>
#include <cstring>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

using dsm::DeepShadowMap;
using dsm::ErrorCode;
using dsm::MapInput;
using dsm::test::TempDir;
using Bytes = std::vector<std::uint8_t>;

constexpr std::size_t kHeaderSize = 296;  // tiles follow the 1.1 header (spec/dsm-format.md)

// The caller's reads over a byte vector; reads that touch [failFrom, failTo) fail.
class VectorInput final : public MapInput {
public:
    explicit VectorInput(Bytes bytes, std::uint64_t failFrom = 0, std::uint64_t failTo = 0)
        : bytes_(std::move(bytes)), failFrom_(failFrom), failTo_(failTo) {}
    std::uint64_t size() const override { return bytes_.size(); }
    std::size_t read(std::uint64_t offset, void* out, std::size_t count) const override {
        ++reads;
        if (offset < failTo_ && offset + count > failFrom_) throw std::runtime_error("the disk is on fire");
        if (offset >= bytes_.size()) return 0;
        const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(count, bytes_.size() - offset));
        std::memcpy(out, bytes_.data() + offset, n);
        return n;
    }
    mutable std::atomic<int> reads{0};

private:
    Bytes bytes_;
    std::uint64_t failFrom_, failTo_;
};

class MapInputTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::mt19937_64 rng(7);
        image_ = dsm::test::makeImage(
            20, 12, [&](std::uint32_t, std::uint32_t) { return dsm::test::randomFunction(rng, 3, false, 1, 8); });
        dsm::WriterOptions o;
        o.tileSize = 8;
        o.channels = 3;
        o.tolerance = 0.01;
        dsm::test::writeMap(path_, o, image_);
        bytes_ = dsm::test::readFile(path_);
    }

    // Expects `action` to throw dsm::Error with `code` and a message containing `part`.
    template <class Action>
    void expectError(ErrorCode code, const std::string& part, Action&& action) {
        try {
            action();
            ADD_FAILURE() << "no error; expected " << dsm::errorCodeName(code) << " with '" << part << "'";
        } catch (const dsm::Error& e) {
            EXPECT_EQ(e.code(), code) << dsm::errorCodeName(e.code()) << ": " << e.what();
            EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
        }
    }

    TempDir dir_;
    std::string path_ = (dir_ / "map.dsm").string();
    dsm::test::Image image_;
    Bytes bytes_;
};

TEST_F(MapInputTest, MemoryAndCallbackInputsAnswerAsThePath) {
    const auto fromPath = DeepShadowMap::open(path_);
    const auto fromMemory = DeepShadowMap::open(MapInput::memory(bytes_.data(), bytes_.size()), "in memory");
    const auto input = std::make_shared<VectorInput>(bytes_);
    const auto fromReads = DeepShadowMap::open(input, "through reads");
    EXPECT_EQ(fromMemory->path(), "in memory");
    EXPECT_EQ(fromReads->path(), "through reads");
    for (const auto& map : {fromMemory, fromReads}) {
        EXPECT_EQ(map->info().levels.size(), fromPath->info().levels.size());
        EXPECT_EQ(map->info().fileBytes, fromPath->info().fileBytes);
        EXPECT_EQ(map->info().metadata, fromPath->info().metadata);
        for (unsigned l = 0; l < map->info().levels.size(); ++l)
            for (std::uint32_t y = 0; y < map->info().levels[l].height; ++y)
                for (std::uint32_t x = 0; x < map->info().levels[l].width; ++x)
                    EXPECT_TRUE(dsm::test::sameFunction(map->pixel(l, x, y).view(),
                                                        fromPath->pixel(l, x, y)->toFunction(), false));
    }
    EXPECT_GT(input->reads.load(), 0);
    EXPECT_NO_THROW(dsm::validate(MapInput::memory(bytes_.data(), bytes_.size()), "in memory"));
}

TEST_F(MapInputTest, ReadFailuresAndDamageCarryTheirCodes) {
    // A failing read while opening: io, naming the map and the reason.
    expectError(ErrorCode::io, "'broken': read failed: the disk is on fire",
                [&] { (void)DeepShadowMap::open(std::make_shared<VectorInput>(bytes_, 0, 16), "broken"); });
    // A failing read of a tile: the map opens, the tile's read reports io.
    const auto map = DeepShadowMap::open(std::make_shared<VectorInput>(bytes_, kHeaderSize, kHeaderSize + 1), "tiles");
    expectError(ErrorCode::io, "'tiles' level 0 tile 0,0: read failed", [&] { (void)map->pixel(0, 0, 0); });
    // Truncated bytes: corrupt (the header records another size).
    const Bytes truncated(bytes_.begin(), bytes_.end() - 1);
    expectError(ErrorCode::corrupt, "'short':", [&] {
        (void)DeepShadowMap::open(MapInput::memory(truncated.data(), truncated.size()), "short");
    });
    // Not a map at all: format.
    const std::string text = "hello, not a map";
    expectError(ErrorCode::format, "bad magic",
                [&] { (void)DeepShadowMap::open(MapInput::memory(text.data(), text.size()), "text"); });
    // A damaged tile: corrupt, when the tile is read.
    Bytes damaged = bytes_;
    damaged[kHeaderSize + 3] ^= 0x10;
    const auto damagedMap = DeepShadowMap::open(MapInput::memory(damaged.data(), damaged.size()), "damaged");
    expectError(ErrorCode::corrupt, "CRC-32 mismatch", [&] { (void)damagedMap->pixel(0, 0, 0); });
    // A newer major version: unsupported.
    Bytes newer = bytes_;
    newer[8] = 2;
    expectError(ErrorCode::unsupported, "not supported",
                [&] { (void)DeepShadowMap::open(MapInput::memory(newer.data(), newer.size()), "newer"); });
    // Limits and arguments.
    dsm::ReaderOptions small;
    small.maxWidth = 4;
    expectError(ErrorCode::limit, "exceeds the reader's limit", [&] { (void)DeepShadowMap::open(path_, small); });
    expectError(ErrorCode::io, "cannot open", [&] { (void)DeepShadowMap::open((dir_ / "missing.dsm").string()); });
    expectError(ErrorCode::io, "not a regular file", [&] { (void)DeepShadowMap::open(dir_.path().string()); });
    expectError(ErrorCode::argument, "does not exist", [&] { (void)map->pixel(9, 0, 0); });
    expectError(ErrorCode::argument, "no input given", [&] { (void)DeepShadowMap::open(nullptr, "none"); });
    expectError(ErrorCode::argument, "no data", [&] { (void)MapInput::memory(nullptr, 10); });
}

TEST_F(MapInputTest, TryLookupsMatchTheThrowingOnesAndNeverThrow) {
    const auto map = DeepShadowMap::open(path_);
    dsm::LookupContext throwing(map), quiet(map);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> rx(-1.0, 21.0), ry(-1.0, 13.0), z(0.0, 4.0);
    dsm::LookupOptions options;
    options.filter = dsm::PixelFilter::Gaussian;
    options.filterWidth = 3.0;
    for (int i = 0; i < 500; ++i) {
        const double x = rx(rng), y = ry(rng), d = z(rng);
        const dsm::LookupResult want = throwing.raster(x, y, d, options);
        dsm::LookupResult got;
        ASSERT_TRUE(quiet.tryRaster(x, y, d, options, got));
        for (int c = 0; c < 3; ++c)
            EXPECT_EQ(std::bit_cast<std::uint64_t>(got.v[c]), std::bit_cast<std::uint64_t>(want.v[c]));
        EXPECT_EQ(got.errorBound, want.errorBound);
        EXPECT_EQ(got.pixelsUsed, want.pixelsUsed);
    }
    // A bad point: the failure value and the reason, no exception.
    dsm::LookupResult failed;
    failed.v = {0.25, 0.25, 0.25};
    EXPECT_FALSE(quiet.tryRaster(std::numeric_limits<double>::quiet_NaN(), 1.0, 1.0, options, failed));
    EXPECT_EQ(failed.v, (std::array<double, 3>{1.0, 1.0, 1.0}));
    EXPECT_EQ(failed.errorBound, 1.0);
    EXPECT_EQ(failed.pixelsUsed, 0);
    EXPECT_EQ(failed.channels, 3);
    EXPECT_EQ(quiet.lastFailure().code, ErrorCode::argument);
    EXPECT_NE(quiet.lastFailure().message.find("is not finite"), std::string::npos) << quiet.lastFailure().message;
    EXPECT_FALSE(quiet.tryWorld({0.0, std::numeric_limits<double>::infinity(), 1.0}, options, failed));
    dsm::LookupOptions negativeWidth;
    negativeWidth.filterWidth = -1.0;
    EXPECT_FALSE(quiet.tryLight({0.0, 0.0, 1.0}, negativeWidth, failed));
    EXPECT_EQ(quiet.lastFailure().code, ErrorCode::argument);
    EXPECT_NE(quiet.lastFailure().message.find("filter width"), std::string::npos) << quiet.lastFailure().message;

    // A tile that cannot be read: corrupt, and the lookup goes on failing quietly.
    Bytes damaged = bytes_;
    damaged[kHeaderSize + 3] ^= 0x10;
    const auto damagedMap = DeepShadowMap::open(MapInput::memory(damaged.data(), damaged.size()), "damaged");
    dsm::LookupContext onDamaged(damagedMap);
    dsm::LookupOptions levelZero;
    levelZero.level = 0;
    dsm::LookupResult r;
    EXPECT_FALSE(onDamaged.tryRaster(1.0, 1.0, 2.0, levelZero, r));
    EXPECT_EQ(onDamaged.lastFailure().code, ErrorCode::corrupt);
    EXPECT_NE(onDamaged.lastFailure().message.find("'damaged' level 0 tile 0,0"), std::string::npos)
        << onDamaged.lastFailure().message;
    EXPECT_EQ(r.errorBound, 1.0);
    // Other tiles still answer.
    EXPECT_TRUE(onDamaged.tryRaster(18.0, 10.0, 2.0, levelZero, r));
}

}  // namespace
