// bench_trade: measures what each knob of a deep shadow map costs in time,
// bytes and error, on the example scenes, and writes the figures as JSON for
// bench/trade_report.py (which writes bench/RESULTS.md and its plots).
// scripts/bench-trade runs both; --smoke is the seconds-long version CI runs.
//
//   bench_trade --out FILE.json [--smoke] [--work-dir DIR] [--scenes A.json,B.json]
//               [--resolution R] [--spp 4,16,...] [--reference-spp N] [--queries Q]
//               [--threads T]
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>

#include "trade.h"

#ifndef DSM_TRADE_EXAMPLES_DIR
#define DSM_TRADE_EXAMPLES_DIR "examples"
#endif

namespace {

using namespace dsm::trade;

std::vector<std::string> splitList(const std::string& text) {
    std::vector<std::string> out;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

std::string cpuModel() {
    std::ifstream in("/proc/cpuinfo");
    for (std::string line; std::getline(in, line);)
        if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
    return "unknown";
}

std::string stem(const std::string& path) {
    const auto slash = path.find_last_of('/');
    std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
    return name.substr(0, name.find('.'));
}

int usage(const char* message) {
    std::fprintf(stderr, "bench_trade: %s\nusage: bench_trade --out FILE.json [--smoke] [--work-dir DIR] "
                         "[--scenes A,B] [--resolution R] [--spp N,N] [--reference-spp N] [--queries Q] "
                         "[--threads T]\n", message);
    return 2;
}

}  // namespace

int main(int argc, char** argv) {
    Config config;
    std::string outPath;
    std::string scenes = std::string(DSM_TRADE_EXAMPLES_DIR) + "/hairball.json," + DSM_TRADE_EXAMPLES_DIR +
                         "/cloud-and-pipes.json";
    std::string sppList, workDir;
    int resolution = -1, referenceSpp = -1, queries = -1;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
            return argv[++i];
        };
        try {
            if (a == "--smoke") config.smoke = true;
            else if (a == "--out") outPath = value();
            else if (a == "--work-dir") workDir = value();
            else if (a == "--scenes") scenes = value();
            else if (a == "--resolution") resolution = std::stoi(value());
            else if (a == "--spp") sppList = value();
            else if (a == "--reference-spp") referenceSpp = std::stoi(value());
            else if (a == "--queries") queries = std::stoi(value());
            else if (a == "--threads") config.threads = static_cast<unsigned>(std::stoul(value()));
            else if (a == "-h" || a == "--help") {
                usage("measures the trade of deep shadow maps (see bench/RESULTS.md)");
                return 0;
            } else return usage(("unknown argument " + a).c_str());
        } catch (const std::exception& e) {
            return usage(e.what());
        }
    }
    if (outPath.empty()) return usage("--out is required");
    if (config.smoke) {
        config.resolution = 16;
        config.spp = {4, 16};
        config.toleranceFactors = {0.0, 1.0, 4.0};
        config.referenceSpp = 64;
        config.referenceTolerance = 0.001;
        config.queries = 500;
        config.tracedQueries = 50;
        config.tracedRaysPerSide = 8;
        config.cacheResolution = 32;
        config.cacheTileSize = 8;
    }
    if (resolution > 0) config.resolution = static_cast<std::uint32_t>(resolution);
    if (referenceSpp > 0) config.referenceSpp = static_cast<std::uint32_t>(referenceSpp);
    if (queries > 0) config.queries = static_cast<std::size_t>(queries);
    if (!sppList.empty()) {
        config.spp.clear();
        for (const auto& s : splitList(sppList)) config.spp.push_back(static_cast<std::uint32_t>(std::stoul(s)));
    }
    config.scenes = splitList(scenes);
    if (config.scenes.empty()) return usage("no scenes");

    const bool ownWorkDir = workDir.empty();
    config.workDir = ownWorkDir ? std::filesystem::temp_directory_path() / ("dsm-trade-" + std::to_string(::getpid()))
                                : std::filesystem::path(workDir);
    std::filesystem::create_directories(config.workDir);

    Json report;
    try {
        const auto start = std::chrono::steady_clock::now();
        const std::time_t now = std::time(nullptr);
        char date[32];
        std::strftime(date, sizeof date, "%Y-%m-%d", std::gmtime(&now));
        report["machine"] = {{"cpu", cpuModel()},
                             {"hardware_threads", std::thread::hardware_concurrency()},
                             {"compiler", __VERSION__},
                             {"date", date}};
        report["smoke"] = config.smoke;
        report["tolerance_spp"] = Json::array();
        std::vector<dsm::Scene> loaded;
        for (const std::string& file : config.scenes) {
            loaded.push_back(dsm::loadScene(file));
            std::printf("tolerance x spp: %s\n", file.c_str());
            report["tolerance_spp"].push_back(studyToleranceAndSpp(config, loaded.back(), stem(file)));
        }
        const std::string first = stem(config.scenes[0]);
        std::printf("deep vs normal shadow maps: %s\n", first.c_str());
        report["deep_vs_normal"] = studyDeepVersusNormal(config, loaded[0], first);
        std::printf("filter width: %s\n", first.c_str());
        report["filter_width"] = studyFilterWidth(config, loaded[0], first);
        std::printf("storage against OpenEXR deep: %s\n", first.c_str());
        report["storage"] = studyStorage(config, loaded[0], first);
        std::printf("cache budget: %s\n", first.c_str());
        report["cache_budget"] = studyCacheBudget(config, loaded[0], first);
        report["total_seconds"] =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_trade: ERROR %s\n", e.what());
        if (ownWorkDir) std::filesystem::remove_all(config.workDir);
        return 1;
    }
    if (ownWorkDir) std::filesystem::remove_all(config.workDir);
    std::ofstream out(outPath);
    out << report.dump(2) << "\n";
    if (!out) {
        std::fprintf(stderr, "bench_trade: ERROR cannot write '%s'\n", outPath.c_str());
        return 1;
    }
    std::printf("wrote %s (%.0f s)\n", outPath.c_str(), report["total_seconds"].get<double>());
    return 0;
}
