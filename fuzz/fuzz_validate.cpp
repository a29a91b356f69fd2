// libFuzzer target: the input bytes as a .dsm file. dsm::validate() must
// either accept the file or throw dsm::Error; a file it accepts must then open
// and read (every pixel of every level, a few filtered lookups) without any
// error at all. Anything else, a crash, a sanitizer report, a leak or an
// exception of another type, is a finding. Built by fuzz/CMakeLists.txt.
//
// Every section of a file is protected by a CRC-32, so nearly every mutation
// stops at a CRC check. Each input is therefore tried twice: as it is (which
// exercises the CRC checks and everything before them), and "resealed", with
// the recorded file size and every CRC-32 it can locate recomputed, so that
// mutations reach the structural checks, zlib and the function checks behind
// the CRCs.
#include <dsm/error.h>
#include <dsm/lookup.h>
#include <dsm/reader.h>
#include <dsm/tile_cache.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "scratch_file.h"

namespace {

// Limits for untrusted files, tightened so that one input cannot ask for more
// than a few MB or a few million pixel reads (the defaults allow GB tiles and
// 131072 x 131072 maps, which a fuzzer would spend all its time on).
dsm::ReaderOptions fuzzOptions() {
    dsm::ReaderOptions o;
    o.maxWidth = 256;
    o.maxHeight = 256;
    o.maxVerticesPerPixel = 1u << 16;
    o.maxTileBytes = 16u << 20;
    o.maxMetadataBytes = 1u << 20;
    o.cache = dsm::TileCache::create(4u << 20);
    return o;
}

void readEverything(const std::string& path, const dsm::ReaderOptions& options) {
    const auto map = dsm::DeepShadowMap::open(path, options);
    const dsm::MapInfo& info = map->info();
    double sink = 0.0;
    for (unsigned l = 0; l < info.levels.size(); ++l) {
        const dsm::LevelInfo& L = info.levels[l];
        for (std::uint32_t ty = 0; ty < L.tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < L.tilesX; ++tx) sink += map->tile(l, tx, ty).maxZ;
        for (std::uint32_t y = 0; y < L.height; ++y)
            for (std::uint32_t x = 0; x < L.width; ++x) {
                const dsm::PixelFunction p = map->pixel(l, x, y);
                if (!p->empty()) sink += p->evaluate(0.5 * (p->z(0) + p->z(p->size() - 1)), p->channels() - 1);
            }
    }
    // Filtered lookups through the file's camera and levels.
    dsm::LookupContext lookup(map);
    dsm::LookupOptions wide;
    wide.filter = dsm::PixelFilter::Gaussian;
    wide.filterWidth = 3.0;
    const double w = info.width, h = info.height;
    sink += lookup.raster(0.5 * w, 0.5 * h, 1.0).v[0];
    sink += lookup.raster(0.25 * w, 0.75 * h, 2.0, wide).v[0];
    sink += lookup.world({0.1, -0.2, 1.5}, wide).v[0];
    sink += lookup.world({0.0, 0.0, 0.5}).v[0];
    if (sink != sink) std::abort();  // NaN: a value escaped the [0, 1] checks
}

std::uint32_t crc32(const std::uint8_t* data, std::size_t size) {
    static const auto table = [] {
        std::vector<std::uint32_t> t(256);
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

// Recomputes what it can find of a file's integrity fields, trusting the
// (mutated) offsets and sizes only as far as they lie inside the file: the
// recorded file size, tile CRCs, directory CRCs, the level table and metadata
// CRCs, the header CRC. Offsets follow spec/dsm-format.md.
class Resealer {
public:
    explicit Resealer(std::vector<std::uint8_t>& f) : f_(f) {}

    void run() {
        std::uint64_t headerSize = 0, levelCount = 0, levelEntrySize = 0, tileEntrySize = 0, levelTable = 0,
                      metadata = 0, metadataSize = 0;
        if (!get(12, 4, headerSize) || headerSize < 272 || headerSize > f_.size()) return;
        get(216, 4, levelCount);
        get(220, 4, levelEntrySize);
        get(224, 4, tileEntrySize);
        get(232, 8, levelTable);
        get(240, 8, metadata);
        get(248, 8, metadataSize);
        put(264, 8, f_.size());
        if (levelCount <= 64 && levelEntrySize >= 72 && levelEntrySize <= (1u << 16) && tileEntrySize >= 40 &&
            tileEntrySize <= (1u << 16) && fits(levelTable, levelCount * levelEntrySize)) {
            for (std::uint64_t l = 0; l < levelCount; ++l) {
                const std::uint64_t e = levelTable + l * levelEntrySize;
                std::uint64_t tilesX = 0, tilesY = 0, directory = 0;
                get(e + 8, 4, tilesX);
                get(e + 12, 4, tilesY);
                get(e + 32, 8, directory);
                const std::uint64_t tiles = tilesX * tilesY;
                if (tiles > f_.size() / tileEntrySize || !fits(directory, tiles * tileEntrySize)) continue;
                for (std::uint64_t t = 0; t < tiles; ++t) {
                    const std::uint64_t d = directory + t * tileEntrySize;
                    std::uint64_t offset = 0, stored = 0;
                    get(d, 8, offset);
                    get(d + 8, 4, stored);
                    if (stored > 0 && fits(offset, stored)) put(d + 16, 4, crc(offset, stored));
                }
                put(e + 64, 4, crc(directory, tiles * tileEntrySize));
            }
            put(256, 4, crc(levelTable, levelCount * levelEntrySize));
        }
        if (fits(metadata, metadataSize)) put(260, 4, crc(metadata, metadataSize));
        put(228, 4, 0);
        put(228, 4, crc(0, headerSize));
    }

private:
    bool fits(std::uint64_t at, std::uint64_t n) const { return at <= f_.size() && n <= f_.size() - at; }
    bool get(std::uint64_t at, int n, std::uint64_t& v) const {
        v = 0;
        if (!fits(at, std::uint64_t(n))) return false;
        for (int i = 0; i < n; ++i) v |= std::uint64_t(f_[at + std::uint64_t(i)]) << (8 * i);
        return true;
    }
    void put(std::uint64_t at, int n, std::uint64_t v) {
        if (!fits(at, std::uint64_t(n))) return;
        for (int i = 0; i < n; ++i) f_[at + std::uint64_t(i)] = static_cast<std::uint8_t>(v >> (8 * i));
    }
    std::uint32_t crc(std::uint64_t at, std::uint64_t n) const { return crc32(f_.data() + at, n); }
    std::vector<std::uint8_t>& f_;
};

// One file: validate, and read it all when validate accepts it.
void check(ScratchFile& scratch, const std::uint8_t* data, std::size_t size, const dsm::ReaderOptions& options) {
    scratch.write(data, size);
    try {
        dsm::validate(scratch.path, options);
    } catch (const dsm::Error& e) {
        if (!*e.what()) std::abort();  // errors must say what is wrong
        return;
    }
    // validate() accepted the file: the normal read path must accept all of it.
    readEverything(scratch.path, options);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static ScratchFile scratch("fuzz_validate.dsm");
    static const dsm::ReaderOptions options = fuzzOptions();
    check(scratch, data, size, options);
    std::vector<std::uint8_t> resealed(data, data + size);
    Resealer(resealed).run();
    if (!std::equal(resealed.begin(), resealed.end(), data)) check(scratch, resealed.data(), resealed.size(), options);
    return 0;
}
