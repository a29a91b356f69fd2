// dsm-build: renders a scene from its light and writes a deep shadow map.
#include <dsm/dsm.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include "build_options.h"
#include "option_checks.h"
#include "tool_support.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include <unistd.h>

namespace {

/// --region X0,Y0,X1,Y1: four decimal integers, X0 < X1 and Y0 < Y1 (an empty
/// region is refused, not taken for the whole map).
std::array<std::uint32_t, 4> parseRegion(const std::string& text) {
    std::array<std::uint32_t, 4> r{};
    std::size_t start = 0;
    for (std::size_t k = 0; k < 4; ++k) {
        const std::size_t end = k < 3 ? text.find(',', start) : text.size();
        std::uint64_t value = 0;
        if (end == std::string::npos ||
            !dsm::tools::parseUnsigned(std::string_view(text).substr(start, end - start), value) ||
            value > UINT32_MAX)
            throw std::invalid_argument("--region expects X0,Y0,X1,Y1, got '" + text +
                                        "' (four integers in [0, 4294967295])");
        r[k] = static_cast<std::uint32_t>(value);
        start = end + 1;
    }
    if (r[0] >= r[2] || r[1] >= r[3])
        throw std::invalid_argument("--region " + text + " is empty (X0 < X1 and Y0 < Y1 are needed)");
    return r;
}

std::string humanBytes(double bytes) {
    const char* units[] = {"B", "KiB", "MiB", "GiB"};
    int u = 0;
    while (bytes >= 1024.0 && u < 3) {
        bytes /= 1024.0;
        ++u;
    }
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, u == 0 ? "%.0f %s" : "%.2f %s", bytes, units[u]);
    return buffer;
}

/// Maps above this many pixels (16384^2) are announced before they start.
constexpr std::uint64_t kAnnouncedPixels = std::uint64_t{16384} * 16384;

/// Physical memory of the machine, or 0 when unknown.
std::uint64_t physicalMemory() {
    const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGESIZE);
    return pages > 0 && pageSize > 0 ? std::uint64_t(pages) * std::uint64_t(pageSize) : 0;
}

/// One line on standard error before a build that will take long or may not
/// fit: what it is about to do and the memory it expects to hold.
void announceLargeBuild(const dsm::BuildEstimate& e, std::uint32_t spp) {
    const std::uint64_t machine = physicalMemory();
    const bool tooBig = machine && e.memoryBytes > machine;
    if (std::uint64_t(e.width) * e.height <= kAnnouncedPixels && !tooBig) return;
    const std::string pixels = e.pixels == std::uint64_t(e.width) * e.height
                                   ? std::to_string(e.width) + " x " + std::to_string(e.height) + " pixels"
                                   : std::to_string(e.pixels) + " region pixels";
    std::fprintf(stderr, "dsm-build: %s x %u samples = %llu sample rays, about %s of memory%s\n", pixels.c_str(),
                 spp, static_cast<unsigned long long>(e.sampleRays), humanBytes(double(e.memoryBytes)).c_str(),
                 tooBig ? (", more than the machine's " + humanBytes(double(machine))).c_str() : "");
    std::fflush(stderr);
}

// A progress bar with ETA on a terminal, a plain line every 10% otherwise.
class Progress {
public:
    explicit Progress(bool quiet) : quiet_(quiet), terminal_(::isatty(STDERR_FILENO) != 0) {}
    void operator()(double fraction) {
        if (quiet_) return;
        const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
        const double eta = fraction > 0.0 ? elapsed * (1.0 - fraction) / fraction : 0.0;
        if (terminal_) {
            const int width = 40, filled = static_cast<int>(fraction * width + 0.5);
            std::fprintf(stderr, "\r[%s%s] %5.1f%%  %6.1fs elapsed  ETA %6.1fs", std::string(filled, '#').c_str(),
                         std::string(width - filled, ' ').c_str(), 100.0 * fraction, elapsed, eta);
            if (fraction >= 1.0) std::fprintf(stderr, "\n");
        } else {
            const int decile = static_cast<int>(fraction * 10.0 + 1e-9);
            if (decile > lastDecile_) {
                lastDecile_ = decile;
                std::fprintf(stderr, "dsm-build: %3d%% done, %.1f s elapsed, ETA %.1f s\n", decile * 10, elapsed, eta);
            }
        }
        std::fflush(stderr);
    }

private:
    using Clock = std::chrono::steady_clock;
    bool quiet_;
    bool terminal_;
    int lastDecile_ = 0;
    Clock::time_point start_ = Clock::now();
};

}  // namespace

int main(int argc, char** argv) {
    using dsm::tools::finiteNumberIn, dsm::tools::integerIn, dsm::tools::LowerBound;
    CLI::App app{"dsm-build: render a scene from its light into a deep shadow map (.dsm)"};
    app.set_version_flag("--version", std::string("dsm-build ") + DSM_TOOLS_VERSION);
    std::string scenePath, output, region;
    std::string statsJson;
    dsm::tools::BuildOptionText buildText;
    dsm::BuildOptions options;
    unsigned threads = 0;
    bool quiet = false;
    app.add_option("scene", scenePath, "Scene description (JSON, see spec/scene.md); - reads stdin")->required();
    app.add_option("-o,--output", output, "Output .dsm file")->required();
    dsm::tools::addBuildOptions(app, buildText);
    app.add_option("--region", region, "Build only pixels X0,Y0,X1,Y1 (half-open), for distributed builds");
    app.add_option("-j,--threads", threads, "Worker threads (0 = all cores; more are clamped to the cores)")
        ->check(integerIn(0, UINT32_MAX))
        ->capture_default_str();
    app.add_flag("-q,--quiet", quiet, "No progress or summary");
    app.add_option("--stats-json", statsJson, "Write the build statistics as JSON to this file");
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::cerr << "dsm-build: " << e.what() << " (see --help)\n";
        return 2;
    }

    try {
        options = dsm::tools::parsedBuildOptions(buildText);
        if (app.count("--region")) options.region = parseRegion(region);
    } catch (const std::exception& e) {
        std::cerr << "dsm-build: " << e.what() << "\n";
        return 2;
    }

    try {
        // Before the scene is read or the build starts: outputs that cannot be
        // written, or would replace the scene or each other, are refused.
        std::vector<std::string> outputs{output};
        if (app.count("--stats-json")) outputs.push_back(statsJson);
        dsm::tools::checkOutputs(outputs, {scenePath});
        if (scenePath != "-") dsm::tools::requireRegularFile(scenePath);  // a FIFO would block the open
        dsm::SceneReadOptions sceneOptions;
        sceneOptions.maxBytes = buildText.maxSceneMiB << 20;
        const dsm::Scene scene = scenePath == "-" ? dsm::readScene(std::cin, ".", "<stdin>", sceneOptions)
                                                  : dsm::loadScene(scenePath, sceneOptions);
        dsm::tools::checkOutputs(outputs, scene.files);
        options.threads = dsm::tools::usableThreadsNoted("dsm-build", threads, quiet);
        if (!quiet) announceLargeBuild(dsm::estimateBuild(scene, options), options.samplesPerPixel);
        Progress progress(quiet);
        options.progress = [&](double f) { progress(f); };
        const dsm::BuildStats s = dsm::buildMap(scene, options, output);

        const double mean = s.pixels ? double(s.vertices) / double(s.pixels) : 0.0;
        if (!quiet) {
            const double cpu = s.samplingSeconds + s.sweepSeconds + s.compressionSeconds;
            std::printf("dsm-build: wrote '%s'\n", output.c_str());
            std::printf("  time         %.2f s wall; thread time: sampling %.2f s, sweep %.2f s, compression %.2f s; "
                        "writing %.2f s\n",
                        s.wallSeconds, s.samplingSeconds, s.sweepSeconds, s.compressionSeconds, s.writingSeconds);
            std::printf("  share        sampling %.1f%%, sweep %.1f%%, compression %.1f%% of thread time\n",
                        cpu > 0 ? 100.0 * s.samplingSeconds / cpu : 0.0, cpu > 0 ? 100.0 * s.sweepSeconds / cpu : 0.0,
                        cpu > 0 ? 100.0 * s.compressionSeconds / cpu : 0.0);
            std::printf("  samples      %llu (%.0f per second of wall time)\n",
                        static_cast<unsigned long long>(s.samples), s.wallSeconds > 0 ? s.samples / s.wallSeconds : 0.0);
            std::printf("  vertices     %.2f per pixel (max %u), tolerance %.6g\n", mean, s.maxVerticesPerPixel,
                        s.tolerance);
            std::printf("  file         %s, %.1fx smaller than the raw per-sample data (%s)\n",
                        humanBytes(double(s.fileBytes)).c_str(),
                        s.fileBytes ? double(s.rawBytes) / double(s.fileBytes) : 0.0,
                        humanBytes(double(s.rawBytes)).c_str());
        }
        if (app.count("--stats-json")) {
            nlohmann::json j = {{"output", output},
                                {"wall_seconds", s.wallSeconds},
                                {"sampling_seconds", s.samplingSeconds},
                                {"crossing_seconds", s.crossingSeconds},
                                {"sweep_seconds", s.sweepSeconds},
                                {"compression_seconds", s.compressionSeconds},
                                {"writing_seconds", s.writingSeconds},
                                {"samples", s.samples},
                                {"pixels", s.pixels},
                                {"vertices", s.vertices},
                                {"mean_vertices_per_pixel", mean},
                                {"max_vertices_per_pixel", s.maxVerticesPerPixel},
                                {"tolerance", s.tolerance},
                                {"file_bytes", s.fileBytes},
                                {"raw_bytes", s.rawBytes},
                                {"sample_vertices", s.sampleVertices}};
            const std::string text = j.dump(2) + "\n";
            dsm::OutputFile stats(statsJson);
            stats.write(text.data(), text.size());
            stats.commit();
        }
    } catch (const dsm::Error& e) {
        std::cerr << "dsm-build: ERROR " << e.what() << "\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << dsm::tools::oneLine("dsm-build: ERROR " + dsm::tools::exceptionMessage(e)) << "\n";
        return 1;
    }
    return 0;
}
