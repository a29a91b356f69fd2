// Streaming writer of .dsm files (format: spec/dsm-format.md).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "dsm/map_info.h"
#include "dsm/span.h"
#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

struct WriterOptions {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    /// Tile edge in pixels: a power of two from 2 to 4096.
    std::uint32_t tileSize = 32;
    /// 1 or 3. An RGB map may hold monochrome pixels (stored with one channel).
    int channels = 1;
    /// Store per-vertex sample counts. Pixels must then carry counts.
    bool counts = false;
    /// Most layers a pixel may have (1..255); > 1 for an MTSM.
    int maxLayers = 1;
    LightCamera camera;
    PixelFilter filter = PixelFilter::Box;
    double filterWidth = 1.0;
    /// Tolerance epsilon the level-0 functions were compressed with (recorded).
    double tolerance = 0.0;
    /// Mip levels to write, >= 1: 1 = no mip-maps, N = the first N levels
    /// (capped at the full count). Unset (automatic): a full pyramid down to 1 x 1.
    std::optional<unsigned> mipLevels;
    /// Each coarser level is recompressed with the previous tolerance times
    /// this factor (Lokovic & Veach §5.3 halve it: total error <= 2 epsilon).
    double levelToleranceFactor = 0.5;
    /// Compress the coarser levels centred (CompressorOptions::centred), as
    /// the level-0 functions given were.
    bool centredCompression = false;
    /// The tiles' compressor (format 1.1 for zstd): zlib by default; zstd
    /// makes tiles 3-6 % larger and decompresses them several times faster.
    TileCodec codec = TileCodec::Zlib;
    /// zlib level 0..9; 0 stores tiles uncompressed. Recorded in the header
    /// (1.1), so that a tool rewriting the map reproduces the same tiles.
    int zlibLevel = 6;
    /// zstd level 0..22 when codec is zstd (0 stores tiles uncompressed);
    /// recorded in the header as the zlib level is.
    int zstdLevel = 19;
    /// Format minor version written: 1 (coded tiles, value steps, codec and
    /// area light recorded), or 0 for readers of format 1.0 (raw tile arrays).
    std::uint16_t formatMinor = kFormatVersionMinor;
    /// Store every level's values as multiples of valueStep(level tolerance)
    /// (dsm/value_step.h; format 1.1 only). The level-0 functions given must
    /// then have been compressed with compressorTolerance(tolerance), so that
    /// the stated tolerance holds for the values as stored; the writer builds
    /// the coarser levels that way. Off: values are stored as given.
    bool quantiseValues = false;
    /// The area light the map was built for (format 1.1; see MapInfo): a disk
    /// of this radius in the plane z = areaLightPlaneDepth. 0: a point light.
    double areaLightRadius = 0.0;
    double areaLightPlaneDepth = 0.0;
    /// JSON text stored in the file.
    std::string metadata = "{}";
};

/// A level-0 tile made ready for the file by MapWriter::prepareTile(), on
/// any thread, for MapWriter::writePreparedTile() to append. Its storage is
/// kept from one tile to the next: a producer keeps one per tile in flight.
/// Not thread-safe: one thread at a time prepares or writes it.
class DSM_API PreparedTile {
public:
    PreparedTile();
    ~PreparedTile();
    PreparedTile(PreparedTile&&) noexcept;
    PreparedTile& operator=(PreparedTile&&) noexcept;
    PreparedTile(const PreparedTile&) = delete;
    PreparedTile& operator=(const PreparedTile&) = delete;

private:
    friend class MapWriter;
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Writes a map tile by tile. Level-0 tiles may come in any order; each is
/// written to disk as soon as it arrives, and coarser levels are built from
/// each 2 x 2 block of tiles as soon as the block is complete (exact averaging
/// by the sweep, then recompression). Memory holds only the partly built
/// coarser tiles: about half a row of level-0 tiles in row order.
///
/// Output goes through an OutputFile (dsm/output_file.h): a temporary file
/// beside `path`, synced and renamed to `path` by finish(). If finish() is not
/// reached (an error, an exception, a crash) no file named `path` is created
/// or replaced; the destructor removes the temporary file.
///
/// Thread safety: prepareTile() may run on any number of threads at once,
/// also while another calls the other members; those must not overlap
/// (writeTile() and writePreparedTile() build the coarser levels and append
/// to the file). A producer that computes tiles on several threads prepares
/// each on its own thread and hands them to the writer one at a time, in any
/// order. Separate writers (to different paths) are independent.
///
/// Failure: every error throws dsm::Error naming the file, tile and pixel as
/// known; after a failure of writeTile() or finish() the writer is unusable,
/// and its destructor removes the temporary file.
class DSM_API MapWriter {
public:
    /// Opens the temporary file. Throws dsm::Error for bad options or I/O.
    MapWriter(const std::string& path, const WriterOptions& options);
    ~MapWriter();
    MapWriter(const MapWriter&) = delete;
    MapWriter& operator=(const MapWriter&) = delete;

    /// Tiles across and down at level 0.
    std::uint32_t tilesX() const;
    std::uint32_t tilesY() const;
    /// Pixel size of level-0 tile (tx, ty), clipped at the image edge.
    std::uint32_t tileWidth(std::uint32_t tx) const;
    std::uint32_t tileHeight(std::uint32_t ty) const;

    /// Level-0 tile (tx, ty): tileWidth(tx) * tileHeight(ty) functions in row
    /// order. Each is validated; channels, counts and layers must fit the
    /// options. Throws dsm::Error naming tile and pixel.
    void writeTile(std::uint32_t tx, std::uint32_t ty, Span<const VisibilityFunction> pixels);

    /// The part of writeTile() that needs neither the file nor other tiles:
    /// checks the pixels as writeTile() does, rounds their values to the
    /// level's step in place (so they become the tile as stored; writeTile()
    /// rounds a copy), encodes and compresses the tile, and averages the
    /// level-1 pixels it covers, into `out`. Thread-safe (see above), each
    /// thread with its own pixels and `out`; not once finish() has begun.
    /// Throws dsm::Error as writeTile() does, and `out` is then not ready to
    /// write; the pixels are rounded only once every one has passed its checks.
    void prepareTile(std::uint32_t tx, std::uint32_t ty, Span<VisibilityFunction> pixels, PreparedTile& out) const;
    /// Appends a tile prepareTile() made ready, and builds what it completes
    /// of the coarser levels: the file is byte for byte the one writeTile()
    /// with the same pixels gives. Throws dsm::Error when `tile` is not ready
    /// (never prepared, its preparation failed, or written already) or its
    /// tile was written before.
    void writePreparedTile(PreparedTile& tile);

    /// Completes the pyramid, writes directories and metadata, and renames the
    /// file into place. Throws dsm::Error naming the first missing tile.
    void finish();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
