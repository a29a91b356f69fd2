// dsm-merge: combines deep shadow maps, as the product of separately built
// occluders or by stitching region builds. Documentation: docs/dsm-merge.md.
//
// Uses only libdsm's public API; the library does the work.
#include <exception>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "dsm/error.h"
#include "dsm/merge.h"
#include "option_checks.h"
#include "tool_support.h"

namespace {

constexpr const char* kToolName = "dsm-merge";

}  // namespace

int main(int argc, char** argv) {
    using namespace dsm::tools;
    CLI::App app{"dsm-merge: combine deep shadow maps (.dsm): the product of maps of separately built occluders, "
                 "or one map stitched from region builds"};
    configureApp(app, kToolName, "docs/dsm-merge.md");
    std::vector<std::string> inputs;
    std::string output;
    std::string mode = "product";
    double tolerance = 0.0;
    int zlibLevel = 6;
    bool quiet = false;
    app.add_option("inputs", inputs, "Input .dsm files")->required();
    app.add_option("-o,--output", output, "Output .dsm file (written atomically)")->required();
    app.add_option("--mode", mode, "product: multiply visibilities; stitch: join region builds")
        ->check(CLI::IsMember({"product", "stitch"}))
        ->capture_default_str();
    app.add_option("-e,--tolerance", tolerance,
                   "Product: recompression tolerance in [0, 1] (default: the largest level-0 tolerance of the inputs)")
        ->check(finiteNumberIn(0.0, 1.0));
    app.add_option("-z,--zlib-level", zlibLevel,
                   "zlib level 0..9 (default: product 6; stitch the inputs' level, found from their tiles)")
        ->check(integerIn(0, 9));
    app.add_flag("-q,--quiet", quiet, "Print nothing on success");
    if (const int status = parseArguments(app, argc, argv); status >= 0) return status;
    if (mode == "stitch" && app.count("--tolerance")) {
        std::cerr << kToolName << ": --tolerance applies to --mode product only (stitch keeps the inputs')\n"
                  << "Run with --help for more information.\n";
        return kExitUsage;
    }

    dsm::MergeOptions options;
    options.mode = mode == "stitch" ? dsm::MergeMode::Stitch : dsm::MergeMode::Product;
    if (app.count("--tolerance")) options.tolerance = tolerance;
    if (app.count("--zlib-level")) options.zlibLevel = zlibLevel;
    try {
        const dsm::MergeReport r = dsm::mergeMaps(inputs, output, options);
        if (!quiet) {
            std::cout << kToolName << ": wrote '" << output << "' (" << mode << " of " << inputs.size() << " map"
                      << (inputs.size() == 1 ? "" : "s") << ")\n"
                      << "  size         " << r.width << "x" << r.height << ", " << r.channels
                      << (r.channels == 1 ? " channel" : " channels")
                      << (r.maxLayers > 1 ? ", " + std::to_string(r.maxLayers) + " layers" : "") << ", " << r.vertices
                      << " level-0 vertices, "
                      << r.fileBytes << " bytes\n"
                      << "  tolerance    " << r.tolerance << " (zlib level " << r.zlibLevel << ")\n";
            if (options.mode == dsm::MergeMode::Product)
                std::cout << "  error bound  " << r.errorBound << " = inputs and interpolation " << r.inputErrorBound
                          << " (interpolation " << r.interpolationError << ") + recompression\n";
        }
    } catch (const std::exception& e) {
        reportException(kToolName, e);  // libdsm's error names the input or output it is about
        return kExitFailure;
    }
    return kExitOk;
}
