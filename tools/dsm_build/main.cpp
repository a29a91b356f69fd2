// dsm-build: renders a scene from its light and writes a deep shadow map.
#include <dsm/dsm.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include <unistd.h>

namespace {

// Parses "auto" or a number (0 is allowed where the option allows it).
bool parseAutoOr(const std::string& text, double& value) {
    if (text == "auto") return false;
    std::size_t used = 0;
    value = std::stod(text, &used);
    if (used != text.size()) throw std::invalid_argument(text);
    return true;
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
    CLI::App app{"dsm-build: render a scene from its light into a deep shadow map (.dsm)"};
    app.set_version_flag("--version", std::string("dsm-build ") + DSM_TOOLS_VERSION);
    std::string scenePath, output, resolution, tolerance = "auto", filter = "gaussian", mipLevels = "auto", region;
    std::string statsJson;
    dsm::BuildOptions options;
    unsigned threads = 0;
    bool quiet = false;
    app.add_option("scene", scenePath, "Scene description (JSON, see spec/scene.md); - reads stdin")->required();
    app.add_option("-o,--output", output, "Output .dsm file")->required();
    app.add_option("-r,--resolution", resolution, "Map size WxH or N (default: the scene light's)");
    app.add_option("-s,--spp", options.samplesPerPixel, "Samples per pixel (stratified, jittered)")
        ->capture_default_str();
    app.add_option("-e,--tolerance", tolerance, "Compression tolerance: auto (0.25/sqrt(spp)) or a value >= 0")
        ->capture_default_str();
    app.add_option("-f,--filter", filter, "Pixel filter: box, triangle or gaussian")
        ->check(CLI::IsMember({"box", "triangle", "gaussian"}))
        ->capture_default_str();
    app.add_option("-w,--filter-width", options.filterWidth, "Filter width in pixels")->capture_default_str();
    app.add_option("-m,--mip-levels", mipLevels, "Mip levels: auto (full pyramid) or N (1 = none)")
        ->capture_default_str();
    app.add_option("-t,--tile-size", options.tileSize, "Tile size: a power of two, 2..4096")->capture_default_str();
    app.add_option("-l,--mtsm-layers", options.mtsmLayers, "Layers per pixel (> 1 builds an MTSM with counts)")
        ->capture_default_str();
    app.add_flag("--counts", options.counts, "Store per-vertex sample counts even without layers");
    app.add_option("--region", region, "Build only pixels X0,Y0,X1,Y1 (half-open), for distributed builds");
    app.add_option("-j,--threads", threads, "Worker threads (0 = all cores)")->capture_default_str();
    app.add_option("--seed", options.seed, "Random seed (a non-negative integer)")
        ->check(CLI::Validator(
            [](std::string& text) {
                return text.find('-') == std::string::npos ? std::string() : "expects a non-negative integer";
            },
            "UINT", "non-negative"))
        ->capture_default_str();
    app.add_option("-z,--zlib-level", options.zlibLevel, "zlib level 0..9 (0 stores tiles)")->capture_default_str();
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
        if (threads != 0) options.threads = threads;  // 0: all cores
        double value = 0.0;
        try {
            if (parseAutoOr(tolerance, value)) options.tolerance = value;
            if (parseAutoOr(mipLevels, value)) {
                if (value < 1.0 || value != std::floor(value)) throw std::invalid_argument(mipLevels);
                options.mipLevels = static_cast<unsigned>(value);
            }
        } catch (const std::exception&) {
            throw std::invalid_argument("--tolerance and --mip-levels expect auto or a number");
        }
        if (options.tolerance && !(*options.tolerance >= 0.0))
            throw std::invalid_argument("--tolerance expects auto or a value >= 0, got '" + tolerance + "'");
        options.filter = *dsm::pixelFilterFromName(filter);  // CLI11 checked the name
        if (!region.empty()) {
            std::istringstream in(region);
            char c1 = 0, c2 = 0, c3 = 0;
            auto& r = options.region;
            if (!(in >> r[0] >> c1 >> r[1] >> c2 >> r[2] >> c3 >> r[3]) || c1 != ',' || c2 != ',' || c3 != ',')
                throw std::invalid_argument("--region expects X0,Y0,X1,Y1, got '" + region + "'");
        }
    } catch (const std::exception& e) {
        std::cerr << "dsm-build: " << e.what() << "\n";
        return 2;
    }

    // Fail before the build, not after it, when the statistics cannot be
    // written; and leave no statistics file behind when the build fails.
    bool statsDone = false;
    struct RemoveUnlessDone {
        const std::string& path;
        const bool& done;
        ~RemoveUnlessDone() {
            if (!path.empty() && !done) std::remove(path.c_str());
        }
    } statsGuard{statsJson, statsDone};
    try {
        std::ofstream statsOut;
        if (!statsJson.empty()) {
            statsOut.open(statsJson);
            if (!statsOut) throw dsm::Error("cannot write statistics to '" + statsJson + "'");
        }
        dsm::Scene scene;
        if (scenePath == "-") {
            std::stringstream text;
            text << std::cin.rdbuf();
            scene = dsm::parseScene(text.str(), ".", "<stdin>");
        } else {
            scene = dsm::loadScene(scenePath);
        }
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
        if (!statsJson.empty()) {
            nlohmann::json j = {{"output", output},
                                {"wall_seconds", s.wallSeconds},
                                {"sampling_seconds", s.samplingSeconds},
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
            statsOut << j.dump(2) << "\n";
            statsOut.flush();
            if (!statsOut) throw dsm::Error("cannot write statistics to '" + statsJson + "'");
            statsDone = true;
        }
    } catch (const dsm::Error& e) {
        std::cerr << "dsm-build: ERROR " << e.what() << "\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "dsm-build: ERROR " << e.what() << "\n";
        return 1;
    }
    return 0;
}
