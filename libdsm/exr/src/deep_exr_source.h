// The deep EXR part being imported: opened and checked, its channels chosen,
// and its pixels handed out in bands of rows, each chunk decoded once
// (internal).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <ImathBox.h>
#include <ImfDeepScanLineInputPart.h>
#include <ImfDeepTiledInputPart.h>
#include <ImfHeader.h>
#include <ImfMultiPartInputFile.h>

#include "channel_mapping.h"
#include "deep_band.h"
#include "part_selection.h"

DSM_NAMESPACE_BEGIN
namespace exr {

class DeepExrSource {
public:
    /// Opens `path` and selects the part and channels `options` ask for.
    /// Throws dsm::Error naming the file.
    DeepExrSource(const std::string& path, const ExrImportOptions& options);

    const Imf::Header& header() const;
    const SelectedPart& part() const { return part_; }
    const ResolvedChannels& channels() const { return channels_; }
    bool rgb() const { return channels_.rgb; }
    /// The part carries vertex samples (vertex_samples.h).
    bool withVertices() const { return channels_.names.withVertices(); }
    const Imath::Box2i& display() const { return display_; }
    const Imath::Box2i& data() const { return data_; }
    bool tiled() const { return tiledFile_ != nullptr; }

    /// File rows [y0, y1) of the data window (clipped), all its columns, into
    /// `band`. Calls must ask for rows in increasing order without gaps
    /// (starting anywhere): every chunk (scanline block or tile) is decoded
    /// once, and the rows it holds beyond y1 wait for the next call.
    void read(int y0, int y1, Band& band);

    /// Chunks (scanline blocks or tiles) of the data window, and how many
    /// decodes read() has made so far.
    std::uint64_t chunkCount() const;
    std::uint64_t decodes() const { return decodes_; }

private:
    int chunkRows() const;
    /// Decodes the chunks of rows [y0, y1) (chunk-aligned) into `band`.
    void decode(int y0, int y1, Band& band);
    void checkSamples(const Band& band) const;
    void checkUnpackedSize(const char* sizes, const std::string& what) const;
    void checkScanlineChunks(int y0, int y1);
    void checkTiles(int nx, int ty0, int ty1);

    std::string path_;
    std::unique_ptr<Imf::MultiPartInputFile> file_;
    /// A second reader of the same file for raw chunk checks: OpenEXR's
    /// scanline reader expects the stream where its last read left it.
    std::unique_ptr<Imf::MultiPartInputFile> rawFile_;
    std::unique_ptr<Imf::DeepScanLineInputPart> scanFile_, rawScanFile_;
    std::unique_ptr<Imf::DeepTiledInputPart> tiledFile_, rawTiledFile_;
    std::uint64_t fileBytes_ = 0;
    SelectedPart part_;
    ResolvedChannels channels_;
    Imath::Box2i data_, display_;
    /// Decoded rows not yet handed out: [pending_.y0, pending_.y0 + pending_.rows).
    Band pending_;
    int decodedEnd_ = 0;
    std::uint64_t decodes_ = 0;
};

}  // namespace exr
DSM_NAMESPACE_END
