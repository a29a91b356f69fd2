#include "build_options.h"

#include "option_checks.h"

#include <dsm/names.h>

#include <charconv>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace dsm::tools {
namespace {

/// A map is at most 131072 pixels wide: at most 18 mip levels.
constexpr double kMaxMipLevels = 18;

// Parses "auto" or a number (0 is allowed where the option allows it).
bool parseAutoOr(const std::string& text, double& value) {
    if (text == "auto") return false;
    std::size_t used = 0;
    value = std::stod(text, &used);
    if (used != text.size()) throw std::invalid_argument(text);
    return true;
}

/// Shortest text that reads back as the same double.
std::string exactText(double value) {
    char buffer[32];
    const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
    return std::string(buffer, result.ptr);
}

}  // namespace

void addBuildOptions(CLI::App& app, BuildOptionText& text) {
    BuildOptions& options = text.options;
    app.add_option("-r,--resolution", text.resolution, "Map size WxH or N (default: the scene light's)");
    app.add_option("-s,--spp", options.samplesPerPixel, "Samples per pixel (stratified, jittered), 1..65536")
        ->check(integerIn(1, 65536))
        ->capture_default_str();
    app.add_option("-e,--tolerance", text.tolerance,
                   "Compression tolerance: auto (0.25/sqrt(spp), 0.125/sqrt(spp) for a scene with an area light) or "
                   "a value in [0, 1]")
        ->capture_default_str();
    app.add_option("-f,--filter", text.filter,
                   "Pixel filter: box, triangle or gaussian; auto: gaussian, box for a scene with an area light")
        ->check(CLI::IsMember({"auto", "box", "triangle", "gaussian"}))
        ->capture_default_str();
    app.add_option("-w,--filter-width", text.filterWidth,
                   "Filter width in pixels, in (0, 64]; auto: 2, 1 for a box filter under an area light")
        ->check(autoOr(finiteNumberIn(0.0, 64.0, LowerBound::Exclusive)))
        ->capture_default_str();
    app.add_option("-m,--mip-levels", text.mipLevels, "Mip levels: auto (full pyramid) or N (1 = none)")
        ->capture_default_str();
    app.add_option("--level-tolerance-factor", options.levelToleranceFactor,
                   "Each coarser mip level's tolerance = the previous one's x this, in (0, 16]")
        ->check(finiteNumberIn(0.0, 16.0, LowerBound::Exclusive))
        ->capture_default_str();
    app.add_option("-t,--tile-size", options.tileSize, "Tile size: a power of two, 2..4096")
        ->check(integerIn(2, 4096))
        ->capture_default_str();
    app.add_option("-l,--mtsm-layers", text.mtsmLayers,
                   "Layers per pixel, 1..255 (> 1 builds an MTSM with counts); auto: 1, 2 for a scene with an area light")
        ->check(autoOr(integerIn(1, 255)))
        ->capture_default_str();
    app.add_option("--sampler", text.sampler,
                   "How samples find surfaces: scanline (primitives bucketed by tile) or raytrace (a ray per sample)")
        ->check(CLI::IsMember({"scanline", "raytrace"}))
        ->capture_default_str();
    app.add_flag("--counts", options.counts, "Store per-vertex sample counts even without layers");
    app.add_flag("--centred-compression", options.centredCompression,
                 "Centre compressed segments on their input (mean signed error within eps/10 on plateaus and ramps, "
                 "and within eps/10 where a plateau ends); "
                 "larger maps");
    app.add_option("--seed", options.seed, "Random seed, an integer in [0, 2^64 - 1]")
        ->check(integerIn(0, UINT64_MAX))
        ->capture_default_str();
    app.add_option("-z,--zlib-level", options.zlibLevel, "zlib level 0..9 (0 stores tiles)")
        ->check(integerIn(0, 9))
        ->capture_default_str();
    app.add_option("--codec", text.codec,
                   "Tile compressor: zlib, or zstd (3-6 % larger tiles, decompressed several times faster)")
        ->check(CLI::IsMember({"zlib", "zstd"}))
        ->capture_default_str();
    app.add_option("--zstd-level", options.zstdLevel, "zstd level 0..22 with --codec zstd (0 stores tiles)")
        ->check(integerIn(0, 22))
        ->capture_default_str();
    app.add_option("--max-scene-mb", text.maxSceneMiB, "Largest scene read, in MiB, 1..1048576")
        ->check(integerIn(1, 1u << 20))
        ->capture_default_str();
}

BuildOptions parsedBuildOptions(const BuildOptionText& text) {
    BuildOptions options = text.options;
    const std::string& resolution = text.resolution;
    if (!resolution.empty()) {
        if (resolution.find('-') != std::string::npos)
            throw std::invalid_argument("--resolution expects positive WxH or N, got '" + resolution + "'");
        unsigned w = 0, h = 0;
        char x = 0, extra = 0;
        std::istringstream in(resolution);
        if ((in >> w) && in.eof()) {
            h = w;
        } else {
            std::istringstream again(resolution);
            if (!(again >> w >> x >> h) || x != 'x' || (again >> extra))
                throw std::invalid_argument("--resolution expects WxH or N, got '" + resolution + "'");
        }
        if (w == 0 || h == 0)
            throw std::invalid_argument("--resolution expects positive WxH or N, got '" + resolution + "'");
        options.width = w;
        options.height = h;
    }
    double value = 0.0;
    try {
        if (parseAutoOr(text.tolerance, value)) options.tolerance = value;
        if (parseAutoOr(text.mipLevels, value)) {
            if (!(value >= 1.0 && value <= kMaxMipLevels) || value != std::floor(value))
                throw std::invalid_argument(text.mipLevels);
            options.mipLevels = static_cast<unsigned>(value);
        }
    } catch (const std::exception&) {
        throw std::invalid_argument("--tolerance and --mip-levels expect auto or a number");
    }
    if (options.tolerance && !(*options.tolerance >= 0.0 && *options.tolerance <= 1.0))
        throw std::invalid_argument("--tolerance expects auto or a value in [0, 1], got '" + text.tolerance + "'");
    // CLI11 checked these: a filter name, a number in (0, 64], an integer in [1, 255].
    if (text.filter != "auto") options.filter = *pixelFilterFromName(text.filter);
    if (text.filterWidth != "auto") options.filterWidth = std::stod(text.filterWidth);
    if (text.mtsmLayers != "auto") options.mtsmLayers = std::stoi(text.mtsmLayers);
    options.sampler = text.sampler == "raytrace" ? SamplerMethod::raytrace : SamplerMethod::scanline;
    options.codec = text.codec == "zstd" ? dsm::TileCodec::Zstd : dsm::TileCodec::Zlib;
    return options;
}

std::vector<std::string> buildOptionArguments(const BuildOptions& options, std::uint64_t maxSceneMiB) {
    std::vector<std::string> args;
    if (options.width && options.height)
        args.insert(args.end(), {"--resolution", std::to_string(*options.width) + "x" + std::to_string(*options.height)});
    args.insert(args.end(), {"--spp", std::to_string(options.samplesPerPixel)});
    args.insert(args.end(), {"--tolerance", options.tolerance ? exactText(*options.tolerance) : "auto"});
    args.insert(args.end(), {"--filter", options.filter ? filterName(*options.filter) : "auto"});
    args.insert(args.end(), {"--filter-width", options.filterWidth ? exactText(*options.filterWidth) : "auto"});
    args.insert(args.end(), {"--mip-levels", options.mipLevels ? std::to_string(*options.mipLevels) : "auto"});
    args.insert(args.end(), {"--level-tolerance-factor", exactText(options.levelToleranceFactor)});
    args.insert(args.end(), {"--tile-size", std::to_string(options.tileSize)});
    args.insert(args.end(), {"--mtsm-layers", options.mtsmLayers ? std::to_string(*options.mtsmLayers) : "auto"});
    args.insert(args.end(), {"--sampler", options.sampler == SamplerMethod::raytrace ? "raytrace" : "scanline"});
    if (options.counts) args.push_back("--counts");
    if (options.centredCompression) args.push_back("--centred-compression");
    args.insert(args.end(), {"--seed", std::to_string(options.seed)});
    args.insert(args.end(), {"--zlib-level", std::to_string(options.zlibLevel)});
    args.insert(args.end(), {"--codec", options.codec == dsm::TileCodec::Zstd ? "zstd" : "zlib"});
    args.insert(args.end(), {"--zstd-level", std::to_string(options.zstdLevel)});
    args.insert(args.end(), {"--max-scene-mb", std::to_string(maxSceneMiB)});
    return args;
}

}  // namespace dsm::tools
