// The inside of DeepShadowMap, shared by the reader and the lookups (internal).
#pragma once

#include <cerrno>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <unistd.h>

#include "dsm/error.h"
#include "dsm/reader.h"
#include "impl_access.h"
#include "text.h"
#include "tile_cache_impl.h"
#include "tile_codec.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

struct DeepShadowMap::Impl {
    std::string path;
    int fd = -1;
    ReaderOptions options;
    MapInfo info;
    std::vector<std::vector<TileSummary>> directories;
    std::shared_ptr<TileCache> cache;
    std::uint64_t fileId = 0;

    ~Impl() {
        if (cache && fileId) ImplAccess::of(*cache).forgetFile(fileId);
        if (fd >= 0) ::close(fd);
    }

    std::string where() const { return concat("'", path, "'"); }
    std::string tileWhere(unsigned level, std::uint32_t tx, std::uint32_t ty) const {
        return concat(where(), " level ", level, " tile ", tx, ",", ty);
    }

    void readAt(std::uint64_t offset, std::uint8_t* out, std::size_t size, const std::string& what) const {
        std::size_t done = 0;
        while (done < size) {
            const ssize_t n = ::pread(fd, out + done, size - done, static_cast<off_t>(offset + done));
            if (n < 0 && errno == EINTR) continue;
            if (n < 0) throw Error(concat(what, ": read failed: ", std::strerror(errno)));
            if (n == 0) throw Error(concat(what, ": unexpected end of file"));
            done += static_cast<std::size_t>(n);
        }
    }

    format::TileLayout layout() const { return {info.channels, info.hasCounts, info.maxLayers}; }

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
            format::decodeTile(stored, t, tileExtent(L.width, tx), tileExtent(L.height, ty), layout(), options, where,
                               tx * info.tileSize, ty * info.tileSize));
        LoadedTile loaded;
        loaded.memoryBytes = tile->memoryBytes();
        loaded.fileBytes = t.storedBytes;
        loaded.data = std::move(tile);
        return loaded;
    }

    void openFile(const std::string& p, const ReaderOptions& o);
    /// Tile (tx, ty) of a level through the cache.
    std::shared_ptr<const format::DecodedTile> getTile(unsigned level, std::uint32_t tx, std::uint32_t ty) const;
};

DSM_NAMESPACE_END
