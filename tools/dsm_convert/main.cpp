// dsm-convert: deep shadow maps to deep OpenEXR images and back; the
// direction follows OUT's extension, and IN must be of the other kind (by its
// magic number, whatever its name). Documentation: docs/dsm-convert.md; the
// mapping and its error bounds: spec/exr-interop.md.
//
// Uses only libdsm's public API.
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "dsm/error.h"
#include "dsm/exr_deep.h"
#include "dsm/reader.h"
#include "option_checks.h"
#include "tool_support.h"

namespace {

constexpr const char* kToolName = "dsm-convert";
/// A map is at most 131072 pixels wide: 18 levels, numbered 0..17.
constexpr std::uint64_t kMaxMipLevel = 17;
/// Widths in light units: any finite scene fits well inside.
constexpr double kMaxLength = 1e30;

enum class Kind { Map, Exr, Unknown };

/// The kind OUT's extension asks for.
Kind kindOf(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".dsm") return Kind::Map;
    if (ext == ".exr") return Kind::Exr;
    return Kind::Unknown;
}

}  // namespace

int main(int argc, char** argv) {
    using dsm::tools::finiteNumberIn, dsm::tools::integerIn, dsm::tools::LowerBound;
    CLI::App app{"Convert a deep shadow map (.dsm) to a deep OpenEXR image (.exr) or back; the direction follows "
                 "the extension of OUT.",
                 kToolName};
    std::string input, output;
    app.add_option("IN", input, "Input map or deep OpenEXR image, told apart by its first bytes; - reads "
                                "standard input")
        ->required()
        ->type_name("");
    app.add_option("OUT", output, "Output .exr or .dsm (written atomically)")->required()->type_name("");

    dsm::ExrExportOptions exportOptions;
    auto* level = app.add_option("--level", exportOptions.level, ".dsm -> .exr: mip level to export (default 0)")
                      ->type_name("L")
                      ->check(integerIn(0, kMaxMipLevel));
    auto* tiled = app.add_flag("--tiled", exportOptions.tiled,
                               ".dsm -> .exr: write a deep tiled image (default deep scanline)");
    auto* exrTile = app.add_option("--exr-tile-size", exportOptions.tileSize,
                                   ".dsm -> .exr: tile edge of a --tiled image (default 64)")
                        ->type_name("N")
                        ->check(integerIn(1, 65536))
                        ->needs(tiled);
    double maxDeviation = 0.0;
    auto* deviation = app.add_option("--max-deviation", maxDeviation,
                                     ".dsm -> .exr: bound on |EXR transmittance - map visibility| from the "
                                     "exponential reading of volume samples, in [1e-6, 1] (default "
                                     "clamp(tolerance/2, 1e-5, 1e-3))")
                          ->type_name("D")
                          ->check(finiteNumberIn(dsm::kMinExrErrorBound, 1.0));

    dsm::ExrImportOptions importOptions;
    double importTolerance = 0.0, maxLinearError = 0.0, fieldOfView = 0.0, orthoWidth = 0.0;
    unsigned mipLevels = 0;
    auto* tolerance = app.add_option("-e,--tolerance", importTolerance,
                                     ".exr -> .dsm: compression tolerance (default: the file's dsm:tolerance, "
                                     "else 1/256), in [0, 1]")
                          ->type_name("E")
                          ->check(finiteNumberIn(0.0, 1.0));
    auto* linear = app.add_option("--max-linear-error", maxLinearError,
                                  ".exr -> .dsm: bound on the chords that replace exponential volume samples "
                                  "in [1e-6, 1] (default clamp(tolerance/4, 1e-5, 1e-3))")
                       ->type_name("D")
                       ->check(finiteNumberIn(dsm::kMinExrErrorBound, 1.0));
    std::string part, view, channelMapping;
    auto* partOption = app.add_option("--part", part, ".exr -> .dsm: the part to read, by index or name (default: "
                                                      "the first deep part)")
                           ->type_name("NAME|INDEX");
    auto* viewOption = app.add_option("--view", view, ".exr -> .dsm: the deep part of this view")->type_name("NAME");
    auto* channelsOption =
        app.add_option("--channels", channelMapping,
                       ".exr -> .dsm: channels for Z, ZBack, A, AR, AG, AB, as Z=depth.Z,A=rgba.A (default: the "
                       "channel of that name, else the one named LAYER.ROLE)")
            ->type_name("ROLE=NAME,...")
            ->check(CLI::Validator(
                [](std::string& text) {
                    try {
                        (void)dsm::parseExrChannelMapping(text);
                    } catch (const dsm::Error& e) {
                        return std::string(e.what());
                    }
                    return std::string();
                },
                "ROLE=NAME,...", "channel mapping"));
    std::string cameraFrom;
    auto* cameraMap = app.add_option("--camera-from", cameraFrom, ".exr -> .dsm: take the light camera of this map")
                          ->type_name("MAP.dsm");
    auto* fov = app.add_option("--fov", fieldOfView,
                               ".exr -> .dsm: perspective light of this horizontal field of view (degrees), placed "
                               "by the file's worldToCamera")
                    ->type_name("DEG")
                    ->check(CLI::Validator(
                        [](std::string& text) {
                            double degrees = 0.0;
                            try {
                                degrees = std::stod(text);
                            } catch (const std::exception&) {
                                return std::string("expects a number of degrees");
                            }
                            return degrees > 0.0 && degrees < 180.0 ? std::string()
                                                                    : std::string("expects degrees in (0, 180)");
                        },
                        "DEG", "in (0, 180)"));
    auto* ortho = app.add_option("--ortho-width", orthoWidth,
                                 ".exr -> .dsm: orthographic light with a window this wide (light units)")
                      ->type_name("W")
                      ->check(finiteNumberIn(0.0, kMaxLength, LowerBound::Exclusive));
    auto* mapTile = app.add_option("-t,--tile-size", importOptions.tileSize,
                                   ".exr -> .dsm: map tile edge, a power of two 2..4096 (default 32)")
                        ->type_name("N")
                        ->check(integerIn(2, 4096));
    auto* mips = app.add_option("-m,--mip-levels", mipLevels,
                                ".exr -> .dsm: mip levels, 0 = full pyramid (default), 1 = none")
                     ->type_name("N")
                     ->check(integerIn(0, kMaxMipLevel + 1));
    auto* levelFactor =
        app.add_option("--level-tolerance-factor", importOptions.levelToleranceFactor,
                       ".exr -> .dsm: each coarser mip level's tolerance = the previous one's x this (default 0.5)")
            ->type_name("F")
            ->check(finiteNumberIn(0.0, 16.0, LowerBound::Exclusive));
    bool quiet = false;
    app.add_flag("-q,--quiet", quiet, "Print nothing on success");
    cameraMap->excludes(fov)->excludes(ortho);
    fov->excludes(ortho);

    Kind from = Kind::Unknown, to = Kind::Unknown;
    app.callback([&] {
        to = kindOf(output);
        if (to == Kind::Unknown) throw CLI::ValidationError("OUT", "'" + output + "' must end in .dsm or .exr");
        from = to == Kind::Map ? Kind::Exr : Kind::Map;
        const auto& exportOnly = {level, tiled, exrTile, deviation};
        const auto& importOnly = {tolerance, linear, cameraMap, fov, ortho, mapTile, mips, levelFactor, partOption,
                                  viewOption, channelsOption};
        for (CLI::Option* o : to == Kind::Exr ? importOnly : exportOnly)
            if (o->count())
                throw CLI::ValidationError(o->get_name(), std::string("applies only to ") +
                                                              (to == Kind::Exr ? ".exr -> .dsm" : ".dsm -> .exr"));
    });
    dsm::tools::configureApp(app, kToolName, "docs/dsm-convert.md");
    app.footer("Exit status: 0 on success, 1 when a file cannot be read, converted or written, 2 on a usage "
               "error.\nDocumentation: docs/dsm-convert.md");
    if (const int status = dsm::tools::parseArguments(app, argc, argv); status >= 0) return status;
    if (deviation->count()) exportOptions.maxDeviation = maxDeviation;
    if (tolerance->count()) importOptions.tolerance = importTolerance;
    if (linear->count()) importOptions.maxLinearError = maxLinearError;
    if (fov->count()) importOptions.fieldOfView = fieldOfView;
    if (ortho->count()) importOptions.orthoWidth = orthoWidth;
    if (mips->count() && mipLevels != 0) importOptions.mipLevels = mipLevels;  // 0: the full pyramid
    importOptions.part = part;
    importOptions.view = view;
    if (channelsOption->count()) importOptions.channels = dsm::parseExrChannelMapping(channelMapping);

    // What the failed step was working on, for errors that name no file.
    std::string current = input == "-" ? "<stdin>" : input;
    dsm::tools::DisplayNames displayNames;
    try {
        // Before any work: an output that cannot be written or would replace an input is refused.
        dsm::tools::checkOutputs({output}, cameraFrom.empty() ? std::vector<std::string>{input}
                                                              : std::vector<std::string>{input, cameraFrom});
        dsm::tools::InputFile in(input);
        dsm::tools::addDisplayName(displayNames, in);
        // The input's kind by its magic number, not its name.
        if (const bool exr = dsm::hasOpenExrMagic(in.path()); exr != (from == Kind::Exr))
            throw dsm::Error(dsm::ErrorCode::format,
                             "'" + in.name() + "': " +
                                 (exr ? "an OpenEXR image converts to a .dsm map, not to '" + output + "'"
                                      : "not an OpenEXR file (to make '" + output + "' from a map, give an .exr OUT)"),
                             in.name());
        if (to == Kind::Exr) {
            const dsm::ExrExportReport r = dsm::exportDeepExr(in.path(), output, exportOptions);
            if (!quiet)
                std::printf("%s: wrote '%s': %u x %u, %s, %llu point and %llu volume samples; largest deviation "
                            "%.3g (bound %.3g)\n",
                            kToolName, output.c_str(), r.width, r.height, r.channels == 1 ? "mono" : "RGB",
                            static_cast<unsigned long long>(r.pointSamples),
                            static_cast<unsigned long long>(r.volumeSamples), r.largestDeviation, r.maxDeviation);
            if (!quiet && r.vertexSamples)
                std::printf("  and %llu vertex samples (every layer and count, for a lossless import)\n",
                            static_cast<unsigned long long>(r.vertices));
            if (!quiet && r.oneStepExcess)
                std::printf("  %llu volume samples one float step long exceed the bound between adjacent float "
                            "depths (segments too steep to cut finer)\n",
                            static_cast<unsigned long long>(r.oneStepExcess));
        } else {
            if (!cameraFrom.empty()) {
                current = cameraFrom;
                importOptions.camera = dsm::DeepShadowMap::open(cameraFrom)->info().camera;
                current = in.name();
            }
            const dsm::ExrImportReport r = dsm::importDeepExr(in.path(), output, importOptions);
            if (!quiet)
                for (const std::string& note : r.notes) std::fprintf(stderr, "%s: note: %s\n", kToolName, note.c_str());
            if (!quiet) {
                const auto count = [](std::uint64_t n) { return static_cast<unsigned long long>(n); };
                std::printf("%s: wrote '%s': %u x %u, %s, %s (%s), %llu samples -> %llu vertices%s, tolerance %.3g, "
                            "error bound %.3g, camera from %s\n",
                            kToolName, output.c_str(), r.width, r.height, r.channels == 1 ? "mono" : "RGB",
                            r.part.c_str(), r.channelNames.c_str(), count(r.samples), count(r.vertices),
                            r.fromVertexSamples ? " (from vertex samples, as they are)" : "", r.tolerance,
                            r.errorBound, r.cameraSource.c_str());
                if (r.mergedSamples)
                    std::printf("  %llu samples at the depths of another sample of their pixel were combined with "
                                "it\n",
                                count(r.mergedSamples));
                if (r.droppedSamples)
                    std::printf("  %llu samples outside the display window were left out\n", count(r.droppedSamples));
                if (r.tiled)
                    std::printf("  %llu EXR tiles, %llu decodes\n", count(r.exrChunks), count(r.exrDecodes));
            }
        }
    } catch (const std::exception& e) {
        // libdsm's errors name the file they concern: the input, the output or the --camera-from map.
        dsm::tools::reportException(kToolName, e, current, displayNames);
        return dsm::tools::kExitFailure;
    }
    return dsm::tools::kExitOk;
}
