// Import of a deep EXR part as a map (spec/exr-interop.md section 4).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <utility>

#include <ImfDoubleAttribute.h>
#include <ImfIntAttribute.h>
#include <ImfStringAttribute.h>
#include <tbb/parallel_for.h>

#include "deep_exr_source.h"
#include "dsm/compressor.h"
#include "dsm/error.h"
#include "dsm/exr_deep.h"
#include "dsm/names.h"
#include "dsm/output_file.h"
#include "dsm/writer.h"
#include "exr_camera.h"
#include "exr_common.h"
#include "kept_attributes.h"
#include "naming_file.h"
#include "vertex_samples.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using exr::findAttribute;
using exr::quoted;

namespace {

/// Most rows of the data window outside the display window read at once,
/// only to count their samples.
constexpr int kCountingRows = 64;

/// Samples at the same depths (Z and ZBack) as an earlier sample of the pixel.
std::uint64_t coincidentSamples(std::span<const DeepSample> samples) {
    if (samples.size() < 2) return 0;
    if (samples.size() == 2)
        return samples[0].z == samples[1].z && samples[0].zBack == samples[1].zBack ? 1 : 0;
    thread_local std::vector<std::pair<float, float>> keys;
    keys.clear();
    for (const DeepSample& s : samples) keys.emplace_back(s.z, s.zBack);
    std::sort(keys.begin(), keys.end());
    std::uint64_t n = 0;
    for (std::size_t i = 1; i < keys.size(); ++i) n += keys[i] == keys[i - 1] ? 1 : 0;
    return n;
}

/// A double attribute that is finite and >= 0, else `fallback`.
double nonNegativeAttribute(const Imf::Header& h, const char* name, double fallback) {
    const auto* a = findAttribute<Imf::DoubleAttribute>(h, name);
    return a && std::isfinite(a->value()) && a->value() >= 0.0 ? a->value() : fallback;
}

/// Reads rows [y0, y1) of the data window only to count their samples.
std::uint64_t countRows(exr::DeepExrSource& source, int y0, int y1) {
    std::uint64_t n = 0;
    exr::Band band;
    for (int y = y0; y < y1; y += kCountingRows) {
        source.read(y, std::min(y1, y + kCountingRows), band);
        n += band.sampleCount();
    }
    return n;
}

}  // namespace

ExrImportReport importDeepExr(const std::string& exrPath, const std::string& dsmPath,
                              const ExrImportOptions& options) try {
    exr::checkErrorBoundOption(options.maxLinearError, "deep EXR import: the linearisation error");
    if (options.tolerance && !(std::isfinite(*options.tolerance) && *options.tolerance >= 0.0))
        throw Error(ErrorCode::argument, concat("deep EXR import: the tolerance must be a finite value >= 0, got ",
                                                *options.tolerance));
    checkOutputPath(dsmPath);
    refuseOutputOverInputs(dsmPath, {exrPath});
    try {
        exr::DeepExrSource source(exrPath, options);
        const Imf::Header& h = source.header();
        ExrImportReport report;
        report.channels = source.rgb() ? 3 : 1;
        report.part = source.part().description;
        report.channelNames = source.channels().summary;
        report.notes = source.part().notes;
        report.fromVertexSamples = source.withVertices();
        report.tiled = source.tiled();
        const Imath::Box2i display = source.display(), data = source.data();
        report.width = std::uint32_t(display.max.x - display.min.x + 1);
        report.height = std::uint32_t(display.max.y - display.min.y + 1);

        WriterOptions w;
        try {
            w.camera = exr::lightCamera(h, options, report.width, report.height, report.cameraSource);
        } catch (const Error& e) {
            throw Error(e.code(), concat(quoted(exrPath), ": ", e.what()));
        }
        const auto* fileTolerance = findAttribute<Imf::DoubleAttribute>(h, "dsm:tolerance");
        report.tolerance = options.tolerance ? *options.tolerance
                           : fileTolerance && fileTolerance->value() >= 0.0 && std::isfinite(fileTolerance->value())
                               ? fileTolerance->value()
                               : kDefaultExrImportTolerance;
        report.maxLinearError = options.maxLinearError.value_or(std::clamp(report.tolerance / 4.0, 1e-5, 1e-3));
        // The image's own statement about its source: the map level it came
        // from (dsm:errorBound) and, read through its samples, the export's
        // exponential reading (dsm:maxDeviation).
        report.sourceErrorBound = nonNegativeAttribute(h, "dsm:errorBound", 0.0);
        if (report.fromVertexSamples) {
            report.errorBound = report.sourceErrorBound;
        } else {
            report.sourceErrorBound += nonNegativeAttribute(h, "dsm:maxDeviation", 0.0);
            report.errorBound = report.tolerance + report.maxLinearError + report.sourceErrorBound;
        }

        w.width = report.width;
        w.height = report.height;
        w.tileSize = options.tileSize;
        w.channels = report.channels;
        // Level 0's recorded tolerance is its whole error bound, so the bounds
        // the writer derives for every level stay true.
        w.tolerance = report.errorBound;
        w.mipLevels = options.mipLevels;
        w.levelToleranceFactor = options.levelToleranceFactor;
        w.zlibLevel = options.zlibLevel;
        if (report.fromVertexSamples) {
            const auto* counts = findAttribute<Imf::IntAttribute>(h, "dsm:counts");
            const auto* layers = findAttribute<Imf::IntAttribute>(h, "dsm:maxLayers");
            w.counts = !counts || counts->value() != 0;
            w.maxLayers = layers && layers->value() >= 1 && layers->value() <= 255 ? layers->value() : 255;
        }
        if (const auto* f = findAttribute<Imf::StringAttribute>(h, "dsm:filter")) {
            if (const auto filter = pixelFilterFromName(f->value())) w.filter = *filter;
        }
        if (const auto* fw = findAttribute<Imf::DoubleAttribute>(h, "dsm:filterWidth"))
            if (fw->value() > 0.0 && std::isfinite(fw->value())) w.filterWidth = fw->value();
        w.metadata = exr::importedMetadata(h, std::filesystem::path(exrPath).filename().string());

        MapWriter writer(dsmPath, w);
        // Rows of the data window above the display window: counted, not read into the map.
        report.droppedSamples += countRows(source, data.min.y, std::min(data.max.y + 1, display.min.y));
        const int mapWidth = int(report.width);
        exr::Band band;
        std::vector<VisibilityFunction> rows;  // the current row of map tiles
        std::vector<VisibilityFunction> tile;
        for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty) {
            const int top = int(ty * w.tileSize), rowCount = int(writer.tileHeight(ty));
            rows.assign(std::size_t(mapWidth) * std::size_t(rowCount), VisibilityFunction(report.channels, w.counts));
            source.read(display.min.y + top, display.min.y + top + rowCount, band);
            const std::size_t bandRows = std::size_t(band.rows > 0 ? band.rows : 0);
            std::vector<std::uint64_t> vertices(bandRows, 0), samples(bandRows, 0), merged(bandRows, 0),
                dropped(bandRows, 0);
            tbb::parallel_for(0, band.rows, [&](int r) {
                const int fileY = band.y0 + r, mapY = fileY - display.min.y - top;
                for (int c = 0; c < band.width; ++c) {
                    const std::size_t i = std::size_t(r) * std::size_t(band.width) + std::size_t(c);
                    const auto& pixel = band.samples[i];
                    if (pixel.empty()) continue;
                    const int fileX = band.x0 + c, mapX = fileX - display.min.x;
                    if (mapX < 0 || mapX >= mapWidth) {
                        dropped[std::size_t(r)] += pixel.size();
                        continue;
                    }
                    samples[std::size_t(r)] += pixel.size();
                    try {
                        auto& out = rows[std::size_t(mapY) * std::size_t(mapWidth) + std::size_t(mapX)];
                        if (report.fromVertexSamples) {
                            out = exr::functionFromVertexSamples(pixel, band.vertices[i], report.channels, w.counts);
                        } else {
                            merged[std::size_t(r)] += coincidentSamples(pixel);
                            const VisibilityFunction exact =
                                visibilityFromDeepSamples(pixel, report.channels, report.maxLinearError);
                            out = compress(exact, report.tolerance);
                        }
                        vertices[std::size_t(r)] += out.size();
                    } catch (const Error& e) {
                        throw Error(ErrorCode::corrupt,
                                    concat(quoted(exrPath), " pixel ", fileX, ",", fileY, ": ", e.what()));
                    }
                }
            });
            for (std::size_t r = 0; r < bandRows; ++r) {
                report.samples += samples[r];
                report.mergedSamples += merged[r];
                report.droppedSamples += dropped[r];
                report.vertices += vertices[r];
            }
            for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
                tile.clear();
                for (std::uint32_t y = 0; y < writer.tileHeight(ty); ++y)
                    for (std::uint32_t x = 0; x < writer.tileWidth(tx); ++x)
                        tile.push_back(std::move(rows[std::size_t(y) * std::size_t(mapWidth) + tx * w.tileSize + x]));
                writer.writeTile(tx, ty, tile);
            }
        }
        // Rows of the data window below the display window.
        report.droppedSamples += countRows(source, std::max(data.min.y, display.max.y + 1), data.max.y + 1);
        writer.finish();
        report.exrChunks = source.chunkCount();
        report.exrDecodes = source.decodes();
        return report;
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error(ErrorCode::io, concat(quoted(exrPath), ": ", exr::openExrMessage(exrPath, e.what())));
    }
} catch (const Error& e) {
    throw detail::withOneOf(e, {exrPath, dsmPath});
}

DSM_NAMESPACE_END
