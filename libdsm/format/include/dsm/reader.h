// Reading .dsm files: lazy, validating, cached (format: spec/dsm-format.md).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "dsm/map_info.h"
#include "dsm/map_input.h"
#include "dsm/tile_cache.h"
#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// Limits for untrusted files, checked before anything is allocated.
struct ReaderOptions {
    std::uint32_t maxWidth = 1u << 17;
    std::uint32_t maxHeight = 1u << 17;
    std::uint32_t maxVerticesPerPixel = 1u << 24;
    /// Largest decoded tile accepted, in bytes.
    std::uint64_t maxTileBytes = 1ull << 30;
    std::uint64_t maxMetadataBytes = 1ull << 24;
    /// Cache for decoded tiles; null uses TileCache::defaultCache().
    std::shared_ptr<TileCache> cache;
};

class ImplAccess;

/// One pixel's function, kept alive with the tile that holds it: the view stays
/// valid for as long as this object (or a copy) lives, whatever the cache does.
/// Made by DeepShadowMap::pixel(); a default-constructed one views an empty
/// function (V = 1). Copies may be used from any thread.
class DSM_API PixelFunction {
public:
    PixelFunction() = default;
    const VisibilityView& view() const { return view_; }
    const VisibilityView* operator->() const { return &view_; }

private:
    friend class ImplAccess;
    struct TileOwner;  // opaque: the decoded tile that holds the viewed arrays
    PixelFunction(std::shared_ptr<const TileOwner> tile, VisibilityView view) : tile_(std::move(tile)), view_(view) {}
    std::shared_ptr<const TileOwner> tile_;
    VisibilityView view_;
};

/// Per-tile summary from the directory (no tile data is read).
struct TileSummary {
    std::uint64_t offset = 0;
    std::uint32_t storedBytes = 0;
    std::uint32_t rawBytes = 0;
    std::uint32_t crc32 = 0;
    std::uint32_t vertexCount = 0;
    std::uint32_t nonEmptyPixels = 0;
    float minZ = 0.0f;  ///< smallest vertex depth in the tile (0 for an empty tile)
    float maxZ = 0.0f;  ///< largest vertex depth in the tile
    bool empty() const { return storedBytes == 0; }
};

/// An open deep shadow map. open() reads and checks the header, level table,
/// directories and metadata against the file size; tiles are read on demand
/// through the cache. Thread-safe: any number of threads may read pixels at
/// once. Every problem with the file throws dsm::Error naming the file and,
/// where known, level, tile and pixel.
class DSM_API DeepShadowMap {
public:
    static std::shared_ptr<DeepShadowMap> open(const std::string& path, const ReaderOptions& options = {});
    /// Opens a map from memory or the caller's reads (see MapInput); `name` is
    /// what path() returns and messages quote.
    static std::shared_ptr<DeepShadowMap> open(std::shared_ptr<const MapInput> input, const std::string& name,
                                               const ReaderOptions& options = {});
    ~DeepShadowMap();
    DeepShadowMap(const DeepShadowMap&) = delete;
    DeepShadowMap& operator=(const DeepShadowMap&) = delete;

    const MapInfo& info() const;
    const std::string& path() const;
    const TileCache& cache() const;

    /// The function of pixel (x, y) of a level (0 = full resolution). Its
    /// channels are those the file stores for it: libdsm's writer stores a
    /// grey pixel (no vertices, or channels equal at every vertex) as
    /// monochrome, so it reads so; other writers may store it as RGB.
    PixelFunction pixel(unsigned level, std::uint32_t x, std::uint32_t y) const;
    /// Directory entry of tile (tx, ty) of a level.
    TileSummary tile(unsigned level, std::uint32_t tx, std::uint32_t ty) const;

private:
    friend class ImplAccess;
    struct Impl;
    DeepShadowMap();
    std::unique_ptr<Impl> impl_;
};

/// Checks a whole file: the header and every directory (as open() does), then
/// reads every tile of every level without the cache and checks its CRC-32,
/// its layout, every function's invariants (depth order, value range,
/// monotonicity, counts) and the directory's totals. Throws dsm::Error naming
/// the file, level, tile and pixel of the first problem.
DSM_API void validate(const std::string& path, const ReaderOptions& options = {});
/// validate() for a map read through a MapInput; `name` is what messages quote.
DSM_API void validate(std::shared_ptr<const MapInput> input, const std::string& name,
                      const ReaderOptions& options = {});

DSM_NAMESPACE_END
