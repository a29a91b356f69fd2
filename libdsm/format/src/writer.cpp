#include "dsm/writer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <map>
#include <memory>
#include <utility>
#include <vector>

#include "dsm/error.h"
#include "dsm/output_file.h"
#include "dsm/value_step.h"
#include "format_layout.h"
#include "mipmap.h"
#include "text.h"
#include "tile_codec.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

// Rounding of double values to the stored float32 (see compressor.h).
constexpr double kStoreRounding = 0x1p-25;

// The level of the codec the options choose.
int codecLevel(const WriterOptions& o) { return o.codec == TileCodec::Zstd ? o.zstdLevel : o.zlibLevel; }

struct Level {
    LevelInfo info;
    std::vector<TileSummary> directory;
    std::vector<bool> written;
};

// A tile of a coarser level being filled from its (up to 4) children.
struct PendingTile {
    std::vector<VisibilityFunction> pixels;
    unsigned childrenReceived = 0;
};

// The pixels of the next level that one tile covers, averaged from it
// (MapWriter::Impl::averageCoarser()), with the working memory that takes.
struct CoarserPixels {
    std::vector<VisibilityFunction> pixels;  // row order over the tile's CoarserRect
    FunctionAverager averager;
    std::vector<VisibilityView> block;
    std::vector<double> weights;
};

// The pixels [x0, x1) x [y0, y1) of level + 1 that a tile of `level` covers:
// with an even tile size each coarser pixel's 2 x 2 children lie in one tile.
struct CoarserRect {
    std::uint32_t x0, x1, y0, y1;
    std::size_t index(std::uint32_t x, std::uint32_t y) const { return std::size_t(y - y0) * (x1 - x0) + (x - x0); }
};

}  // namespace

// What prepareTile() makes of a level-0 tile, and its working memory, kept
// from one tile to the next.
struct PreparedTile::Impl {
    std::uint32_t tx = 0, ty = 0;
    bool ready = false;  // prepared and not yet written
    bool empty = true;   // every pixel empty: no level-1 pixels to add
    format::EncodedTile encoded;
    // The level-1 pixels the tile covers; none without level 1 or when the
    // tile is empty.
    CoarserPixels coarser;
    VisibilityFunction rounded;  // a pixel rounded to the level's step, before it takes the pixel's place
};

PreparedTile::PreparedTile() : impl_(std::make_unique<Impl>()) {}
PreparedTile::~PreparedTile() = default;
PreparedTile::PreparedTile(PreparedTile&&) noexcept = default;
PreparedTile& PreparedTile::operator=(PreparedTile&&) noexcept = default;

struct MapWriter::Impl {
    std::string path;
    WriterOptions options;
    std::unique_ptr<OutputFile> file;
    std::uint64_t offset = 0;
    std::vector<Level> levels;
    std::vector<std::map<std::uint32_t, PendingTile>> pending;  // per level >= 1
    // writeTile()'s tile, and the working memory of the levels >= 1 (built
    // on the writer's thread).
    PreparedTile serialTile;
    std::vector<VisibilityFunction> level0Copy;  // writeTile()'s pixels, rounded
    CoarserPixels coarser;
    VisibilityFunction rounded;  // a coarser pixel with its values rounded to the level's step
    // Coarser tiles written, kept for their functions' storage: the next
    // pending tile is averaged into them.
    std::vector<std::vector<VisibilityFunction>> spareTiles;
    bool finished = false;

    std::string where() const { return concat("'", path, "'"); }

    // Level-0 tile (tx, ty) made ready for the file from its pixels, checked
    // and with their values on the level's step (`empty` when all are
    // empty): encoded, and its level-1 pixels averaged. Safe on any thread.
    void prepareRounded(std::uint32_t tx, std::uint32_t ty, Span<const VisibilityFunction> rounded, bool empty,
                        PreparedTile::Impl& t) const;

    void writeBytes(const std::uint8_t* data, std::size_t size) {
        file->write(data, size);
        offset += size;
    }

    std::uint32_t tileExtent(std::uint32_t levelExtent, std::uint32_t t) const {
        return std::min(options.tileSize, levelExtent - t * options.tileSize);
    }

    // The tile of `level` coded as stored, or nothing for a tile whose pixels
    // are all empty (`pixels` empty, their values already on the level's
    // step): the parts of a region build and sparse maps are mostly such
    // tiles, and they cost nothing to store or average. Reads only what the
    // constructor set: safe on any thread.
    format::EncodedTile encode(unsigned level, Span<const VisibilityFunction> pixels) const {
        const format::TileLayout layout{options.channels, options.counts, options.maxLayers, options.formatMinor >= 1,
                                        levels[level].info.valueStep, options.codec};
        return pixels.empty() ? format::EncodedTile{}
                              : format::encodeTile(std::span(pixels.data(), pixels.size()), layout, codecLevel(options));
    }

    // Appends an encoded tile of `level` and enters it in the directory.
    void store(unsigned level, std::uint32_t tx, std::uint32_t ty, format::EncodedTile& encoded) {
        Level& L = levels[level];
        const std::uint32_t index = ty * L.info.tilesX + tx;
        if (!encoded.stored.empty()) {
            encoded.summary.offset = offset;
            writeBytes(encoded.stored.data(), encoded.stored.size());
        }
        L.directory[index] = encoded.summary;
        L.written[index] = true;
        L.info.vertexCount += encoded.summary.vertexCount;
        L.info.nonEmptyPixels += encoded.summary.nonEmptyPixels;
        L.info.storedBytes += encoded.summary.storedBytes;
    }

    // A coarser tile (level >= 1), complete: stored, and averaged into its parent.
    void acceptTile(unsigned level, std::uint32_t tx, std::uint32_t ty, const std::vector<VisibilityFunction>& pixels) {
        format::EncodedTile encoded = encode(level, pixels);
        store(level, tx, ty, encoded);
        if (level + 1 == levels.size()) return;
        if (!pixels.empty()) averageCoarser(level, tx, ty, pixels, coarser);
        addToParent(level, tx, ty, pixels.empty() ? nullptr : &coarser.pixels);
    }

    CoarserRect coarserRect(unsigned level, std::uint32_t tx, std::uint32_t ty) const {
        const std::uint32_t x0 = tx * options.tileSize, y0 = ty * options.tileSize;
        const std::uint32_t w = tileExtent(levels[level].info.width, tx), h = tileExtent(levels[level].info.height, ty);
        return {x0 / 2, (x0 + w + 1) / 2, y0 / 2, (y0 + h + 1) / 2};
    }

    // The pixels of level + 1 that tile (tx, ty) of `level` covers
    // (coarserRect()), averaged from its `pixels` into `out.pixels`. Reads
    // only what the constructor set: safe on any thread, each with its own
    // `out`.
    void averageCoarser(unsigned level, std::uint32_t tx, std::uint32_t ty, Span<const VisibilityFunction> pixels,
                        CoarserPixels& out) const {
        const Level& child = levels[level];
        const Level& parent = levels[level + 1];
        const std::uint32_t cw = tileExtent(child.info.width, tx), ch = tileExtent(child.info.height, ty);
        const std::uint32_t x0 = tx * options.tileSize, y0 = ty * options.tileSize;  // the tile's origin
        // With stored value steps the compressor leaves room for the rounding
        // (value_step.h), so the level's stated tolerance holds as stored.
        const double tolerance =
            options.quantiseValues ? compressorTolerance(parent.info.tolerance) : parent.info.tolerance;
        // Level-0 pixels covered by pixel x of `level` along one axis: fewer at
        // the far edge of an odd-sized level, so each coarser pixel stays the
        // exact average of the full-resolution pixels it covers.
        const auto covered = [&](std::uint32_t x, std::uint32_t fullExtent) {
            const std::uint64_t span = std::uint64_t(1) << level;
            return static_cast<double>(std::min<std::uint64_t>((x + 1) * span, fullExtent) - x * span);
        };
        const CoarserRect rect = coarserRect(level, tx, ty);
        const std::size_t count = std::size_t(rect.x1 - rect.x0) * (rect.y1 - rect.y0);
        if (out.pixels.size() < count) out.pixels.resize(count);
        for (std::uint32_t py = rect.y0; py < rect.y1; ++py) {
            for (std::uint32_t px = rect.x0; px < rect.x1; ++px) {
                out.block.clear();
                out.weights.clear();
                for (std::uint32_t dy = 0; dy < 2; ++dy)
                    for (std::uint32_t dx = 0; dx < 2; ++dx) {
                        const std::uint32_t cx = 2 * px + dx, cy = 2 * py + dy;
                        if (cx < x0 + cw && cy < y0 + ch) {
                            out.block.push_back(pixels[std::size_t(cy - y0) * cw + (cx - x0)].view());
                            out.weights.push_back(covered(cx, options.width) * covered(cy, options.height));
                        }
                    }
                out.averager.average(out.block, out.weights, tolerance, options.counts, options.centredCompression,
                                     out.pixels[rect.index(px, py)]);
            }
        }
    }

    // Puts the coarser pixels of tile (tx, ty) of `level` (averageCoarser()'s,
    // or none for an empty tile: the average of empty functions is empty, as
    // the parent's pixels start) into the parent tile, and writes the parent
    // once all its children have arrived. The pixels trade storage with the
    // parent's.
    void addToParent(unsigned level, std::uint32_t tx, std::uint32_t ty, std::vector<VisibilityFunction>* block) {
        const Level& child = levels[level];
        const Level& parent = levels[level + 1];
        const std::uint32_t T = options.tileSize;
        const std::uint32_t ptx = tx / 2, pty = ty / 2;
        const std::uint32_t parentIndex = pty * parent.info.tilesX + ptx;
        PendingTile& p = pending[level + 1][parentIndex];
        if (block) {
            const std::uint32_t pw = tileExtent(parent.info.width, ptx), ph = tileExtent(parent.info.height, pty);
            if (p.pixels.empty()) {
                if (!spareTiles.empty()) {
                    p.pixels = std::move(spareTiles.back());
                    spareTiles.pop_back();
                }
                p.pixels.assign(std::size_t(pw) * ph, VisibilityFunction(1, options.counts));
            }
            const CoarserRect rect = coarserRect(level, tx, ty);
            for (std::uint32_t py = rect.y0; py < rect.y1; ++py)
                for (std::uint32_t px = rect.x0; px < rect.x1; ++px)
                    std::swap(p.pixels[std::size_t(py - pty * T) * pw + (px - ptx * T)], (*block)[rect.index(px, py)]);
        }
        const std::uint32_t expected = (std::min(2 * ptx + 2, child.info.tilesX) - 2 * ptx) *
                                       (std::min(2 * pty + 2, child.info.tilesY) - 2 * pty);
        if (++p.childrenReceived == expected) {
            std::vector<VisibilityFunction> done = std::move(p.pixels);
            pending[level + 1].erase(parentIndex);
            if (parent.info.valueStep > 0.0)
                for (VisibilityFunction& f : done) {
                    roundValues(f, parent.info.valueStep, rounded);
                    std::swap(f, rounded);  // `rounded` keeps f's storage for the next pixel
                }
            acceptTile(level + 1, ptx, pty, done);
            spareTiles.push_back(std::move(done));
        }
    }
};

// The public members below attach the output's path to the errors they raise
// (Error::withFile), whichever step below raised them.
MapWriter::MapWriter(const std::string& path, const WriterOptions& options) try : impl_(std::make_unique<Impl>()) {
    Impl& s = *impl_;
    s.path = path;
    s.options = options;
    const std::string where = s.where();
    auto fail = [&](const std::string& what, ErrorCode code = ErrorCode::argument) {
        throw Error(code, concat(where, ": ", what));
    };
    if (options.width == 0 || options.height == 0 || options.width > (1u << 17) || options.height > (1u << 17))
        fail(concat("image size ", options.width, "x", options.height, " is not in [1, 131072]"));
    if (options.tileSize < format::kMinTileSize || options.tileSize > format::kMaxTileSize ||
        !std::has_single_bit(options.tileSize))
        fail(concat("tile size ", options.tileSize, " is not a power of two from 2 to 4096"));
    if (options.channels != 1 && options.channels != 3) fail(concat("channel count ", options.channels, " is not 1 or 3"));
    if (options.maxLayers < 1 || options.maxLayers > 255) fail(concat("layer count ", options.maxLayers, " is not in [1, 255]"));
    if (!std::isfinite(options.tolerance) || options.tolerance < 0.0)
        fail(concat("tolerance ", options.tolerance, " is not a finite value >= 0"));
    if (!std::isfinite(options.levelToleranceFactor) || options.levelToleranceFactor <= 0.0)
        fail(concat("level tolerance factor ", options.levelToleranceFactor, " is not a finite value > 0"));
    if (options.zlibLevel < 0 || options.zlibLevel > 9) fail(concat("zlib level ", options.zlibLevel, " is not in [0, 9]"));
    if (options.codec != TileCodec::Zlib && options.codec != TileCodec::Zstd) fail("unknown tile codec");
    if (options.zstdLevel < 0 || options.zstdLevel > 22) fail(concat("zstd level ", options.zstdLevel, " is not in [0, 22]"));
    if (options.codec == TileCodec::Zstd && options.formatMinor < 1) fail("zstd tiles need format 1.1");
    if (!std::isfinite(options.filterWidth) || options.filterWidth < 0.0)
        fail(concat("filter width ", options.filterWidth, " is not a finite value >= 0"));
    if (static_cast<unsigned>(options.filter) > 2) fail("unknown pixel filter");
    if (options.formatMinor > kFormatVersionMinor)
        fail(concat("format version 1.", options.formatMinor, " is not one this writer writes (1.0 to 1.",
                    kFormatVersionMinor, ")"));
    if (!std::isfinite(options.areaLightRadius) || options.areaLightRadius < 0.0 ||
        !std::isfinite(options.areaLightPlaneDepth) || options.areaLightPlaneDepth < 0.0)
        fail(concat("area light radius ", options.areaLightRadius, " or plane depth ", options.areaLightPlaneDepth,
                    " is not a finite value >= 0"));
    if (options.formatMinor == 0 && (options.quantiseValues || options.areaLightRadius > 0.0))
        fail("value steps and the area light need format version 1.1");
    try {
        options.camera.validate();
    } catch (const Error& e) {
        fail(e.what());
    }

    const unsigned full = fullLevelCount(options.width, options.height);
    if (options.mipLevels && *options.mipLevels == 0) fail("mip level count 0 is not >= 1");
    const unsigned count = std::min(options.mipLevels.value_or(full), full);
    double tolerance = options.tolerance, bound = 0.0;
    for (unsigned l = 0; l < count; ++l) {
        Level L;
        L.info.width = levelExtent(options.width, l);
        L.info.height = levelExtent(options.height, l);
        L.info.tilesX = (L.info.width + options.tileSize - 1) / options.tileSize;
        L.info.tilesY = (L.info.height + options.tileSize - 1) / options.tileSize;
        L.info.tolerance = tolerance;
        L.info.valueStep = options.quantiseValues ? valueStep(tolerance) : 0.0;
        bound += std::max(tolerance, kStoreRounding);
        L.info.errorBound = bound;
        L.directory.resize(std::size_t(L.info.tilesX) * L.info.tilesY);
        L.written.assign(L.directory.size(), false);
        s.levels.push_back(std::move(L));
        tolerance *= options.levelToleranceFactor;
    }
    s.pending.resize(count);

    s.file = std::make_unique<OutputFile>(path);
    const std::vector<std::uint8_t> placeholder(format::headerSizeOf(options.formatMinor), 0);
    s.writeBytes(placeholder.data(), placeholder.size());
} catch (const Error& e) {
    throw e.withFile(path);
}

MapWriter::~MapWriter() = default;

std::uint32_t MapWriter::tilesX() const { return impl_->levels[0].info.tilesX; }
std::uint32_t MapWriter::tilesY() const { return impl_->levels[0].info.tilesY; }
std::uint32_t MapWriter::tileWidth(std::uint32_t tx) const {
    return impl_->tileExtent(impl_->levels[0].info.width, tx);
}
std::uint32_t MapWriter::tileHeight(std::uint32_t ty) const {
    return impl_->tileExtent(impl_->levels[0].info.height, ty);
}

namespace {

// Throws dsm::Error unless `pixels` fit level-0 tile (tx, ty) of a map with
// these options: their number, channels, counts and layers, and each a valid
// function.
void checkTile(const MapWriter& writer, const WriterOptions& options, const std::string& where, std::uint32_t tx,
               std::uint32_t ty, Span<const VisibilityFunction> pixels) {
    if (tx >= writer.tilesX() || ty >= writer.tilesY())
        throw Error(ErrorCode::argument,
                    concat(where, ": outside the ", writer.tilesX(), "x", writer.tilesY(), " tiles of the map"));
    const std::uint32_t w = writer.tileWidth(tx), h = writer.tileHeight(ty);
    if (pixels.size() != std::size_t(w) * h)
        throw Error(ErrorCode::argument, concat(where, ": ", pixels.size(), " pixels given, the tile has ", w, "x", h));
    for (std::size_t p = 0; p < pixels.size(); ++p) {
        const VisibilityFunction& f = pixels[p];
        // Built only for a message: formatting it for every pixel cost more
        // than encoding the tile.
        const auto pixelWhere = [&] {
            return concat(where, " pixel ", tx * options.tileSize + p % w, ",", ty * options.tileSize + p / w, ": ");
        };
        if (f.channels() > options.channels)
            throw Error(ErrorCode::argument, concat(pixelWhere(), "RGB function in a monochrome map"));
        if (options.counts && !f.hasCounts() && !f.empty())
            throw Error(ErrorCode::argument,
                        concat(pixelWhere(), "the map stores sample counts but the function has none"));
        if (static_cast<int>(f.layerCount()) > options.maxLayers)
            throw Error(ErrorCode::argument,
                        concat(pixelWhere(), f.layerCount(), " layers exceed the map's ", options.maxLayers));
        try {
            f.validate();
        } catch (const Error& e) {
            throw Error(e.code(), pixelWhere() + e.what());
        }
    }
}

bool allEmpty(Span<const VisibilityFunction> pixels) {
    return std::all_of(pixels.begin(), pixels.end(), [](const VisibilityFunction& f) { return f.empty(); });
}

}  // namespace

void MapWriter::Impl::prepareRounded(std::uint32_t tx, std::uint32_t ty, Span<const VisibilityFunction> rounded,
                                     bool empty, PreparedTile::Impl& t) const {
    const Span<const VisibilityFunction> stored = empty ? Span<const VisibilityFunction>() : rounded;
    t.encoded = encode(0, stored);
    if (levels.size() > 1 && !empty) averageCoarser(0, tx, ty, stored, t.coarser);
    t.tx = tx;
    t.ty = ty;
    t.empty = empty;
    t.ready = true;
}

void MapWriter::prepareTile(std::uint32_t tx, std::uint32_t ty, Span<VisibilityFunction> pixels,
                            PreparedTile& out) const try {
    const Impl& s = *impl_;
    PreparedTile::Impl& t = *out.impl_;
    t.ready = false;
    checkTile(*this, s.options, concat(s.where(), " level 0 tile ", tx, ",", ty), tx, ty, pixels);
    const bool empty = allEmpty(pixels);
    const double step = s.levels[0].info.valueStep;
    if (!empty && step > 0.0)
        for (VisibilityFunction& f : pixels) {
            roundValues(f, step, t.rounded);
            std::swap(f, t.rounded);  // `rounded` keeps f's storage for the next pixel
        }
    s.prepareRounded(tx, ty, pixels, empty, t);
} catch (const Error& e) {
    throw e.withFile(impl_->path);
}

void MapWriter::writePreparedTile(PreparedTile& tile) try {
    Impl& s = *impl_;
    PreparedTile::Impl& t = *tile.impl_;
    if (!t.ready) throw Error(ErrorCode::argument, concat(s.where(), ": a tile not prepared, or written already"));
    const std::string where = concat(s.where(), " level 0 tile ", t.tx, ",", t.ty);
    if (s.finished) throw Error(ErrorCode::argument, concat(where, ": the file is already finished"));
    if (s.levels[0].written[std::size_t(t.ty) * tilesX() + t.tx])
        throw Error(ErrorCode::argument, concat(where, ": written twice"));
    t.ready = false;
    s.store(0, t.tx, t.ty, t.encoded);
    if (s.levels.size() > 1) s.addToParent(0, t.tx, t.ty, t.empty ? nullptr : &t.coarser.pixels);
} catch (const Error& e) {
    throw e.withFile(impl_->path);
}

void MapWriter::writeTile(std::uint32_t tx, std::uint32_t ty, Span<const VisibilityFunction> pixels) try {
    Impl& s = *impl_;
    const std::string where = concat(s.where(), " level 0 tile ", tx, ",", ty);
    if (s.finished) throw Error(ErrorCode::argument, concat(where, ": the file is already finished"));
    checkTile(*this, s.options, where, tx, ty, pixels);
    if (s.levels[0].written[std::size_t(ty) * tilesX() + tx])
        throw Error(ErrorCode::argument, concat(where, ": written twice"));
    // The pixels with their values rounded to the level's step (a copy when
    // there is none), in the functions of the tile before, so that the
    // writer allocates nothing once they have grown.
    const bool empty = allEmpty(pixels);
    s.level0Copy.resize(empty ? 0 : pixels.size());
    for (std::size_t p = 0; p < s.level0Copy.size(); ++p)
        roundValues(pixels[p], s.levels[0].info.valueStep, s.level0Copy[p]);
    s.prepareRounded(tx, ty, s.level0Copy, empty, *s.serialTile.impl_);
    writePreparedTile(s.serialTile);
} catch (const Error& e) {
    throw e.withFile(impl_->path);
}

void MapWriter::finish() try {
    Impl& s = *impl_;
    if (s.finished) throw Error(ErrorCode::argument, concat(s.where(), ": finish() called twice"));
    for (std::uint32_t ty = 0; ty < tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < tilesX(); ++tx)
            if (!s.levels[0].written[std::size_t(ty) * tilesX() + tx])
                throw Error(ErrorCode::argument,
                            concat(s.where(), ": level 0 tile ", tx, ",", ty, " was never written"));

    MapInfo info;
    info.width = s.options.width;
    info.height = s.options.height;
    info.tileSize = s.options.tileSize;
    info.channels = s.options.channels;
    info.hasCounts = s.options.counts;
    info.maxLayers = s.options.maxLayers;
    info.camera = s.options.camera;
    info.filter = s.options.filter;
    info.filterWidth = s.options.filterWidth;
    for (const Level& L : s.levels) info.levels.push_back(L.info);
    info.codedTiles = s.options.formatMinor >= 1;
    info.predictedDepths = info.codedTiles;
    info.codec = s.options.codec;
    info.codecLevel = codecLevel(s.options);
    info.areaLightRadius = s.options.areaLightRadius;
    info.areaLightPlaneDepth = s.options.areaLightPlaneDepth;
    format::Header header = format::headerFromInfo(info, s.options.formatMinor);

    std::vector<format::LevelEntry> entries;
    for (const Level& L : s.levels) {
        std::vector<std::uint8_t> bytes;
        bytes.reserve(L.directory.size() * format::kTileEntrySize);
        for (const TileSummary& t : L.directory) format::encodeTileEntry(bytes, t);
        format::LevelEntry e;
        e.info = L.info;
        e.directoryOffset = s.offset;
        e.directoryCrc = format::crc32(bytes.data(), bytes.size());
        s.writeBytes(bytes.data(), bytes.size());
        entries.push_back(e);
    }
    std::vector<std::uint8_t> table;
    for (const format::LevelEntry& e : entries) format::encodeLevelEntry(table, e, s.options.formatMinor);
    header.levelTableOffset = s.offset;
    header.levelTableCrc = format::crc32(table.data(), table.size());
    s.writeBytes(table.data(), table.size());
    const auto* metadata = reinterpret_cast<const std::uint8_t*>(s.options.metadata.data());
    header.metadataOffset = s.offset;
    header.metadataSize = s.options.metadata.size();
    header.metadataCrc = format::crc32(metadata, s.options.metadata.size());
    s.writeBytes(metadata, s.options.metadata.size());
    header.fileSize = s.offset;

    const std::vector<std::uint8_t> headerBytes = format::encodeHeader(header);
    s.file->writeAt(0, headerBytes.data(), headerBytes.size());
    s.file->commit();
    s.finished = true;
} catch (const Error& e) {
    throw e.withFile(impl_->path);
}

DSM_NAMESPACE_END
