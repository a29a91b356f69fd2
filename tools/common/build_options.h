// The dsm-build options that set dsm::BuildOptions, shared by the tools that
// build maps (dsm-build, dsm-farm): declared on a CLI11 app, turned into
// BuildOptions, and spelled back as arguments (for the per-part commands a
// farm engine runs).
#pragma once

#include <dsm/sampler.h>

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace dsm::tools {

/// What the options hold as given, before they are checked.
struct BuildOptionText {
    BuildOptions options;
    std::string resolution;
    std::string tolerance = "auto";
    std::string filter = "auto";
    std::string filterWidth = "auto";
    std::string mtsmLayers = "auto";
    std::string mipLevels = "auto";
    std::string sampler = "scanline";
    std::string codec = "zlib";
    std::uint64_t maxSceneMiB = SceneReadOptions{}.maxBytes >> 20;
};

/// Declares -r, -s, -e, -f, -w, -m, -t, -l, --sampler, --counts, --seed, -z,
/// --codec, --zstd-level and --max-scene-mb on `app` (or a subcommand), bound to `text`.
void addBuildOptions(CLI::App& app, BuildOptionText& text);

/// text.options with the resolution, tolerance, mip levels, filter, filter
/// width and layers parsed ("auto" leaves a field unset: buildMap gives it
/// the scene's default, dsm::resolvedBuildOptions).
/// Throws std::invalid_argument with the usage message on a malformed value.
BuildOptions parsedBuildOptions(const BuildOptionText& text);

/// `options` spelled as the arguments addBuildOptions declares, so that the
/// same options reach another process exactly (threads and region are left
/// out).
std::vector<std::string> buildOptionArguments(const BuildOptions& options, std::uint64_t maxSceneMiB);

}  // namespace dsm::tools
