// The deep EXR part being imported (spec/exr-interop.md section 4).
#include "deep_exr_source.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

#include <ImfCompression.h>
#include <ImfPartType.h>
#include <ImfTestFile.h>

#include <sys/stat.h>

#include "dsm/error.h"
#include "exr_common.h"
#include "exr_header_check.h"

DSM_NAMESPACE_BEGIN
namespace exr {

using detail::concat;

namespace {

/// Moves the rows of `from` within [y0, y1) into the same rows of `to`.
void moveRows(Band& from, int y0, int y1, Band& to) {
    const int first = std::max({y0, from.y0, to.y0}), last = std::min({y1, from.y0 + from.rows, to.y0 + to.rows});
    const std::size_t w = std::size_t(to.width);
    for (int y = first; y < last; ++y) {
        const std::size_t a = std::size_t(y - from.y0) * w, b = std::size_t(y - to.y0) * w;
        for (std::size_t x = 0; x < w; ++x) {
            to.counts[b + x] = from.counts[a + x];
            to.samples[b + x] = std::move(from.samples[a + x]);
            if (!to.vertices.empty()) to.vertices[b + x] = std::move(from.vertices[a + x]);
        }
    }
}

}  // namespace

DeepExrSource::DeepExrSource(const std::string& path, const ExrImportOptions& options) : path_(path) {
    // stat, not open: opening a FIFO would wait for a writer forever.
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0)
        throw Error(ErrorCode::io, concat(quoted(path), ": cannot open: ", std::strerror(errno)));
    if (!S_ISREG(st.st_mode)) throw Error(ErrorCode::io, concat(quoted(path), ": not a regular file"));
    checkExrHeaderSizes(path, static_cast<std::uint64_t>(st.st_size));
    fileBytes_ = static_cast<std::uint64_t>(st.st_size);
    limitOpenExrAllocations();
    bool tiled = false, deep = false, multiPart = false;
    if (!Imf::isOpenExrFile(path.c_str(), tiled, deep, multiPart))
        throw Error(ErrorCode::format, concat(quoted(path), ": not an OpenEXR file"));
    file_ = std::make_unique<Imf::MultiPartInputFile>(path.c_str());
    try {
        part_ = selectDeepPart(*file_, options.part, options.view);
    } catch (const Error& e) {
        throw Error(e.code(), concat(quoted(path), ": ", e.what()));
    }
    rawFile_ = std::make_unique<Imf::MultiPartInputFile>(path.c_str());
    const std::string type = file_->header(part_.index).type();
    if (type == Imf::DEEPTILE) {
        tiledFile_ = std::make_unique<Imf::DeepTiledInputPart>(*file_, part_.index);
        rawTiledFile_ = std::make_unique<Imf::DeepTiledInputPart>(*rawFile_, part_.index);
    } else {
        scanFile_ = std::make_unique<Imf::DeepScanLineInputPart>(*file_, part_.index);
        rawScanFile_ = std::make_unique<Imf::DeepScanLineInputPart>(*rawFile_, part_.index);
    }
    const std::string where = file_->parts() > 1 ? concat(quoted(path), ": ", part_.description) : quoted(path);
    try {
        channels_ = resolveChannels(header().channels(), options.channels);
    } catch (const Error& e) {
        throw Error(e.code(), concat(where, ": ", e.what()));
    }
    data_ = header().dataWindow();
    display_ = header().displayWindow();
    const long long dw = (long long)display_.max.x - display_.min.x + 1;
    const long long dh = (long long)display_.max.y - display_.min.y + 1;
    if (dw < 1 || dh < 1 || dw > kMaxExrExtent || dh > kMaxExrExtent)
        throw Error(ErrorCode::limit,
                    concat(where, ": display window ", dw, " x ", dh, " is outside 1..", kMaxExrExtent));
    const long long ww = (long long)data_.max.x - data_.min.x + 1;
    if (ww > kMaxExrExtent) throw Error(ErrorCode::limit, concat(where, ": data window is wider than ", kMaxExrExtent));
    decodedEnd_ = data_.min.y;
    pending_.reset(data_.min.x, data_.min.y, 0, 0, false);
}

const Imf::Header& DeepExrSource::header() const { return tiledFile_ ? tiledFile_->header() : scanFile_->header(); }

int DeepExrSource::chunkRows() const {
    if (tiledFile_) return int(tiledFile_->header().tileDescription().ySize);
    // Deep scanline images allow no compression, RLE, ZIPS (one row a chunk) and ZIP (16 rows).
    return header().compression() == Imf::ZIP_COMPRESSION ? 16 : 1;
}

std::uint64_t DeepExrSource::chunkCount() const {
    const std::uint64_t rows = std::uint64_t(std::int64_t(data_.max.y) - data_.min.y + 1);
    const std::uint64_t bands = (rows + std::uint64_t(chunkRows()) - 1) / std::uint64_t(chunkRows());
    return tiledFile_ ? bands * std::uint64_t(tiledFile_->numXTiles(0)) : bands;
}

/// The same for the tiles of rows [ty0, ty1] of level 0: a raw tile holds
/// its coordinates (16 bytes), then the three sizes.
void DeepExrSource::checkTiles(int nx, int ty0, int ty1) {
    std::vector<char> raw;
    for (int ty = ty0; ty <= ty1; ++ty)
        for (int tx = 0; tx < nx; ++tx) {
            int dx = tx, dy = ty, lx = 0, ly = 0;
            std::uint64_t bytes = 0;
            rawTiledFile_->rawTileData(dx, dy, lx, ly, nullptr, bytes);
            if (bytes < 40 || bytes > fileBytes_)
                throw Error(ErrorCode::corrupt, concat(quoted(path_), ": tile ", tx, ",", ty, " records ", bytes,
                                                       " bytes, more than the file has"));
            raw.resize(std::size_t(bytes));
            dx = tx, dy = ty, lx = 0, ly = 0;
            rawTiledFile_->rawTileData(dx, dy, lx, ly, raw.data(), bytes);
            checkUnpackedSize(raw.data() + 24, "tile " + std::to_string(tx) + "," + std::to_string(ty));
        }
}

/// A packed and an unpacked size, as OpenEXR writes them: the second must
/// be one zlib could produce from the first (at most 1032:1, plus a little).
void DeepExrSource::checkUnpackedSize(const char* sizes, const std::string& what) const {
    std::uint64_t packed = 0, unpacked = 0;
    std::memcpy(&packed, sizes, 8);  // little-endian, as OpenEXR files and this machine are
    std::memcpy(&unpacked, sizes + 8, 8);
    if (unpacked > packed * 1032 + 4096)
        throw Error(ErrorCode::corrupt, concat(quoted(path_), ": ", what, " records ", unpacked,
                                               " unpacked bytes from ", packed, " packed bytes"));
}

/// OpenEXR allocates a chunk's unpacked size as the file records it, before
/// it decompresses anything: a few damaged bytes could ask for gigabytes.
/// Each chunk of rows [y0, y1) is read raw first (its size checked against
/// the file), and its unpacked size must be one zlib could produce from its
/// packed bytes (at most 1032:1, plus a little).
void DeepExrSource::checkScanlineChunks(int y0, int y1) {
    const int linesPerChunk = chunkRows();
    std::vector<char> raw;
    const int first = data_.min.y + (y0 - data_.min.y) / linesPerChunk * linesPerChunk;
    for (int y = first; y < y1; y += linesPerChunk) {
        std::uint64_t bytes = 0;
        rawScanFile_->rawPixelData(y, nullptr, bytes);
        if (bytes < 28 || bytes > fileBytes_)
            throw Error(ErrorCode::corrupt, concat(quoted(path_), ": the chunk of row ", y, " records ", bytes,
                                                   " bytes, more than the file has"));
        raw.resize(std::size_t(bytes));
        rawScanFile_->rawPixelData(y, raw.data(), bytes);
        checkUnpackedSize(raw.data() + 12, "the chunk of row " + std::to_string(y));
    }
}


void DeepExrSource::checkSamples(const Band& band) const {
    std::uint64_t total = 0;
    for (std::size_t i = 0; i < band.counts.size(); ++i) {
        if (band.counts[i] > kMaxSamplesPerPixel)
            throw Error(ErrorCode::corrupt,
                        concat(quoted(path_), " pixel ", band.x0 + int(i % std::size_t(band.width)), ",",
                               band.y0 + int(i / std::size_t(band.width)), ": ", band.counts[i],
                               " samples (more than ", kMaxSamplesPerPixel, ")"));
        total += band.counts[i];
    }
    if (total > kMaxSamplesPerBand)
        throw Error(ErrorCode::corrupt,
                    concat(quoted(path_), ": rows ", band.y0, "..", band.y0 + band.rows - 1, " hold ", total,
                           " samples (more than ", kMaxSamplesPerBand, " at once)"));
}

void DeepExrSource::decode(int y0, int y1, Band& band) {
    const int width = data_.max.x - data_.min.x + 1;
    band.reset(data_.min.x, y0, width, y1 - y0, withVertices());
    if (scanFile_) {
        scanFile_->setFrameBuffer(band.frameBuffer(channels_.names));
        scanFile_->readPixelSampleCounts(y0, y1 - 1);
        checkSamples(band);
        band.sizeToCounts();
        checkScanlineChunks(y0, y1);
        scanFile_->readPixels(y0, y1 - 1);
        decodes_ += std::uint64_t((y1 - y0 + chunkRows() - 1) / chunkRows());
    } else {
        const int rows = chunkRows();
        const int ty0 = (y0 - data_.min.y) / rows, ty1 = (y1 - 1 - data_.min.y) / rows;
        const int nx = tiledFile_->numXTiles(0);
        tiledFile_->setFrameBuffer(band.frameBuffer(channels_.names));
        tiledFile_->readPixelSampleCounts(0, nx - 1, ty0, ty1, 0, 0);
        checkSamples(band);
        band.sizeToCounts();
        checkTiles(nx, ty0, ty1);
        tiledFile_->readTiles(0, nx - 1, ty0, ty1, 0, 0);
        decodes_ += std::uint64_t(nx) * std::uint64_t(ty1 - ty0 + 1);
    }
    const bool hasZBack = !channels_.names.zBack.empty();
    for (auto& pixel : band.samples)
        for (DeepSample& s : pixel) {
            if (!hasZBack) s.zBack = s.z;
            if (!channels_.rgb) s.alphaRGB = {s.alpha, s.alpha, s.alpha};
        }
}

void DeepExrSource::read(int y0, int y1, Band& band) {
    y0 = std::max(y0, data_.min.y), y1 = std::min(y1, data_.max.y + 1);
    const int width = data_.max.x - data_.min.x + 1;
    if (y1 <= y0 || width <= 0) {
        band.reset(data_.min.x, y0, 0, 0, false);
        return;
    }
    // Decode whole chunks up to the one holding row y1 - 1, from the first not
    // yet decoded (rows skipped by the caller are never decoded).
    const int rows = chunkRows();
    const auto chunkStart = [&](int y) { return data_.min.y + (y - data_.min.y) / rows * rows; };
    Band fresh;
    fresh.reset(data_.min.x, y0, width, 0, false);
    if (decodedEnd_ < y1) {
        const int from = std::max(decodedEnd_, chunkStart(y0));
        const int to = std::min(data_.max.y + 1, chunkStart(y1 - 1) + rows);
        decode(from, to, fresh);
        decodedEnd_ = to;
    }
    // Rows [y0, y1) go out; rows [y1, decodedEnd_) wait for the next call.
    band.reset(data_.min.x, y0, width, y1 - y0, withVertices());
    moveRows(pending_, y0, y1, band);
    moveRows(fresh, y0, y1, band);
    Band rest;
    rest.reset(data_.min.x, y1, width, std::max(0, decodedEnd_ - y1), withVertices());
    moveRows(pending_, y1, decodedEnd_, rest);
    moveRows(fresh, y1, decodedEnd_, rest);
    pending_ = std::move(rest);
}

}  // namespace exr
DSM_NAMESPACE_END
