// Deterministic corruption test: a small map in which every region of the
// format exists (header, tiles compressed and stored, empty tiles, several mip
// levels, directories, level table, metadata) is damaged in every way we can
// enumerate: each bit of each byte flipped, every truncation, extensions by
// zeros and garbage, whole regions overwritten, and byte flips whose CRC-32s
// are then recomputed so that the checks behind the CRCs are reached.
//
// For each damaged copy, dsm::validate() and the normal read path (open, every
// pixel of every level, a few filtered lookups) must each either succeed or
// throw dsm::Error with a message naming the file. Any other exception fails
// the test; a crash, an out-of-bounds access or undefined behaviour fails it
// under the sanitizers (scripts/test runs it with AddressSanitizer and UBSan).
// Since every byte of a file is covered by a CRC-32 and the header records the
// file size, every plain flip, truncation and extension must be an error.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <unistd.h>

#include <dsm/error.h>
#include <dsm/lookup.h>
#include <dsm/reader.h>
#include <dsm/tile_cache.h>
#include <dsm/writer.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "temp_dir.h"

namespace {

using Bytes = std::vector<std::uint8_t>;

// ---------------------------------------------------------------------------
// The sample map.

constexpr std::uint32_t kWidth = 10;
constexpr std::uint32_t kHeight = 7;
constexpr std::uint32_t kTileSize = 4;

// A small deterministic hash for "noisy" pixels.
std::uint32_t mix(std::uint32_t x) {
    x ^= x >> 16;
    x *= 0x7FEB352Du;
    x ^= x >> 15;
    x *= 0x846CA68Bu;
    return x ^ (x >> 16);
}

float unit(std::uint32_t seed) { return static_cast<float>(mix(seed) % 1000u) / 1000.0f; }

// Level-0 pixel (x, y). Tiles in column 2 (x >= 8) are empty, so the level-1
// tile above them is empty too; the others mix empty, monochrome, RGB, layered
// and noisy functions, all with counts.
dsm::VisibilityFunction samplePixel(std::uint32_t x, std::uint32_t y) {
    if (x >= 8) return dsm::VisibilityFunction(1, true);
    const float dx = 0.05f * static_cast<float>(x), dy = 0.03f * static_cast<float>(y);
    switch ((x + 3 * y) % 6) {
        case 0:
            return dsm::VisibilityFunction(1, true);
        case 1: {
            dsm::VisibilityFunction f(1, true);
            f.append(1.0f + dx, 0.7f, 3);
            f.append(2.0f + dy, 0.2f, 5);
            return f;
        }
        case 2: {
            dsm::VisibilityFunction f(3, true);
            const float a[3] = {0.9f, 0.8f, 0.85f}, b[3] = {0.5f, 0.4f, 0.6f}, c[3] = {0.1f, 0.0f, 0.2f};
            f.append(0.5f + dy, a, 1);
            f.append(1.5f, b, 2);
            f.append(2.5f + dx, c, 4);
            return f;
        }
        case 3: {
            dsm::VisibilityFunction f(1, true);
            f.append(1.0f, 0.5f, 2);
            f.append(2.0f + dx, 0.0f, 2);
            f.beginLayer();
            f.append(2.5f + dx, 0.6f, 1);
            f.append(3.0f + dx + dy, 0.1f, 3);
            return f;
        }
        case 4: {
            dsm::VisibilityFunction f(3, true);
            const float a[3] = {0.6f, 0.5f, 0.7f}, z[3] = {0.0f, 0.0f, 0.0f}, b[3] = {0.9f, 0.7f, 0.8f},
                        c[3] = {0.3f, 0.2f, 0.25f};
            f.append(0.8f + dx, a, 1);
            f.append(1.2f + dy, z, 6);
            f.beginLayer();
            f.append(1.4f + dy, b, 2);
            f.append(2.9f, c, 1);
            return f;
        }
        default: {
            // Noisy: depths and values from a hash, so the tile compresses badly.
            dsm::VisibilityFunction f(3, true);
            float depth = 0.2f, v[3] = {1.0f, 1.0f, 1.0f};
            for (std::uint32_t i = 0; i < 3; ++i) {
                const std::uint32_t seed = (y * kWidth + x) * 16 + i;
                depth += 0.1f + unit(seed);
                for (int c = 0; c < 3; ++c) v[c] *= 0.5f + 0.5f * unit(seed * 3 + static_cast<std::uint32_t>(c) + 7);
                f.append(depth, v, 1 + mix(seed) % 9);
            }
            return f;
        }
    }
}

void writeSampleMap(const std::string& path) {
    dsm::WriterOptions o;
    o.width = kWidth;
    o.height = kHeight;
    o.tileSize = kTileSize;
    o.channels = 3;
    o.counts = true;
    o.maxLayers = 2;
    o.mipLevels.reset();  // the full pyramid: 10x7, 5x4, 3x2, 2x1, 1x1
    o.tolerance = 0.02;
    o.levelToleranceFactor = 2.0;  // coarse levels keep few vertices: a small file
    o.zlibLevel = 6;
    o.filter = dsm::PixelFilter::Gaussian;
    o.filterWidth = 2.0;
    o.camera.projection = dsm::Projection::Orthographic;
    o.camera.screenWindow = {0.0, double(kWidth), 0.0, double(kHeight)};  // raster = (x, height - y)
    o.metadata = R"({"software":"test_corruption","scene":{"name":"corruption","objects":3},"note":"every region"})";
    dsm::MapWriter writer(path, o);
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<dsm::VisibilityFunction> pixels;
            for (std::uint32_t y = 0; y < writer.tileHeight(ty); ++y)
                for (std::uint32_t x = 0; x < writer.tileWidth(tx); ++x)
                    pixels.push_back(samplePixel(tx * kTileSize + x, ty * kTileSize + y));
            writer.writeTile(tx, ty, pixels);
        }
    writer.finish();
}

// ---------------------------------------------------------------------------
// File helpers.

Bytes readFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The damaged copy: one file, changed in place by the fewest writes that turn
// its current contents into the next copy. Rewriting or truncating a whole
// file per copy costs block allocation and (on a disk mounted with discard)
// far more time than the reads being tested.
class BufferFile {
public:
    explicit BufferFile(std::string path) : path_(std::move(path)) {
        fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (fd_ < 0) throw std::runtime_error("cannot create " + path_);
    }
    ~BufferFile() { ::close(fd_); }
    BufferFile(const BufferFile&) = delete;
    BufferFile& operator=(const BufferFile&) = delete;
    const std::string& path() const { return path_; }

    void set(const Bytes& next) {
        if (next.size() < current_.size()) {
            if (::ftruncate(fd_, static_cast<off_t>(next.size())) != 0) throw std::runtime_error("cannot truncate " + path_);
            current_.resize(next.size());
        }
        const std::size_t common = current_.size();
        std::size_t first = 0, last = common;
        while (first < common && current_[first] == next[first]) ++first;
        while (last > first && current_[last - 1] == next[last - 1]) --last;
        put(first, next.data() + first, last - first);
        put(common, next.data() + common, next.size() - common);
        current_ = next;
    }

private:
    void put(std::size_t offset, const std::uint8_t* data, std::size_t size) {
        while (size > 0) {
            const ssize_t n = ::pwrite(fd_, data, size, static_cast<off_t>(offset));
            if (n <= 0) throw std::runtime_error("cannot write " + path_);
            data += n;
            offset += static_cast<std::size_t>(n);
            size -= static_cast<std::size_t>(n);
        }
    }
    std::string path_;
    int fd_ = -1;
    Bytes current_;
};

std::uint64_t le(const Bytes& b, std::size_t at, int n) {
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= std::uint64_t(b[at + static_cast<std::size_t>(i)]) << (8 * i);
    return v;
}

void putLe32(Bytes& b, std::size_t at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
}

// CRC-32 (zlib's polynomial), written here independently of the library.
std::uint32_t crc32(const std::uint8_t* data, std::size_t size) {
    static const std::array<std::uint32_t, 256> table = [] {
        std::array<std::uint32_t, 256> t{};
        for (std::uint32_t i = 0; i < 256; ++i) {
            std::uint32_t c = i;
            for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
            t[i] = c;
        }
        return t;
    }();
    std::uint32_t c = 0xFFFFFFFFu;
    for (std::size_t i = 0; i < size; ++i) c = table[(c ^ data[i]) & 0xFFu] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

// ---------------------------------------------------------------------------
// The file's layout, read from its bytes at the offsets of the format's tables.

// Header and level entry sizes are read from the file (they grew in 1.1).
constexpr std::size_t kHeaderSizeField = 12;
constexpr std::size_t kLevelEntrySizeField = 220;
constexpr std::size_t kHeaderCrc = 228;
constexpr std::size_t kTileEntrySize = 40;

struct Range {
    std::uint64_t offset = 0;
    std::uint64_t size = 0;
};

struct Layout {
    struct Tile {
        std::size_t entry = 0;  // file offset of its directory entry
        Range data;
    };
    struct Level {
        std::size_t entry = 0;  // file offset of its level table entry
        Range directory;
    };
    std::vector<Tile> tiles;  // non-empty ones
    std::vector<Level> levels;
    Range levelTable, metadata;
    std::uint64_t headerSize = 0;
    std::size_t emptyTiles = 0, compressedTiles = 0, storedTiles = 0;

    // Regions in file order; the writer leaves no gaps.
    enum Region { Header, TileData, Directories, LevelTable, Metadata, RegionCount };
    static const char* name(int r) {
        static const char* names[] = {"header", "tile data", "tile directories", "level table", "metadata"};
        return names[r];
    }
    int regionOf(std::uint64_t offset) const {
        if (offset < headerSize) return Header;
        if (offset < levels.front().directory.offset) return TileData;
        if (offset < levelTable.offset) return Directories;
        if (offset < metadata.offset) return LevelTable;
        return Metadata;
    }
    Range region(int r, std::uint64_t fileSize) const {
        const std::uint64_t bounds[] = {0, headerSize, levels.front().directory.offset, levelTable.offset,
                                        metadata.offset, fileSize};
        return {bounds[r], bounds[r + 1] - bounds[r]};
    }
};

Layout layoutOf(const Bytes& f) {
    Layout L;
    const std::uint32_t levelCount = static_cast<std::uint32_t>(le(f, 216, 4));
    const std::uint64_t levelEntrySize = le(f, kLevelEntrySizeField, 4);
    L.headerSize = le(f, kHeaderSizeField, 4);
    L.levelTable = {le(f, 232, 8), std::uint64_t(levelCount) * levelEntrySize};
    L.metadata = {le(f, 240, 8), le(f, 248, 8)};
    for (std::uint32_t l = 0; l < levelCount; ++l) {
        const std::size_t e = L.levelTable.offset + l * levelEntrySize;
        const std::uint64_t tiles = le(f, e + 8, 4) * le(f, e + 12, 4);
        L.levels.push_back({e, {le(f, e + 32, 8), tiles * kTileEntrySize}});
        for (std::uint64_t t = 0; t < tiles; ++t) {
            const std::size_t d = L.levels.back().directory.offset + t * kTileEntrySize;
            const std::uint64_t stored = le(f, d + 8, 4), raw = le(f, d + 12, 4);
            if (stored == 0) {
                ++L.emptyTiles;
                continue;
            }
            (stored < raw ? L.compressedTiles : L.storedTiles)++;
            L.tiles.push_back({d, {le(f, d, 8), stored}});
        }
    }
    return L;
}

// Recomputes every CRC-32 of a damaged copy over the ranges of the original
// layout, innermost first: tiles, directories, level table and metadata,
// header. A damaged byte is then seen only by the checks behind the CRCs.
void reseal(Bytes& f, const Layout& L) {
    for (const Layout::Tile& t : L.tiles) putLe32(f, t.entry + 16, crc32(f.data() + t.data.offset, t.data.size));
    for (const Layout::Level& l : L.levels)
        putLe32(f, l.entry + 64, crc32(f.data() + l.directory.offset, l.directory.size));
    putLe32(f, 256, crc32(f.data() + L.levelTable.offset, L.levelTable.size));
    putLe32(f, 260, crc32(f.data() + L.metadata.offset, L.metadata.size));
    putLe32(f, kHeaderCrc, 0);
    putLe32(f, kHeaderCrc, crc32(f.data(), L.headerSize));
}

// ---------------------------------------------------------------------------
// Reading a (possibly damaged) file both ways.

struct Digest {
    std::uint64_t h = 0xCBF29CE484222325ull;
    void add(std::uint64_t v) {
        for (int i = 0; i < 8; ++i) {
            h ^= (v >> (8 * i)) & 0xFFu;
            h *= 0x100000001B3ull;
        }
    }
    void add(float v) { add(std::uint64_t(std::bit_cast<std::uint32_t>(v))); }
    void add(double v) { add(std::bit_cast<std::uint64_t>(v)); }
};

// Everything the normal read path sees: every pixel of every level and a few
// filtered lookups (both levels of a trilinear blend, world and raster).
std::uint64_t readEverything(const std::string& path, const std::shared_ptr<dsm::TileCache>& cache) {
    dsm::ReaderOptions options;
    options.cache = cache;
    const auto map = dsm::DeepShadowMap::open(path, options);
    Digest d;
    d.add(std::uint64_t(map->info().levels.size()));
    const dsm::MapInfo& info = map->info();
    for (double m : info.camera.worldToLight) d.add(m);
    for (double w : info.camera.screenWindow) d.add(w);
    d.add(info.camera.nearPlane);
    d.add(info.filterWidth);
    d.add(std::uint64_t(info.filter) << 8 | std::uint64_t(info.camera.projection));
    for (char ch : info.metadata) d.add(std::uint64_t(static_cast<unsigned char>(ch)));
    for (const dsm::LevelInfo& L : info.levels) {
        d.add(L.tolerance);
        d.add(L.errorBound);
    }
    for (unsigned l = 0; l < map->info().levels.size(); ++l) {
        const dsm::LevelInfo& L = map->info().levels[l];
        for (std::uint32_t ty = 0; ty < L.tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < L.tilesX; ++tx) {
                const dsm::TileSummary t = map->tile(l, tx, ty);
                d.add(t.offset);
                d.add(std::uint64_t(t.storedBytes) << 32 | t.rawBytes);
                d.add(std::uint64_t(t.crc32) << 32 | t.vertexCount);
                d.add(t.minZ);
                d.add(t.maxZ);
                d.add(std::uint64_t(t.nonEmptyPixels));
            }
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x) {
                const dsm::PixelFunction p = map->pixel(l, x, y);
                const dsm::VisibilityView& f = p.view();
                d.add(std::uint64_t(f.channels()) << 32 | f.size());
                for (std::uint32_t s : f.layerStarts()) d.add(std::uint64_t(s));
                for (float z : f.depths()) d.add(z);
                for (float v : f.allValues()) d.add(v);
                for (std::uint32_t c : f.counts()) d.add(std::uint64_t(c));
                if (!f.empty()) d.add(f.evaluate(f.z(f.size() - 1) * 0.75));
            }
    }
    dsm::LookupContext lookup(map);
    dsm::LookupOptions box, wide, level2;
    wide.filter = dsm::PixelFilter::Gaussian;
    wide.filterWidth = 3.0;
    level2.level = 2;
    level2.filterWidth = 4.0;
    const dsm::LookupResult results[] = {
        lookup.raster(2.5, 3.5, 1.7, box),        lookup.raster(5.0, 2.0, 2.2, wide),
        lookup.raster(9.0, 6.5, 3.0, wide),       lookup.raster(4.0, 4.0, 2.6, level2),
        lookup.world({4.2, 3.3, 2.6}, wide),      lookup.world({1.0, 6.0, 0.9}, box),
    };
    for (const dsm::LookupResult& r : results) {
        for (double v : r.v) d.add(v);
        d.add(std::uint64_t(r.pixelsUsed));
    }
    return d.h;
}

enum class Verdict { Error, ValidSame, ValidDifferent };

struct Outcome {
    Verdict verdict = Verdict::Error;
    std::string problem;  // non-empty: the test fails
};

// Runs `step`; true when it returned, false when it threw dsm::Error with a
// message naming the file. Anything else is recorded as a problem.
template <typename Step>
bool attempt(const char* what, const std::string& path, std::string& problem, Step&& step) {
    try {
        step();
        return true;
    } catch (const dsm::Error& e) {
        const std::string message = e.what();
        if (message.empty())
            problem += std::string(what) + ": dsm::Error with an empty message; ";
        else if (message.find(path) == std::string::npos)
            problem += std::string(what) + ": message does not name the file: " + message + "; ";
    } catch (const std::exception& e) {
        problem += std::string(what) + ": unexpected exception (not dsm::Error): " + e.what() + "; ";
    } catch (...) {
        problem += std::string(what) + ": unexpected non-standard exception; ";
    }
    return false;
}

struct Checker {
    dsm::test::TempDir dir;
    std::string original = (dir / "sample.dsm").string();
    BufferFile buffer{(dir / "damaged.dsm").string()};
    const std::string& damaged = buffer.path();
    std::shared_ptr<dsm::TileCache> cache = dsm::TileCache::create(8 * 1024);
    Bytes bytes;
    Layout layout;
    std::uint64_t digest = 0;

    Checker() {
        writeSampleMap(original);
        bytes = readFile(original);
        layout = layoutOf(bytes);
        digest = readEverything(original, cache);
    }

    Outcome check(const Bytes& copy) {
        buffer.set(copy);
        Outcome o;
        const bool validated = attempt("validate", damaged, o.problem, [&] { dsm::validate(damaged); });
        std::uint64_t seen = 0;
        const bool read = attempt("read", damaged, o.problem, [&] { seen = readEverything(damaged, cache); });
        if (validated != read)
            o.problem += std::string("validate ") + (validated ? "passed" : "failed") + " but reading " +
                         (read ? "passed" : "failed") + "; ";
        if (read) o.verdict = seen == digest ? Verdict::ValidSame : Verdict::ValidDifferent;
        return o;
    }
};

// Outcomes per region, and the first few problems with what caused them.
struct Tally {
    struct Counts {
        std::size_t cases = 0, errors = 0, validSame = 0, validDifferent = 0, problems = 0;
    };
    std::array<Counts, Layout::RegionCount> regions{};
    std::vector<std::string> problems;

    void add(int region, const Outcome& o, const std::string& what) {
        Counts& c = regions[static_cast<std::size_t>(region)];
        ++c.cases;
        if (o.verdict == Verdict::Error) ++c.errors;
        if (o.verdict == Verdict::ValidSame) ++c.validSame;
        if (o.verdict == Verdict::ValidDifferent) ++c.validDifferent;
        if (!o.problem.empty()) {
            ++c.problems;
            if (problems.size() < 20) problems.push_back(what + ": " + o.problem);
        }
    }
    Counts total() const {
        Counts t;
        for (const Counts& c : regions) {
            t.cases += c.cases;
            t.errors += c.errors;
            t.validSame += c.validSame;
            t.validDifferent += c.validDifferent;
            t.problems += c.problems;
        }
        return t;
    }
    std::string report(const char* title) const {
        std::ostringstream out;
        out << title << "\n";
        for (int r = 0; r < Layout::RegionCount; ++r) {
            const Counts& c = regions[static_cast<std::size_t>(r)];
            if (c.cases == 0) continue;
            out << "  " << Layout::name(r) << ": " << c.cases << " cases, " << c.errors << " errors, " << c.validSame
                << " valid (same data), " << c.validDifferent << " valid (different data), " << c.problems
                << " problems\n";
        }
        const Counts t = total();
        out << "  total: " << t.cases << " cases, " << t.errors << " errors, " << t.validSame << " valid (same), "
            << t.validDifferent << " valid (different), " << t.problems << " problems\n";
        for (const std::string& p : problems) out << "  PROBLEM " << p << "\n";
        return out.str();
    }
};

std::string at(std::size_t offset, const char* how, unsigned pattern) {
    std::ostringstream out;
    out << "offset " << offset << " " << how << " 0x" << std::hex << pattern;
    return out.str();
}

// ---------------------------------------------------------------------------
// The tests.

TEST(Corruption, SampleMapHasEveryRegion) {
    Checker c;
    const dsm::MapInfo info = dsm::DeepShadowMap::open(c.original)->info();
    EXPECT_EQ(info.levels.size(), 5u);
    EXPECT_EQ(info.channels, 3);
    EXPECT_TRUE(info.hasCounts);
    EXPECT_EQ(info.maxLayers, 2);
    EXPECT_GT(info.metadata.size(), 20u);
    EXPECT_NO_THROW(dsm::validate(c.original));
    const Layout& L = c.layout;
    EXPECT_GE(L.emptyTiles, 3u) << "empty tiles at level 0 and level 1";
    EXPECT_GE(L.compressedTiles, 1u);
    EXPECT_GE(L.storedTiles, 1u) << "at least one tile stored without zlib";
    EXPECT_EQ(L.levels.front().directory.offset, L.tiles.back().data.offset + L.tiles.back().data.size);
    EXPECT_EQ(L.levelTable.offset, L.levels.back().directory.offset + L.levels.back().directory.size);
    EXPECT_EQ(L.metadata.offset, L.levelTable.offset + L.levelTable.size);
    EXPECT_EQ(L.metadata.offset + L.metadata.size, c.bytes.size());
    // Resealing an intact file changes nothing, so the CRC layout read here is right.
    Bytes copy = c.bytes;
    reseal(copy, L);
    EXPECT_EQ(copy, c.bytes);
    // A few KB, so that the exhaustive loops below stay fast.
    EXPECT_LT(c.bytes.size(), 8000u);
    std::ostringstream sizes;
    for (int r = 0; r < Layout::RegionCount; ++r)
        sizes << " " << Layout::name(r) << " " << L.region(r, c.bytes.size()).size;
    std::printf("sample map: %zu bytes:%s; %zu tiles (%zu compressed, %zu stored, %zu empty)\n", c.bytes.size(),
                sizes.str().c_str(), L.tiles.size() + L.emptyTiles, L.compressedTiles, L.storedTiles, L.emptyTiles);
}

// Every byte changed by xor: each of its bits and all of them (0xFF) in the
// header, directories, level table and metadata; the lowest bit, the highest
// bit and all of them in tile data (most of the file, where every damaged
// copy costs a tile decode; CRC-32 detects any error within 32 bits, so the
// other bits take the same path). All must be errors.
TEST(Corruption, ByteFlipsAreAllDetected) {
    Checker c;
    Tally tally;
    static constexpr unsigned kEveryBit[] = {0x01, 0x02, 0x04, 0x08, 0x10, 0x20, 0x40, 0x80, 0xFF};
    static constexpr unsigned kSomeBits[] = {0x01, 0x80, 0xFF};
    std::size_t expected = 0;
    Bytes copy = c.bytes;
    for (std::size_t i = 0; i < c.bytes.size(); ++i) {
        const int region = c.layout.regionOf(i);
        const std::span<const unsigned> patterns =
            region == Layout::TileData ? std::span<const unsigned>(kSomeBits) : std::span<const unsigned>(kEveryBit);
        for (unsigned pattern : patterns) {
            copy[i] = static_cast<std::uint8_t>(c.bytes[i] ^ pattern);
            tally.add(region, c.check(copy), at(i, "xor", pattern));
        }
        copy[i] = c.bytes[i];
        expected += patterns.size();
    }
    const std::string report = tally.report("byte flips (xor):");
    std::printf("%s", report.c_str());
    const Tally::Counts t = tally.total();
    EXPECT_EQ(t.cases, expected);
    EXPECT_EQ(t.problems, 0u) << report;
    EXPECT_EQ(t.errors, t.cases) << "a flip went undetected\n" << report;
}

// Every length from 0 to size - 1: all must be errors.
TEST(Corruption, TruncationsAreAllDetected) {
    Checker c;
    Tally tally;
    // Longest first, so that the buffer file only ever shrinks.
    for (std::size_t length = c.bytes.size(); length-- > 0;) {
        const Bytes copy(c.bytes.begin(), c.bytes.begin() + static_cast<std::ptrdiff_t>(length));
        tally.add(c.layout.regionOf(length), c.check(copy), "truncated to " + std::to_string(length));
    }
    const std::string report = tally.report("truncations (region of the first missing byte):");
    std::printf("%s", report.c_str());
    const Tally::Counts t = tally.total();
    EXPECT_EQ(t.cases, c.bytes.size());
    EXPECT_EQ(t.problems, 0u) << report;
    EXPECT_EQ(t.errors, t.cases) << report;
}

// Appending 1, 7 or 4096 bytes of zeros or garbage: all must be errors.
TEST(Corruption, ExtensionsAreAllDetected) {
    Checker c;
    Tally tally;
    for (std::size_t extra : {1u, 7u, 4096u})
        for (bool garbage : {false, true}) {
            Bytes copy = c.bytes;
            for (std::size_t i = 0; i < extra; ++i)
                copy.push_back(garbage ? static_cast<std::uint8_t>(mix(static_cast<std::uint32_t>(i)) >> 7) : 0);
            tally.add(Layout::Metadata, c.check(copy),
                      "extended by " + std::to_string(extra) + (garbage ? " garbage bytes" : " zeros"));
        }
    const std::string report = tally.report("extensions:");
    std::printf("%s", report.c_str());
    const Tally::Counts t = tally.total();
    EXPECT_EQ(t.cases, 6u);
    EXPECT_EQ(t.problems, 0u) << report;
    EXPECT_EQ(t.errors, t.cases) << report;
}

// Each whole region overwritten with 0x00, 0xFF or garbage, with the CRCs left
// as they were and recomputed afterwards.
TEST(Corruption, RegionOverwrites) {
    Checker c;
    Tally plain, resealed;
    for (int r = 0; r < Layout::RegionCount; ++r) {
        const Range range = c.layout.region(r, c.bytes.size());
        for (int fill = 0; fill < 3; ++fill) {
            Bytes copy = c.bytes;
            for (std::uint64_t i = range.offset; i < range.offset + range.size; ++i)
                copy[i] = fill == 0 ? 0x00 : fill == 1 ? 0xFF : static_cast<std::uint8_t>(mix(static_cast<std::uint32_t>(i)));
            const std::string what = std::string(Layout::name(r)) + " fill " + std::to_string(fill);
            plain.add(r, c.check(copy), what);
            // Resealing writes the CRC fields of the original layout, which
            // would undo part of a header or level table overwrite; the
            // other regions keep their damage.
            if (r == Layout::Header) continue;
            reseal(copy, c.layout);
            resealed.add(r, c.check(copy), what + " resealed");
        }
    }
    const std::string report = plain.report("region overwrites:") + resealed.report("region overwrites, resealed:");
    std::printf("%s", report.c_str());
    EXPECT_EQ(plain.total().problems, 0u) << report;
    EXPECT_EQ(plain.total().errors, plain.total().cases) << report;
    EXPECT_EQ(resealed.total().problems, 0u) << report;
}

// Byte flips with every CRC-32 recomputed: the structural checks behind the
// CRCs (sizes, offsets, counts, function invariants, zlib) see the damage.
// Some copies are then valid files with different contents; none may crash or
// throw anything but dsm::Error.
TEST(Corruption, ResealedByteFlipsFailCleanly) {
    Checker c;
    Tally tally;
    static constexpr unsigned kPatterns[] = {0x01, 0xFF};
    Bytes copy = c.bytes;
    for (std::size_t i = 0; i < c.bytes.size(); ++i) {
        for (unsigned pattern : kPatterns) {
            copy = c.bytes;
            copy[i] = static_cast<std::uint8_t>(c.bytes[i] ^ pattern);
            reseal(copy, c.layout);
            tally.add(c.layout.regionOf(i), c.check(copy), at(i, "xor (resealed)", pattern));
        }
    }
    const std::string report = tally.report("byte flips with CRCs recomputed:");
    std::printf("%s", report.c_str());
    EXPECT_EQ(tally.total().problems, 0u) << report;
    // Every field of a tile directory entry is checked against the tile it
    // describes (or must be 0 for an empty tile), so a changed directory is
    // never read as a valid map; only its reserved words may change unseen.
    EXPECT_EQ(tally.regions[Layout::Directories].validDifferent, 0u) << report;
    // Flips of the CRC fields themselves are undone by resealing.
    EXPECT_GT(tally.total().validSame, 0u);
    EXPECT_GT(tally.total().errors, tally.total().cases / 2) << report;
}

}  // namespace
