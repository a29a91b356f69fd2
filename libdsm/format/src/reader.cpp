#include "dsm/reader.h"

#include <bit>
#include <cmath>
#include <limits>

#include "dsm/error.h"
#include "format_layout.h"
#include "naming_file.h"
#include "text.h"
#include "tile_cache_impl.h"
#include "tile_codec.h"
#include "reader_impl.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using detail::namingFile;

namespace {

bool validValueStep(double step) {
    if (step == 0.0) return true;
    int exponent = 0;
    const double mantissa = std::frexp(step, &exponent);  // step = 2^(exponent - 1) when a power of two
    return mantissa == 0.5 && exponent - 1 <= -1 && exponent - 1 >= -format::kFinestValueStepExponent;
}

}  // namespace

void DeepShadowMap::Impl::openInput(std::shared_ptr<const MapInput> in, const std::string& name,
                                    const ReaderOptions& o) {
    path = name;
    options = o;
    if (!in) throw Error(ErrorCode::argument, concat(where(), ": no input given"));
    input = std::move(in);
    const std::uint64_t fileSize = input->size();

    // Header: the fixed part first, then all of it if a newer minor version
    // wrote a longer one (the fields we do not know are skipped).
    std::vector<std::uint8_t> head(std::min<std::uint64_t>(fileSize, format::kHeaderSize));
    readAt(0, head.data(), head.size(), where());
    if (head.size() >= 16) {
        const std::uint32_t declared = static_cast<std::uint32_t>(head[12]) | static_cast<std::uint32_t>(head[13]) << 8 |
                                       static_cast<std::uint32_t>(head[14]) << 16 |
                                       static_cast<std::uint32_t>(head[15]) << 24;
        if (declared > head.size() && declared <= fileSize && declared <= (1u << 20)) {
            head.resize(declared);
            readAt(0, head.data(), head.size(), where());
        }
    }
    const format::Header h = format::decodeHeader(head.data(), head.size(), fileSize, options, where());
    format::infoFromHeader(h, info);
    try {
        info.camera.validate();
    } catch (const Error& e) {
        throw Error(ErrorCode::corrupt, concat(where(), ": ", e.what()));
    }

    // Level table.
    std::vector<std::uint8_t> table(std::size_t(h.levelCount) * h.levelEntrySize);
    readAt(h.levelTableOffset, table.data(), table.size(), where());
    if (format::crc32(table.data(), table.size()) != h.levelTableCrc)
        throw Error(ErrorCode::corrupt, concat(where(), ": level table CRC-32 mismatch"));
    for (unsigned l = 0; l < h.levelCount; ++l) {
        const format::LevelEntry e =
            format::decodeLevelEntry(table.data() + std::size_t(l) * h.levelEntrySize, h.levelEntrySize);
        const std::string lw = concat(where(), " level ", l);
        const LevelInfo& L = e.info;
        if (L.width != levelExtent(info.width, l) || L.height != levelExtent(info.height, l))
            throw Error(ErrorCode::corrupt,
                        concat(lw, ": size ", L.width, "x", L.height, " does not halve the level above"));
        if (L.tilesX != (L.width + info.tileSize - 1) / info.tileSize ||
            L.tilesY != (L.height + info.tileSize - 1) / info.tileSize)
            throw Error(ErrorCode::corrupt,
                        concat(lw, ": tile counts ", L.tilesX, "x", L.tilesY, " do not match its size"));
        if (!std::isfinite(L.tolerance) || L.tolerance < 0.0 || !std::isfinite(L.errorBound) || L.errorBound < 0.0)
            throw Error(ErrorCode::corrupt,
                        concat(lw, ": tolerance ", L.tolerance, " or error bound ", L.errorBound, " is invalid"));
        if (!validValueStep(L.valueStep) || (L.valueStep != 0.0 && !info.codedTiles))
            throw Error(ErrorCode::corrupt, concat(lw, ": value step ", L.valueStep,
                                                   " is neither 0 nor a power of two 2^-k (k in [1, 24]) of coded tiles"));
        const std::uint64_t tiles = std::uint64_t(L.tilesX) * L.tilesY;
        const std::uint64_t bytes = tiles * h.tileEntrySize;
        if (e.directoryOffset < h.headerSize || e.directoryOffset > fileSize || bytes > fileSize - e.directoryOffset)
            throw Error(ErrorCode::corrupt,
                        concat(lw, ": tile directory at ", e.directoryOffset, " (", bytes, " bytes) does not fit"));
        std::vector<std::uint8_t> dir(bytes);
        readAt(e.directoryOffset, dir.data(), dir.size(), lw);
        if (format::crc32(dir.data(), dir.size()) != e.directoryCrc)
            throw Error(ErrorCode::corrupt, concat(lw, ": tile directory CRC-32 mismatch"));
        std::vector<TileSummary> tilesOfLevel(tiles);
        std::uint64_t vertices = 0, nonEmpty = 0, stored = 0;
        for (std::uint64_t i = 0; i < tiles; ++i) {
            TileSummary t = format::decodeTileEntry(dir.data() + i * h.tileEntrySize);
            const std::uint32_t tx = static_cast<std::uint32_t>(i % L.tilesX), ty = static_cast<std::uint32_t>(i / L.tilesX);
            const std::string tw = tileWhere(l, tx, ty);
            const std::uint64_t pixels = std::uint64_t(tileExtent(L.width, tx)) * tileExtent(L.height, ty);
            if (t.empty()) {
                if (t.rawBytes != 0 || t.vertexCount != 0 || t.nonEmptyPixels != 0 || t.offset != 0 || t.crc32 != 0 ||
                    std::bit_cast<std::uint32_t>(t.minZ) != 0 || std::bit_cast<std::uint32_t>(t.maxZ) != 0)
                    throw Error(ErrorCode::corrupt, concat(tw, ": empty tile with non-zero directory fields"));
            } else {
                if (t.offset < h.headerSize || t.offset > fileSize || t.storedBytes > fileSize - t.offset)
                    throw Error(ErrorCode::corrupt, concat(tw, ": data at ", t.offset, " (", t.storedBytes,
                                                           " bytes) does not fit in the file"));
                if (t.rawBytes < t.storedBytes)
                    throw Error(ErrorCode::corrupt, concat(tw, ": raw size below stored size"));
                if (t.rawBytes > options.maxTileBytes)
                    throw Error(ErrorCode::limit, concat(tw, ": tile of ", t.rawBytes,
                                                         " bytes exceeds the reader's limit ", options.maxTileBytes));
                if (t.vertexCount == 0 || t.vertexCount > pixels * options.maxVerticesPerPixel)
                    throw Error(ErrorCode::corrupt,
                                concat(tw, ": vertex count ", t.vertexCount, " is invalid for ", pixels, " pixels"));
                if (t.nonEmptyPixels == 0 || t.nonEmptyPixels > pixels)
                    throw Error(ErrorCode::corrupt,
                                concat(tw, ": non-empty pixel count ", t.nonEmptyPixels, " is invalid"));
                if (!std::isfinite(t.minZ) || !std::isfinite(t.maxZ) || t.minZ < 0.0f || t.minZ > t.maxZ)
                    throw Error(ErrorCode::corrupt,
                                concat(tw, ": depth range [", t.minZ, ", ", t.maxZ, "] is invalid"));
            }
            vertices += t.vertexCount;
            nonEmpty += t.nonEmptyPixels;
            stored += t.storedBytes;
            tilesOfLevel[i] = t;
        }
        if (vertices != L.vertexCount || nonEmpty != L.nonEmptyPixels || stored != L.storedBytes)
            throw Error(ErrorCode::corrupt, concat(lw, ": level totals do not match its tile directory"));
        info.levels.push_back(L);
        directories.push_back(std::move(tilesOfLevel));
    }

    std::string metadata(h.metadataSize, '\0');
    readAt(h.metadataOffset, reinterpret_cast<std::uint8_t*>(metadata.data()), metadata.size(), where());
    if (format::crc32(reinterpret_cast<const std::uint8_t*>(metadata.data()), metadata.size()) != h.metadataCrc)
        throw Error(ErrorCode::corrupt, concat(where(), ": metadata CRC-32 mismatch"));
    info.metadata = std::move(metadata);

    cache = options.cache ? options.cache : TileCache::defaultCache();
    fileId = ImplAccess::of(*cache).newFileId();
}

std::shared_ptr<const format::DecodedTile> DeepShadowMap::Impl::getTile(unsigned level, std::uint32_t tx,
                                                                        std::uint32_t ty) const {
    const TileKey key{fileId, level, ty * info.levels[level].tilesX + tx};
    return ImplAccess::of(*cache).get<format::DecodedTile>(
        key, [&] { return namingFile(path, [&] { return loadTile(level, tx, ty); }); });
}

DeepShadowMap::DeepShadowMap() : impl_(std::make_unique<Impl>()) {}
DeepShadowMap::~DeepShadowMap() = default;

std::shared_ptr<DeepShadowMap> DeepShadowMap::open(const std::string& path, const ReaderOptions& options) {
    std::shared_ptr<DeepShadowMap> map(new DeepShadowMap());
    namingFile(path, [&] { map->impl_->openInput(MapInput::file(path), path, options); });
    return map;
}

std::shared_ptr<DeepShadowMap> DeepShadowMap::open(std::shared_ptr<const MapInput> input, const std::string& name,
                                                   const ReaderOptions& options) {
    std::shared_ptr<DeepShadowMap> map(new DeepShadowMap());
    namingFile(name, [&] { map->impl_->openInput(std::move(input), name, options); });
    return map;
}

const MapInfo& DeepShadowMap::info() const { return impl_->info; }
const std::string& DeepShadowMap::path() const { return impl_->path; }
const TileCache& DeepShadowMap::cache() const { return *impl_->cache; }

PixelFunction DeepShadowMap::pixel(unsigned level, std::uint32_t x, std::uint32_t y) const {
    const Impl& s = *impl_;
    if (level >= s.info.levels.size())
        throw Error(ErrorCode::argument,
                    concat(s.where(), ": level ", level, " does not exist (", s.info.levels.size(), " levels)"),
                    s.path);
    const LevelInfo& L = s.info.levels[level];
    if (x >= L.width || y >= L.height)
        throw Error(ErrorCode::argument,
                    concat(s.where(), " level ", level, ": pixel ", x, ",", y, " is outside ", L.width, "x", L.height),
                    s.path);
    const std::uint32_t tx = x / s.info.tileSize, ty = y / s.info.tileSize;
    auto tile = s.getTile(level, tx, ty);
    const std::uint32_t w = s.tileExtent(L.width, tx);
    const VisibilityView view = tile->pixel(std::size_t(y - ty * s.info.tileSize) * w + (x - tx * s.info.tileSize));
    // The aliasing constructor shares ownership of the tile while storing no
    // pointer: the opaque keep-alive handle never points anywhere.
    using TileOwner = ImplAccess::TileOwner<PixelFunction>;
    return ImplAccess::make<PixelFunction>(std::shared_ptr<const TileOwner>(std::move(tile), nullptr), view);
}

TileSummary DeepShadowMap::tile(unsigned level, std::uint32_t tx, std::uint32_t ty) const {
    const Impl& s = *impl_;
    if (level >= s.info.levels.size())
        throw Error(ErrorCode::argument,
                    concat(s.where(), ": level ", level, " does not exist (", s.info.levels.size(), " levels)"),
                    s.path);
    const LevelInfo& L = s.info.levels[level];
    if (tx >= L.tilesX || ty >= L.tilesY)
        throw Error(ErrorCode::argument, concat(s.where(), " level ", level, ": tile ", tx, ",", ty, " is outside ",
                                                L.tilesX, "x", L.tilesY),
                    s.path);
    return s.directories[level][std::size_t(ty) * L.tilesX + tx];
}

void validate(const std::string& path, const ReaderOptions& options) {
    namingFile(path, [&] { validate(MapInput::file(path), path, options); });
}

void validate(std::shared_ptr<const MapInput> input, const std::string& name, const ReaderOptions& options) {
    ReaderOptions uncached = options;
    uncached.cache = TileCache::create(0);
    const auto map = DeepShadowMap::open(std::move(input), name, uncached);
    const auto& s = ImplAccess::of(*map);
    for (unsigned l = 0; l < s.info.levels.size(); ++l)
        for (std::uint32_t ty = 0; ty < s.info.levels[l].tilesY; ++ty)
            for (std::uint32_t tx = 0; tx < s.info.levels[l].tilesX; ++tx)
                namingFile(name, [&] { s.loadTile(l, tx, ty); });
}

DSM_NAMESPACE_END
