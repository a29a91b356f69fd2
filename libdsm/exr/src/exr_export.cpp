// Export of a map level as a deep EXR (spec/exr-interop.md section 3).
#include <algorithm>
#include <cmath>

#include <ImathBox.h>
#include <ImathMatrix.h>
#include <ImathVec.h>
#include <ImfChannelList.h>
#include <ImfDeepImageStateAttribute.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfDeepTiledOutputFile.h>
#include <ImfDoubleAttribute.h>
#include <ImfHeader.h>
#include <ImfIntAttribute.h>
#include <ImfMatrixAttribute.h>
#include <ImfMultiPartInputFile.h>
#include <ImfPartType.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <ImfVecAttribute.h>
#include <tbb/parallel_for.h>

#include "deep_band.h"
#include "deep_samples.h"
#include "dsm/error.h"
#include "dsm/exr_deep.h"
#include "dsm/names.h"
#include "dsm/output_file.h"
#include "dsm/reader.h"
#include "exr_common.h"
#include "kept_attributes.h"
#include "naming_file.h"
#include "vertex_samples.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using exr::quoted;

namespace {

/// Re-reads the offset tables of the EXR OpenEXR just wrote: every chunk must
/// be there before the file may replace the target.
void verifyWrittenExr(const OutputFile& file) {
    bool complete = false;
    try {
        Imf::MultiPartInputFile written(file.temporaryPath().c_str());
        complete = written.parts() == 1 && written.partComplete(0);
    } catch (const std::exception& e) {
        throw Error(ErrorCode::io, concat(quoted(file.path()), ": the written image does not read back: ",
                                          exr::openExrMessage(file.temporaryPath(), e.what())));
    }
    if (!complete) throw Error(ErrorCode::io, concat(quoted(file.path()), ": the written image is incomplete"));
}

/// The display and data windows of the image: the map's size at the origin,
/// or, for level 0 of an imported map of the same size, the source's windows,
/// the data window grown to every pixel of the map that is not empty.
void imageWindows(const DeepShadowMap& map, unsigned level, const exr::KeptAttributes& kept, Imath::Box2i& display,
                  Imath::Box2i& data) {
    const LevelInfo& info = map.info().levels[level];
    const int width = int(info.width), height = int(info.height);
    display = data = Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(width - 1, height - 1));
    if (level != 0 || !kept.displayWindow || !kept.dataWindow) return;
    const Imath::Box2i source = *kept.displayWindow;
    if (std::int64_t(source.max.x) - source.min.x + 1 != width || std::int64_t(source.max.y) - source.min.y + 1 != height)
        return;
    // A data window no image of ours could have (edited metadata) is not given back.
    const Imath::Box2i keptData = *kept.dataWindow;
    if (std::int64_t(keptData.max.x) - keptData.min.x >= std::int64_t(exr::kMaxExrExtent) ||
        std::int64_t(keptData.max.y) - keptData.min.y >= std::int64_t(exr::kMaxExrExtent))
        return;
    display = source;
    Imath::Box2i grown = keptData;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const Imath::V2i at(display.min.x + x, display.min.y + y);
            if (!grown.intersects(at) && !map.pixel(level, std::uint32_t(x), std::uint32_t(y))->empty())
                grown.extendBy(at);
        }
    data = grown;
}

}  // namespace

// Both entry points attach to their errors the file each one names (the map or
// the image), whichever step below raised it.
ExrExportReport exportDeepExr(const std::string& dsmPath, const std::string& exrPath,
                              const ExrExportOptions& options) try {
    exr::checkErrorBoundOption(options.maxDeviation, "deep EXR export: the largest deviation");
    checkOutputPath(exrPath);
    refuseOutputOverInputs(exrPath, {dsmPath});
    const auto map = DeepShadowMap::open(dsmPath);
    const MapInfo& info = map->info();
    if (options.level >= info.levels.size())
        throw Error(ErrorCode::argument, concat(quoted(dsmPath), ": level ", options.level,
                                                " does not exist (the map has ", info.levels.size(), " levels)"));
    const LevelInfo& level = info.levels[options.level];
    ExrExportReport report;
    report.width = level.width;
    report.height = level.height;
    report.channels = info.channels;
    report.maxDeviation = options.maxDeviation.value_or(std::clamp(level.tolerance / 2.0, 1e-5, 1e-3));
    if (!std::isfinite(report.maxDeviation))
        throw Error(ErrorCode::argument,
                    concat("deep EXR export: the largest deviation must be finite, got ", report.maxDeviation));
    if (options.tiled && (options.tileSize < 1 || options.tileSize > 65536))
        throw Error(ErrorCode::argument,
                    concat("deep EXR export: tile size ", options.tileSize, " is outside 1..65536"));
    const bool mono = info.channels == 1;
    report.vertexSamples = info.hasCounts || info.maxLayers > 1;

    const exr::KeptAttributes kept = exr::keptAttributes(info.metadata);
    Imath::Box2i display, data;
    imageWindows(*map, options.level, kept, display, data);
    const LightCamera& cam = info.camera;
    const double dx = cam.screenWindow[1] - cam.screenWindow[0], dy = cam.screenWindow[3] - cam.screenWindow[2];
    const int width = int(level.width), height = int(level.height);
    Imf::Header header(display, data, float((dx / width) / (dy / height)),
                       Imath::V2f(float((cam.screenWindow[0] + cam.screenWindow[1]) / 2),
                                  float((cam.screenWindow[2] + cam.screenWindow[3]) / 2)),
                       float(dx), Imf::INCREASING_Y, Imf::ZIPS_COMPRESSION);
    for (const auto& [name, value] : kept.strings) header.insert(name, Imf::StringAttribute(value));
    exr::BandChannels names;
    if (!mono) names.alphaRGB = {"AR", "AG", "AB"}, names.colour = {"R", "G", "B"};
    if (report.vertexSamples) {
        names.layer = exr::kLayerChannel;
        names.count = exr::kCountChannel;
        names.value = exr::vertexValueChannels(info.channels);
    }
    for (const std::string* name : {&names.z, &names.zBack, &names.alpha, &names.alphaRGB[0], &names.alphaRGB[1],
                                    &names.alphaRGB[2], &names.colour[0], &names.colour[1], &names.colour[2]})
        if (!name->empty()) header.channels().insert(*name, Imf::Channel(Imf::FLOAT));
    if (report.vertexSamples) {
        header.channels().insert(names.layer, Imf::Channel(Imf::UINT));
        header.channels().insert(names.count, Imf::Channel(Imf::UINT));
        for (const std::string& name : names.value) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    }
    const StandardCameraMatrices standard = standardCameraMatrices(cam);
    Imath::M44f toCamera, toNDC;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            toCamera[i][j] = standard.worldToCamera[std::size_t(i)][std::size_t(j)],
            toNDC[i][j] = standard.worldToNDC[std::size_t(i)][std::size_t(j)];
    Imf::addWorldToCamera(header, toCamera);
    Imf::addWorldToNDC(header, toNDC);
    // Vertex samples overlap the others: the image is then no longer tidy.
    Imf::addDeepImageState(header, report.vertexSamples ? Imf::DIS_MESSY : Imf::DIS_TIDY);
    Imath::M44d worldToLight;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) worldToLight[i][j] = cam.worldToLight[std::size_t(4 * j + i)];  // row-vector form
    header.insert("dsm:worldToLight", Imf::M44dAttribute(worldToLight));
    header.insert("dsm:projection", Imf::StringAttribute(projectionName(cam.projection)));
    header.insert("dsm:screenWindowMin", Imf::V2dAttribute(Imath::V2d(cam.screenWindow[0], cam.screenWindow[2])));
    header.insert("dsm:screenWindowMax", Imf::V2dAttribute(Imath::V2d(cam.screenWindow[1], cam.screenWindow[3])));
    header.insert("dsm:nearPlane", Imf::DoubleAttribute(cam.nearPlane));
    header.insert("dsm:level", Imf::IntAttribute(int(options.level)));
    header.insert("dsm:tolerance", Imf::DoubleAttribute(level.tolerance));
    header.insert("dsm:errorBound", Imf::DoubleAttribute(level.errorBound));
    header.insert("dsm:maxDeviation", Imf::DoubleAttribute(report.maxDeviation));
    header.insert("dsm:filter", Imf::StringAttribute(filterName(info.filter)));
    header.insert("dsm:filterWidth", Imf::DoubleAttribute(info.filterWidth));
    header.insert("dsm:metadata", Imf::StringAttribute(info.metadata));
    if (report.vertexSamples) {
        header.insert("dsm:counts", Imf::IntAttribute(info.hasCounts ? 1 : 0));
        header.insert("dsm:maxLayers", Imf::IntAttribute(info.maxLayers));
    }

    OutputFile output(exrPath);
    const int dataWidth = data.max.x - data.min.x + 1;
    std::vector<double> largest(std::size_t(data.max.y - data.min.y + 1), 0.0);
    std::vector<std::uint64_t> oneStep(largest.size(), 0);
    auto fill = [&](exr::Band& band) {
        tbb::parallel_for(0, band.rows, [&](int r) {
            const int fileY = band.y0 + r, y = fileY - display.min.y;
            const std::size_t row = std::size_t(fileY - data.min.y);
            for (int c = 0; c < band.width; ++c) {
                const int x = band.x0 + c - display.min.x;
                if (x < 0 || y < 0 || x >= width || y >= height) continue;  // data outside the display window
                const std::size_t i = std::size_t(r) * std::size_t(band.width) + std::size_t(c);
                double worst = 0.0;
                std::uint64_t excess = 0;
                try {
                    const PixelFunction f = map->pixel(options.level, std::uint32_t(x), std::uint32_t(y));
                    band.samples[i] = exr::samplesWithDeviation(f.view(), report.maxDeviation, worst, excess);
                    if (report.vertexSamples)
                        exr::appendVertexSamples(f.view(), info.channels, band.samples[i], band.vertices[i]);
                } catch (const Error& e) {
                    throw Error(e.code(), concat(quoted(dsmPath), " level ", options.level, " pixel ", x, ",", y,
                                                 ": ", e.what()));
                }
                band.counts[i] = unsigned(band.samples[i].size());
                largest[row] = std::max(largest[row], worst);
                oneStep[row] += excess;
            }
        });
        band.point();
        for (std::size_t i = 0; i < band.samples.size(); ++i)
            for (std::size_t k = 0; k < band.samples[i].size(); ++k) {
                const DeepSample& s = band.samples[i][k];
                if (!band.vertices.empty() && band.vertices[i][k].layer != 0) ++report.vertices;
                else ++(s.zBack > s.z ? report.volumeSamples : report.pointSamples);
            }
    };
    try {
        exr::Band band;
        if (options.tiled) {
            const int tile = int(options.tileSize);
            header.setTileDescription(Imf::TileDescription(unsigned(tile), unsigned(tile), Imf::ONE_LEVEL));
            header.setType(Imf::DEEPTILE);
            Imf::DeepTiledOutputFile out(output.temporaryPath().c_str(), header);
            for (int ty = 0; ty < out.numYTiles(0); ++ty) {
                const int top = data.min.y + ty * tile;
                band.reset(data.min.x, top, dataWidth, std::min(tile, data.max.y + 1 - top), report.vertexSamples);
                fill(band);
                out.setFrameBuffer(band.frameBuffer(names));
                out.writeTiles(0, out.numXTiles(0) - 1, ty, ty);
            }
        } else {
            header.setType(Imf::DEEPSCANLINE);
            Imf::DeepScanLineOutputFile out(output.temporaryPath().c_str(), header);
            constexpr int kRows = 16;
            for (int y = data.min.y; y <= data.max.y; y += kRows) {
                band.reset(data.min.x, y, dataWidth, std::min(kRows, data.max.y + 1 - y), report.vertexSamples);
                fill(band);
                out.setFrameBuffer(band.frameBuffer(names));
                out.writePixels(band.rows);
            }
        }
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        // OpenEXR names the temporary file it was writing: the output is named once, in front.
        throw Error(ErrorCode::io, concat(quoted(exrPath), ": ", exr::openExrMessage(output.temporaryPath(), e.what())));
    }
    verifyWrittenExr(output);
    output.commit();
    for (double v : largest) report.largestDeviation = std::max(report.largestDeviation, v);
    for (std::uint64_t n : oneStep) report.oneStepExcess += n;
    return report;
} catch (const Error& e) {
    throw detail::withOneOf(e, {dsmPath, exrPath});
}

DSM_NAMESPACE_END
