// The reader's checks (spec section 10) on damaged copies of a valid small
// file: each is rejected by DeepShadowMap::open() (or, for tile contents, by
// the first read of the tile) and by dsm::validate() with a dsm::Error whose
// message names the file and, where relevant, the level, tile and pixel. CRCs
// are recomputed with zlib's crc32() where needed so that the check behind
// the CRC is reached. Also: the reader's limits, and files of a newer minor
// version (longer header, longer level and tile entries) are read.
#include <dsm/dsm.h>
#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

using dsm::DeepShadowMap;
using dsm::ReaderOptions;
using dsm::VisibilityFunction;
using dsm::WriterOptions;
using dsm::test::Image;
using dsm::test::TempDir;
using Bytes = std::vector<std::uint8_t>;

// Layout constants of .dsm 1.0 (spec sections 3, 5, 6).
constexpr std::size_t kHeaderSize = 272;
constexpr std::size_t kHeaderCrc = 228;
constexpr std::size_t kLevelEntry = 72;
constexpr std::size_t kTileEntry = 40;

std::uint64_t get(const Bytes& b, std::size_t at, int n) {
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= std::uint64_t(b.at(at + std::size_t(i))) << (8 * i);
    return v;
}
void put(Bytes& b, std::size_t at, std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b.at(at + std::size_t(i)) = static_cast<std::uint8_t>(v >> (8 * i));
}
std::uint32_t crc(const Bytes& b, std::size_t at, std::size_t n) {
    return static_cast<std::uint32_t>(::crc32(::crc32(0L, Z_NULL, 0), b.data() + at, static_cast<uInt>(n)));
}

// Field access through the header's own offsets and entry sizes.
std::size_t headerSize(const Bytes& b) { return static_cast<std::size_t>(get(b, 12, 4)); }
std::size_t levelCount(const Bytes& b) { return static_cast<std::size_t>(get(b, 216, 4)); }
std::size_t levelEntrySize(const Bytes& b) { return static_cast<std::size_t>(get(b, 220, 4)); }
std::size_t tileEntrySize(const Bytes& b) { return static_cast<std::size_t>(get(b, 224, 4)); }
std::size_t levelTable(const Bytes& b) { return static_cast<std::size_t>(get(b, 232, 8)); }
std::size_t levelEntry(const Bytes& b, std::size_t level) { return levelTable(b) + level * levelEntrySize(b); }
std::size_t tileEntry(const Bytes& b, std::size_t level, std::uint32_t tx, std::uint32_t ty) {
    const std::size_t e = levelEntry(b, level);
    const std::size_t tilesX = static_cast<std::size_t>(get(b, e + 8, 4));
    return static_cast<std::size_t>(get(b, e + 32, 8)) + (ty * tilesX + tx) * tileEntrySize(b);
}
std::size_t tileData(const Bytes& b, std::size_t level, std::uint32_t tx, std::uint32_t ty) {
    return static_cast<std::size_t>(get(b, tileEntry(b, level, tx, ty), 8));
}

void fixHeaderCrc(Bytes& b) {
    const std::size_t n = std::min(headerSize(b), b.size());
    put(b, kHeaderCrc, 0, 4);
    put(b, kHeaderCrc, crc(b, 0, n), 4);
}
void fixLevelTableCrc(Bytes& b) {
    put(b, 256, crc(b, levelTable(b), levelCount(b) * levelEntrySize(b)), 4);
    fixHeaderCrc(b);
}
void fixDirectoryCrc(Bytes& b, std::size_t level) {
    const std::size_t e = levelEntry(b, level);
    const std::size_t tiles = static_cast<std::size_t>(get(b, e + 8, 4) * get(b, e + 12, 4));
    put(b, e + 64, crc(b, static_cast<std::size_t>(get(b, e + 32, 8)), tiles * tileEntrySize(b)), 4);
    fixLevelTableCrc(b);
}
void fixTileCrc(Bytes& b, std::size_t level, std::uint32_t tx, std::uint32_t ty) {
    const std::size_t t = tileEntry(b, level, tx, ty);
    put(b, t + 16, crc(b, static_cast<std::size_t>(get(b, t, 8)), static_cast<std::size_t>(get(b, t + 8, 4))), 4);
    fixDirectoryCrc(b, level);
}

// The base map: 8 x 8, tiles of 4, four levels; tile 1,1 of level 0 empty;
// pixel (5, 2) of tile 1,0 has 20 vertices, the others at most 6.
Image baseImage() {
    std::mt19937_64 rng(12);
    return dsm::test::makeImage(8, 8, [&](std::uint32_t x, std::uint32_t y) {
        if (x >= 4 && y >= 4) return VisibilityFunction(1);
        if (x == 5 && y == 2) {
            VisibilityFunction f(1);
            for (int i = 0; i < 20; ++i) f.append(1.0f + 0.1f * static_cast<float>(i), 1.0f - 0.05f * static_cast<float>(i));
            return f;
        }
        return dsm::test::randomFunction(rng, 1, false, 1, 6);
    });
}

class ReaderErrors : public ::testing::Test {
protected:
    void SetUp() override {
        image_ = baseImage();
        WriterOptions o;
        o.tileSize = 4;
        o.tolerance = 0.01;
        o.zlibLevel = zlibLevel();
        o.formatMinor = 0;  // the offsets below are those of the 1.0 layout
        o.metadata = "{\"test\":\"reader errors\"}";
        dsm::test::writeMap(dir_ / "base.dsm", o, image_);
        base_ = dsm::test::readFile(dir_ / "base.dsm");
        ASSERT_EQ(headerSize(base_), kHeaderSize);
        ASSERT_EQ(levelCount(base_), 4u);
        ASSERT_NO_THROW(dsm::validate((dir_ / "base.dsm").string()));
    }
    virtual int zlibLevel() const { return 6; }

    std::string save(const Bytes& bytes) {
        const auto path = dir_ / ("damaged-" + std::to_string(serial_++) + ".dsm");
        dsm::test::writeFile(path, bytes);
        return path.string();
    }

    // Opening (then reading every pixel of every level) and validating both
    // throw dsm::Error whose message names the file and holds every `part`.
    void expectRejected(const Bytes& bytes, const std::vector<std::string>& parts, const ReaderOptions& options = {}) {
        const std::string path = save(bytes);
        auto check = [&](const std::string& how, const std::function<void()>& action) {
            try {
                action();
                ADD_FAILURE() << how << " accepted the file; expected an error with '" << parts.front() << "'";
            } catch (const dsm::Error& e) {
                const std::string message = e.what();
                EXPECT_NE(message.find(path), std::string::npos) << how << ": " << message;
                for (const std::string& part : parts)
                    EXPECT_NE(message.find(part), std::string::npos) << how << ": '" << part << "' not in: " << message;
            } catch (const std::exception& e) {
                ADD_FAILURE() << how << " threw something other than dsm::Error: " << e.what();
            }
        };
        check("open+read", [&] {
            ReaderOptions o = options;
            o.cache = dsm::TileCache::create(1 << 20);
            const auto map = DeepShadowMap::open(path, o);
            for (unsigned l = 0; l < map->info().levels.size(); ++l)
                for (std::uint32_t y = 0; y < map->info().levels[l].height; ++y)
                    for (std::uint32_t x = 0; x < map->info().levels[l].width; ++x) (void)map->pixel(l, x, y);
        });
        check("validate", [&] { dsm::validate(path, options); });
    }

    void expectOpenRejected(const Bytes& bytes, const std::vector<std::string>& parts, const ReaderOptions& options = {}) {
        const std::string path = save(bytes);
        try {
            (void)DeepShadowMap::open(path, options);
            ADD_FAILURE() << "open accepted the file";
        } catch (const dsm::Error& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find(path), std::string::npos) << message;
            for (const std::string& part : parts)
                EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
        }
    }

    TempDir dir_;
    Image image_;
    Bytes base_;
    int serial_ = 0;
};

TEST_F(ReaderErrors, TheUndamagedCopyIsAccepted) {
    Bytes b = base_;
    fixDirectoryCrc(b, 2);  // recomputing CRCs over unchanged bytes changes nothing
    EXPECT_EQ(b, base_);
    const std::string path = save(b);
    EXPECT_NO_THROW(dsm::validate(path));
}

TEST_F(ReaderErrors, BadMagic) {
    for (std::size_t i : {0u, 1u, 4u, 7u}) {
        Bytes b = base_;
        b[i] ^= 0x20;
        expectOpenRejected(b, {"bad magic"});
    }
    expectOpenRejected(Bytes{'h', 'e', 'l', 'l', 'o'}, {"bad magic"});
    expectOpenRejected(Bytes{}, {"bad magic"});
}

TEST_F(ReaderErrors, UnknownMajorVersion) {
    Bytes b = base_;
    put(b, 8, 2, 2);
    fixHeaderCrc(b);
    expectRejected(b, {"version 2.0", "not supported"});
    put(b, 8, 0, 2);
    fixHeaderCrc(b);
    expectRejected(b, {"version 0.0"});
}

TEST_F(ReaderErrors, UnknownRequiredFlag) {
    Bytes b = base_;
    put(b, 16, get(b, 16, 4) | (1u << 5), 4);
    fixHeaderCrc(b);
    expectRejected(b, {"unknown required flags 0x20"});
    put(b, 16, 1u << 31, 4);
    fixHeaderCrc(b);
    expectRejected(b, {"unknown required flags 0x80000000"});
}

TEST_F(ReaderErrors, PredictedDepthsWithoutCodedTiles) {
    Bytes b = base_;
    put(b, 16, (get(b, 16, 4) & ~4u) | 8u, 4);  // PREDICTED_DEPTHS without CODED_TILES
    fixHeaderCrc(b);
    expectRejected(b, {"predicted depths flag without the coded tiles flag"});
}

TEST_F(ReaderErrors, UnknownOptionalFlagsAreIgnored) {
    Bytes b = base_;
    put(b, 20, 0xFFFFFFFFu, 4);
    fixHeaderCrc(b);
    const std::string path = save(b);
    EXPECT_NO_THROW(dsm::validate(path));
}

TEST_F(ReaderErrors, HeaderSizeBelowMinimumOrBeyondTheFile) {
    Bytes b = base_;
    put(b, 12, 271, 4);
    fixHeaderCrc(b);
    expectRejected(b, {"header size 271", "below the minimum 272"});
    put(b, 12, 0, 4);
    expectRejected(b, {"header size 0"});
    put(b, 12, b.size() + 1, 4);
    expectRejected(b, {"header size " + std::to_string(b.size() + 1), "exceeds the file size"});
}

TEST_F(ReaderErrors, HeaderCrcMismatch) {
    Bytes b = base_;
    put(b, 24, 9, 4);  // width 9 without fixing the CRC
    expectRejected(b, {"header CRC-32 mismatch"});
    Bytes c = base_;
    c[kHeaderCrc] ^= 1;
    expectRejected(c, {"header CRC-32 mismatch"});
}

TEST_F(ReaderErrors, TruncatedOrExtendedByOneByte) {
    Bytes shorter(base_.begin(), base_.end() - 1);
    expectRejected(shorter, {"truncated or extended", std::to_string(base_.size() - 1) + " bytes"});
    Bytes longer = base_;
    longer.push_back(0);
    expectRejected(longer, {"truncated or extended", std::to_string(base_.size() + 1) + " bytes"});
    // Truncated inside the header.
    expectRejected(Bytes(base_.begin(), base_.begin() + 100), {"header size 272 exceeds the file size 100"});
}

TEST_F(ReaderErrors, LevelTableCrcMismatch) {
    Bytes b = base_;
    b[levelEntry(b, 1) + 17] ^= 0x10;  // a byte of level 1's tolerance
    expectRejected(b, {"level table CRC-32 mismatch"});
}

TEST_F(ReaderErrors, TileDirectoryCrcMismatch) {
    for (std::size_t level : {0u, 2u}) {
        Bytes b = base_;
        b[tileEntry(b, level, 0, 0) + 26] ^= 0x01;  // a byte of the tile's minZ
        expectRejected(b, {"level " + std::to_string(level) + ": tile directory CRC-32 mismatch"});
    }
}

TEST_F(ReaderErrors, MetadataCrcMismatch) {
    Bytes b = base_;
    b[get(b, 240, 8) + 3] ^= 0x01;
    expectRejected(b, {"metadata CRC-32 mismatch"});
}

TEST_F(ReaderErrors, TileDataCrcMismatchIsFoundWhenTheTileIsRead) {
    Bytes b = base_;
    const std::size_t at = tileData(b, 0, 1, 0) + 5;
    b[at] ^= 0x40;
    const std::string path = save(b);
    // The directory is intact: the file opens, other tiles read.
    const auto map = DeepShadowMap::open(path);
    EXPECT_NO_THROW((void)map->pixel(0, 1, 1));
    EXPECT_NO_THROW((void)map->pixel(1, 0, 0));
    try {
        (void)map->pixel(0, 6, 3);
        ADD_FAILURE() << "the damaged tile was read";
    } catch (const dsm::Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find(path), std::string::npos) << m;
        EXPECT_NE(m.find("level 0 tile 1,0"), std::string::npos) << m;
        EXPECT_NE(m.find("CRC-32 mismatch"), std::string::npos) << m;
    }
    expectRejected(b, {"level 0 tile 1,0", "CRC-32 mismatch"});
    // The same at a coarser level.
    Bytes c = base_;
    c[tileData(c, 1, 0, 0) + 9] ^= 0x02;
    expectRejected(c, {"level 1 tile 0,0", "CRC-32 mismatch"});
}

TEST_F(ReaderErrors, WidthAndHeightLimits) {
    ReaderOptions o;
    o.maxWidth = 7;
    expectRejected(base_, {"image size 8x8", "exceeds the reader's limit 7x"}, o);
    o.maxWidth = 8;
    o.maxHeight = 4;
    expectRejected(base_, {"exceeds the reader's limit 8x4"}, o);
    o.maxHeight = 8;
    EXPECT_NO_THROW(dsm::validate(save(base_), o));
}

TEST_F(ReaderErrors, VerticesPerPixelLimit) {
    // One level only (coarser levels' averages have more vertices, and their
    // tiles' totals are checked against the limit when the file is opened).
    WriterOptions single;
    single.tileSize = 4;
    single.mipLevels = 1;
    dsm::test::writeMap(dir_ / "single.dsm", single, image_);
    const Bytes b = dsm::test::readFile(dir_ / "single.dsm");
    ReaderOptions o;
    o.maxVerticesPerPixel = 19;  // pixel (5, 2) has 20
    expectRejected(b, {"level 0 tile 1,0", "pixel 5,2", "20 vertices exceed the reader's limit 19"}, o);
    o.maxVerticesPerPixel = 20;
    EXPECT_NO_THROW(dsm::validate(save(b), o));
    // A tile's total above pixels * limit is refused from the directory.
    o.maxVerticesPerPixel = 1;
    expectOpenRejected(base_, {"level 0 tile 0,0", "vertex count"}, o);
    // The full pyramid: its largest pixel passes, one vertex less does not.
    const auto map = DeepShadowMap::open((dir_ / "base.dsm").string());
    std::uint32_t most = 0;
    for (unsigned l = 0; l < map->info().levels.size(); ++l)
        for (std::uint32_t y = 0; y < map->info().levels[l].height; ++y)
            for (std::uint32_t x = 0; x < map->info().levels[l].width; ++x)
                most = std::max<std::uint32_t>(most, static_cast<std::uint32_t>(map->pixel(l, x, y)->size()));
    o.maxVerticesPerPixel = most;
    EXPECT_NO_THROW(dsm::validate(save(base_), o));
    o.maxVerticesPerPixel = most - 1;
    expectRejected(base_, {" level ", " tile "}, o);
}

TEST_F(ReaderErrors, TileBytesLimit) {
    ReaderOptions o;
    o.maxTileBytes = 64;
    expectRejected(base_, {"level 0 tile 0,0", "exceeds the reader's limit 64"}, o);
    std::uint64_t largest = 0;
    for (std::size_t l = 0; l < 4; ++l) {
        const std::size_t e = levelEntry(base_, l);
        for (std::uint32_t ty = 0; ty < get(base_, e + 12, 4); ++ty)
            for (std::uint32_t tx = 0; tx < get(base_, e + 8, 4); ++tx)
                largest = std::max(largest, get(base_, tileEntry(base_, l, tx, ty) + 12, 4));
    }
    o.maxTileBytes = largest;
    EXPECT_NO_THROW(dsm::validate(save(base_), o));
    o.maxTileBytes = largest - 1;
    expectRejected(base_, {"exceeds the reader's limit " + std::to_string(largest - 1)}, o);
}

TEST_F(ReaderErrors, LevelTotalsMustMatchTheDirectory) {
    Bytes b = base_;
    const std::size_t e = levelEntry(b, 0);
    put(b, e + 40, get(b, e + 40, 8) + 1, 8);  // vertexCount
    fixLevelTableCrc(b);
    expectRejected(b, {"level 0", "level totals do not match"});
}

TEST_F(ReaderErrors, LevelSizeMustHalve) {
    Bytes b = base_;
    put(b, levelEntry(b, 1), 5, 4);  // level 1 width 5 instead of 4
    fixLevelTableCrc(b);
    expectRejected(b, {"level 1", "does not halve"});
}

TEST_F(ReaderErrors, TileOutsideTheFile) {
    Bytes b = base_;
    const std::size_t t = tileEntry(b, 0, 1, 0);
    put(b, t, b.size() - 3, 8);  // offset: its bytes run past the end
    fixDirectoryCrc(b, 0);
    expectRejected(b, {"level 0 tile 1,0", "does not fit in the file"});
}

TEST_F(ReaderErrors, EmptyTileWithNonZeroFields) {
    Bytes b = base_;
    const std::size_t t = tileEntry(b, 0, 1, 1);
    ASSERT_EQ(get(b, t + 8, 4), 0u);  // tile 1,1 is empty
    put(b, t + 20, 3, 4);             // vertexCount
    fixDirectoryCrc(b, 0);
    expectRejected(b, {"level 0 tile 1,1", "empty tile with non-zero"});
}

TEST_F(ReaderErrors, ChangingTheFileSizeFieldIsCaught) {
    Bytes b = base_;
    put(b, 264, b.size() + 8, 8);
    fixHeaderCrc(b);
    expectRejected(b, {"truncated or extended"});
}

// Tiles stored without zlib, so single values can be patched.
class ReaderTileContents : public ReaderErrors {
protected:
    int zlibLevel() const override { return 0; }
};

TEST_F(ReaderTileContents, InvalidFunctionBehindAValidCrcNamesThePixel) {
    // Tile 0,0 of level 0: 16 pixels, a 16 * 6 = 96-byte pixel table, then
    // pixel 0 (0, 0): n depths and n values (no layers, no counts).
    Bytes b = base_;
    const std::size_t t = tileData(b, 0, 0, 0);
    const std::size_t n = static_cast<std::size_t>(get(b, t, 4));  // cumulative count of pixel 0
    ASSERT_GT(n, 0u);
    ASSERT_EQ(get(b, tileEntry(b, 0, 0, 0) + 8, 4), get(b, tileEntry(b, 0, 0, 0) + 12, 4));  // stored as is
    put(b, t + 96 + 4 * n, std::bit_cast<std::uint32_t>(1.5f), 4);                         // V_0 = 1.5
    fixTileCrc(b, 0, 0, 0);
    expectRejected(b, {"level 0 tile 0,0", "pixel 0,0", "outside [0, 1]"});

    // A pixel of tile 1,0 with decreasing depths: pixel (4, 0) is the tile's first.
    Bytes c = base_;
    const std::size_t u = tileData(c, 0, 1, 0);
    const std::size_t m = static_cast<std::size_t>(get(c, u, 4));
    ASSERT_GE(m, 2u);
    put(c, u + 96 + 4, std::bit_cast<std::uint32_t>(0.0f), 4);  // z_1 = 0 < z_0
    fixTileCrc(c, 0, 1, 0);
    expectRejected(c, {"level 0 tile 1,0", "pixel 4,0", "less than the previous depth"});

    // An unknown pixel flag (bit 1) in pixel 2 of tile 0,0: (2, 0).
    Bytes d = base_;
    d[tileData(d, 0, 0, 0) + 16 * 4 + 2] |= 0x02;
    fixTileCrc(d, 0, 0, 0);
    expectRejected(d, {"level 0 tile 0,0", "pixel 2,0", "unknown flags"});
}

// --- Newer minor versions ---------------------------------------------------

// Rewrites a 1.0 file as a 1.`minor` file whose header, level entries and tile
// entries are longer by the given amounts, the new bytes filled with a pattern
// (fields this reader does not know), every offset and CRC updated. From 1.1
// on the first new bytes are 1.1's fields, zero (zlib level 0, no area light,
// no value step), so the pattern starts after them.
constexpr std::size_t kHeaderFields11 = 24, kLevelFields11 = 8;
Bytes asNewerMinorVersion(const Bytes& old, std::uint16_t minor, std::size_t extraHeader, std::size_t extraLevel,
                          std::size_t extraTile) {
    const std::size_t levels = levelCount(old);
    std::size_t firstDirectory = old.size();
    for (std::size_t l = 0; l < levels; ++l)
        firstDirectory = std::min<std::size_t>(firstDirectory, static_cast<std::size_t>(get(old, levelEntry(old, l) + 32, 8)));
    Bytes out(old.begin(), old.begin() + kHeaderSize);
    const std::size_t headerZeros = minor >= 1 ? kHeaderFields11 : 0, levelZeros = minor >= 1 ? kLevelFields11 : 0;
    for (std::size_t i = 0; i < extraHeader; ++i)
        out.push_back(i < headerZeros ? 0 : static_cast<std::uint8_t>(0xA0 + i % 16));
    // Tile data: everything between the header and the first directory.
    out.insert(out.end(), old.begin() + kHeaderSize, old.begin() + static_cast<std::ptrdiff_t>(firstDirectory));
    std::vector<Bytes> levelEntries;
    for (std::size_t l = 0; l < levels; ++l) {
        const std::size_t e = levelEntry(old, l);
        const std::size_t tiles = static_cast<std::size_t>(get(old, e + 8, 4) * get(old, e + 12, 4));
        const std::size_t dir = static_cast<std::size_t>(get(old, e + 32, 8));
        const std::size_t newDir = out.size();
        for (std::size_t i = 0; i < tiles; ++i) {
            Bytes entry(old.begin() + static_cast<std::ptrdiff_t>(dir + i * kTileEntry),
                        old.begin() + static_cast<std::ptrdiff_t>(dir + (i + 1) * kTileEntry));
            if (get(entry, 8, 4) != 0) put(entry, 0, get(entry, 0, 8) + extraHeader, 8);
            for (std::size_t k = 0; k < extraTile; ++k) entry.push_back(static_cast<std::uint8_t>(0x5A ^ k));
            out.insert(out.end(), entry.begin(), entry.end());
        }
        Bytes level(old.begin() + static_cast<std::ptrdiff_t>(e), old.begin() + static_cast<std::ptrdiff_t>(e + kLevelEntry));
        put(level, 32, newDir, 8);
        put(level, 64, crc(out, newDir, out.size() - newDir), 4);
        for (std::size_t k = 0; k < extraLevel; ++k) level.push_back(k < levelZeros ? 0 : static_cast<std::uint8_t>(0xC3 ^ k));
        levelEntries.push_back(level);
    }
    const std::size_t table = out.size();
    for (const Bytes& level : levelEntries) out.insert(out.end(), level.begin(), level.end());
    const std::size_t tableSize = out.size() - table;
    const std::size_t metadata = out.size();
    const std::size_t metadataSize = static_cast<std::size_t>(get(old, 248, 8));
    const std::size_t oldMetadata = static_cast<std::size_t>(get(old, 240, 8));
    out.insert(out.end(), old.begin() + static_cast<std::ptrdiff_t>(oldMetadata),
               old.begin() + static_cast<std::ptrdiff_t>(oldMetadata + metadataSize));
    put(out, 10, minor, 2);
    put(out, 12, kHeaderSize + extraHeader, 4);
    put(out, 220, kLevelEntry + extraLevel, 4);
    put(out, 224, kTileEntry + extraTile, 4);
    put(out, 232, table, 8);
    put(out, 240, metadata, 8);
    put(out, 256, crc(out, table, tableSize), 4);
    put(out, 264, out.size(), 8);
    fixHeaderCrc(out);
    return out;
}

void expectSameMap(const DeepShadowMap& a, const DeepShadowMap& b, std::uint64_t offsetShift) {
    const dsm::MapInfo &ia = a.info(), &ib = b.info();
    EXPECT_EQ(ia.width, ib.width);
    EXPECT_EQ(ia.height, ib.height);
    EXPECT_EQ(ia.tileSize, ib.tileSize);
    EXPECT_EQ(ia.channels, ib.channels);
    EXPECT_TRUE(ia.camera == ib.camera);
    EXPECT_EQ(ia.metadata, ib.metadata);
    ASSERT_EQ(ia.levels.size(), ib.levels.size());
    for (unsigned l = 0; l < ia.levels.size(); ++l) {
        const dsm::LevelInfo &la = ia.levels[l], &lb = ib.levels[l];
        EXPECT_EQ(la.tolerance, lb.tolerance);
        EXPECT_EQ(la.errorBound, lb.errorBound);
        EXPECT_EQ(la.vertexCount, lb.vertexCount);
        for (std::uint32_t ty = 0; ty < la.tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < la.tilesX; ++tx) {
                const dsm::TileSummary ta = a.tile(l, tx, ty), tb = b.tile(l, tx, ty);
                EXPECT_EQ(tb.offset, ta.empty() ? 0 : ta.offset + offsetShift);
                EXPECT_EQ(tb.storedBytes, ta.storedBytes);
                EXPECT_EQ(tb.crc32, ta.crc32);
                EXPECT_EQ(tb.minZ, ta.minZ);
            }
        for (std::uint32_t y = 0; y < la.height; ++y)
            for (std::uint32_t x = 0; x < la.width; ++x)
                EXPECT_TRUE(dsm::test::sameFunction(b.pixel(l, x, y).view(), a.pixel(l, x, y)->toFunction(), ia.hasCounts))
                    << "level " << l << " pixel " << x << "," << y;
    }
}

TEST_F(ReaderErrors, NewerMinorVersionWithTheSameLayoutIsRead) {
    // A 1.1 file (this reader's layout) relabelled 1.7.
    WriterOptions o;
    o.tileSize = 4;
    o.tolerance = 0.01;
    o.quantiseValues = true;
    dsm::test::writeMap(dir_ / "base11.dsm", o, image_);
    Bytes b = dsm::test::readFile(dir_ / "base11.dsm");
    put(b, 10, 7, 2);
    fixHeaderCrc(b);
    const std::string path = save(b);
    ASSERT_NO_THROW(dsm::validate(path));
    const auto map = DeepShadowMap::open(path);
    EXPECT_EQ(map->info().versionMajor, 1);
    EXPECT_EQ(map->info().versionMinor, 7);
    EXPECT_TRUE(map->info().codedTiles);
    expectSameMap(*DeepShadowMap::open((dir_ / "base11.dsm").string()), *map, 0);
    // A 1.7 file must hold 1.1's fields: the 1.0 layout relabelled is refused.
    Bytes old = base_;
    put(old, 10, 7, 2);
    fixHeaderCrc(old);
    expectRejected(old, {"header size 272 is below the 296 of version 1.7"});
}

TEST_F(ReaderErrors, NewerMinorVersionWithALongerHeaderIsRead) {
    // Round trip of the rewriting itself: no extra bytes gives the file back.
    EXPECT_EQ(asNewerMinorVersion(base_, 0, 0, 0, 0), base_);
    const auto original = DeepShadowMap::open((dir_ / "base.dsm").string());
    const Bytes longer = asNewerMinorVersion(base_, 1, 28, 8, 0);  // headerSize 300, level entries 80
    ASSERT_EQ(longer.size(), base_.size() + 28 + 8 * levelCount(base_));
    const std::string path = save(longer);
    ASSERT_NO_THROW(dsm::validate(path));
    const auto map = DeepShadowMap::open(path);
    EXPECT_EQ(map->info().versionMinor, 1);
    EXPECT_EQ(map->info().fileBytes, longer.size());
    expectSameMap(*original, *map, 28);
}

TEST_F(ReaderErrors, NewerMinorVersionWithLongerEntriesIsRead) {
    const auto original = DeepShadowMap::open((dir_ / "base.dsm").string());
    const Bytes longer = asNewerMinorVersion(base_, 3, 44, 16, 12);
    const std::string path = save(longer);
    ASSERT_NO_THROW(dsm::validate(path));
    const auto map = DeepShadowMap::open(path);
    EXPECT_EQ(map->info().versionMinor, 3);
    expectSameMap(*original, *map, 44);
    // And the checks still hold in such a file: a damaged entry is caught.
    Bytes damaged = longer;
    damaged[tileEntry(damaged, 0, 0, 0) + 26] ^= 1;
    expectRejected(damaged, {"level 0: tile directory CRC-32 mismatch"});
}

TEST_F(ReaderErrors, EntrySizesBelowTheMinimum) {
    Bytes b = base_;
    put(b, 220, 71, 4);
    fixHeaderCrc(b);
    expectRejected(b, {"level entry size 71"});
    Bytes c = base_;
    put(c, 224, 39, 4);
    fixHeaderCrc(c);
    expectRejected(c, {"tile entry size 39"});
}

TEST_F(ReaderErrors, MissingFile) {
    const std::string path = (dir_ / "absent.dsm").string();
    try {
        (void)DeepShadowMap::open(path);
        ADD_FAILURE() << "opened a missing file";
    } catch (const dsm::Error& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
    EXPECT_THROW(dsm::validate(path), dsm::Error);
    EXPECT_THROW(dsm::validate(dir_.path().string()), dsm::Error);  // a directory
}

}  // namespace
