// The inside of DeepShadowMap, shared by the reader and the lookups (internal).
#pragma once

#include <algorithm>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include "dsm/error.h"
#include "dsm/map_input.h"
#include "dsm/reader.h"
#include "impl_access.h"
#include "text.h"
#include "tile_cache_impl.h"
#include "tile_codec.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

struct DeepShadowMap::Impl {
    std::string path;
    std::shared_ptr<const MapInput> input;
    ReaderOptions options;
    MapInfo info;
    std::vector<std::vector<TileSummary>> directories;
    std::shared_ptr<TileCache> cache;
    std::uint64_t fileId = 0;

    ~Impl() {
        if (cache && fileId) ImplAccess::of(*cache).forgetFile(fileId);
    }

    std::string where() const { return concat("'", path, "'"); }
    std::string tileWhere(unsigned level, std::uint32_t tx, std::uint32_t ty) const {
        return concat(where(), " level ", level, " tile ", tx, ",", ty);
    }

    void readAt(std::uint64_t offset, std::uint8_t* out, std::size_t size, const std::string& what) const {
        std::size_t done = 0;
        while (done < size) {
            std::size_t n = 0;
            try {
                n = input->read(offset + done, out + done, size - done);
            } catch (const std::exception& e) {
                throw Error(ErrorCode::io, concat(what, ": read failed: ", e.what()));
            }
            if (n == 0) throw Error(ErrorCode::corrupt, concat(what, ": unexpected end of file"));
            done += std::min(n, size - done);
        }
    }

    format::TileLayout layout(unsigned level) const {
        return {info.channels,   info.hasCounts,
                info.maxLayers,  info.codedTiles,
                info.levels[level].valueStep, info.codec,
                info.predictedDepths};
    }

    std::uint32_t tileExtent(std::uint32_t levelExtent, std::uint32_t t) const {
        return std::min(info.tileSize, levelExtent - t * info.tileSize);
    }

    // Reads and decodes one tile (no cache).
    LoadedTile loadTile(unsigned level, std::uint32_t tx, std::uint32_t ty) const {
        const LevelInfo& L = info.levels[level];
        const TileSummary& t = directories[level][std::size_t(ty) * L.tilesX + tx];
        const std::string where = tileWhere(level, tx, ty);
        std::vector<std::uint8_t> stored(t.storedBytes);
        if (!t.empty()) readAt(t.offset, stored.data(), stored.size(), where);
        auto tile = std::make_shared<format::DecodedTile>(
            format::decodeTile(stored, t, tileExtent(L.width, tx), tileExtent(L.height, ty), layout(level), options, where,
                               tx * info.tileSize, ty * info.tileSize));
        LoadedTile loaded;
        loaded.memoryBytes = tile->memoryBytes();
        loaded.fileBytes = t.storedBytes;
        loaded.data = std::move(tile);
        return loaded;
    }

    /// Reads and checks everything but the tiles; `name` is what messages call the map.
    void openInput(std::shared_ptr<const MapInput> in, const std::string& name, const ReaderOptions& o);
    /// Tile (tx, ty) of a level through the cache.
    std::shared_ptr<const format::DecodedTile> getTile(unsigned level, std::uint32_t tx, std::uint32_t ty) const;
};

DSM_NAMESPACE_END
