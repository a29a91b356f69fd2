// dsm-farm: builds one map as parts on a render farm and stitches them.
// Documentation: docs/dsm-farm.md.
//
// Uses only libdsm's public API; the library does the work.
#include <dsm/error.h>
#include <dsm/farm.h>
#include <dsm/farm_jobs.h>
#include <dsm/output_file.h>
#include <dsm/sampler.h>
#include <dsm/scene.h>

#include "build_options.h"
#include "option_checks.h"
#include "tool_support.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
constexpr const char* kToolName = "dsm-farm";

/// --tiles N or CxR (columns x rows).
dsm::FarmGrid parseGrid(const std::string& text) {
    std::uint64_t columns = 0, rows = 0;
    const std::size_t x = text.find('x');
    const bool ok = x == std::string::npos
                        ? dsm::tools::parseUnsigned(text, columns)
                        : dsm::tools::parseUnsigned(std::string_view(text).substr(0, x), columns) &&
                              dsm::tools::parseUnsigned(std::string_view(text).substr(x + 1), rows);
    const std::uint64_t count = x == std::string::npos ? columns : columns * rows;
    if (!ok || columns == 0 || (x != std::string::npos && rows == 0) || columns > 65536 || rows > 65536 ||
        count > 65536)
        throw std::invalid_argument("--tiles expects N or CxR (columns x rows), 1 to 65536 parts, got '" + text + "'");
    if (x == std::string::npos) return dsm::farmGridForCount(static_cast<std::uint32_t>(count));
    return {static_cast<std::uint32_t>(columns), static_cast<std::uint32_t>(rows)};
}

std::string regionText(const std::array<std::uint32_t, 4>& r) {
    return std::to_string(r[0]) + "," + std::to_string(r[1]) + "," + std::to_string(r[2]) + "," + std::to_string(r[3]);
}

dsm::Scene loadScene(const std::string& path, std::uint64_t maxSceneMiB) {
    dsm::tools::requireRegularFile(path);
    dsm::SceneReadOptions options;
    options.maxBytes = maxSceneMiB << 20;
    return dsm::loadScene(path, options);
}

std::string absolute(const std::string& path) { return fs::absolute(path).lexically_normal().string(); }

/// The progress of the parts: a line redrawn in place on a terminal, else a
/// line each time a part ends.
class ProgressPrinter {
public:
    explicit ProgressPrinter(bool quiet) : quiet_(quiet), terminal_(::isatty(STDERR_FILENO) != 0) {}
    ~ProgressPrinter() {
        if (drawn_) std::fprintf(stderr, "\n");
    }
    void operator()(const dsm::FarmProgress& p) {
        if (quiet_) return;
        const std::string eta = p.etaSeconds >= 0 ? std::to_string(int(p.etaSeconds + 0.5)) + " s" : "?";
        char line[160];
        std::snprintf(line, sizeof line, "%s: parts %u/%u done, %u running, %u failed, %.1f s elapsed, ETA %s",
                      kToolName, p.done, p.total, p.running, p.failed, p.elapsedSeconds, eta.c_str());
        const std::string counts = std::to_string(p.done) + "/" + std::to_string(p.failed);
        if (terminal_) {
            std::fprintf(stderr, "\r%-100s", line);
            drawn_ = true;
        } else if (counts != lastCounts_) {
            std::fprintf(stderr, "%s\n", line);
        }
        lastCounts_ = counts;
        std::fflush(stderr);
    }

private:
    bool quiet_;
    bool terminal_;
    bool drawn_ = false;
    std::string lastCounts_;
};

/// Prints how a run ended; the exit status.
int reportOutcome(const dsm::FarmOutcome& outcome, const dsm::FarmJob& job, const std::string& output, bool quiet) {
    if (!outcome.failedParts.empty()) {
        std::string list, logs;
        for (const std::uint32_t index : outcome.failedParts) {
            list += (list.empty() ? "" : ", ") + std::to_string(index);
            char log[32];
            std::snprintf(log, sizeof log, "part-%04u.log", index);
            if (logs.empty()) logs = (fs::path(job.logDirectory) / log).string();
        }
        std::cerr << kToolName << ": ERROR " << outcome.failedParts.size() << " of " << job.indices.size()
                  << " parts failed: " << list << " (first log '" << logs << "'); stitch " << outcome.stitchState
                  << "; resubmit them with --indices " << dsm::farmIndexRanges(outcome.failedParts) << "\n";
        return dsm::tools::kExitFailure;
    }
    if (!outcome.stitched) {
        std::cerr << kToolName << ": ERROR the stitch ended " << outcome.stitchState << " (log '"
                  << (fs::path(job.logDirectory) / "stitch.log").string() << "')\n";
        return dsm::tools::kExitFailure;
    }
    if (!quiet) std::cout << kToolName << ": wrote '" << output << "'\n";
    return dsm::tools::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
    using namespace dsm::tools;
    CLI::App app{"dsm-farm: build one deep shadow map as parts on a render farm (Slurm, OpenCue, OpenJD or this "
                 "machine) and stitch them"};
    configureApp(app, kToolName, "docs/dsm-farm.md");
    app.require_subcommand(1);

    // Options shared by the subcommands that read the scene.
    std::string scenePath, tiles, partsDir, output, indicesText;
    BuildOptionText buildText;
    unsigned threads = 0;
    bool quiet = false, json = false;
    const auto sceneOptions = [&](CLI::App* sub) {
        sub->add_option("scene", scenePath, "Scene description (JSON, see spec/scene.md)")->required();
        sub->add_option("--tiles", tiles, "Parts: N, or CxR columns x rows")->required();
        addBuildOptions(*sub, buildText);
    };

    CLI::App* plan = app.add_subcommand("plan", "Print the parts' regions, aligned to map tiles");
    sceneOptions(plan);
    plan->add_flag("--json", json, "Print the plan as JSON");

    std::uint32_t index = 0;
    CLI::App* tile = app.add_subcommand("tile", "Build one part (skipped when it is there and sound)");
    sceneOptions(tile);
    tile->add_option("--index", index, "Part index, 0..parts-1")->required()->check(integerIn(0, 65535));
    tile->add_option("--parts", partsDir, "Directory of the parts (shared by all machines)")->required();
    tile->add_option("-j,--threads", threads, "Worker threads (0 = all cores this process may use)")
        ->check(integerIn(0, UINT32_MAX));
    tile->add_flag("-q,--quiet", quiet, "Print nothing on success");

    CLI::App* stitch = app.add_subcommand("stitch", "Check that every part is there, of one build, and stitch");
    stitch->add_option("parts", partsDir, "Directory of the parts")->required();
    stitch->add_option("-o,--output", output, "Output .dsm file (written atomically)")->required();
    stitch->add_flag("-q,--quiet", quiet, "Print nothing on success");

    std::string engine = "slurm", jobName;
    dsm::SlurmJobOptions slurm;
    std::uint32_t maxRunning = 0;
    bool wait = false, dryRun = false;
    CLI::App* submit = app.add_subcommand("submit", "Run the parts and the stitch through a job engine");
    sceneOptions(submit);
    submit->add_option("-o,--output", output, "The stitched map")->required();
    submit->add_option("--engine", engine, "slurm, local, opencue or openjd")
        ->check(CLI::IsMember({"slurm", "local", "opencue", "openjd"}))
        ->capture_default_str();
    submit->add_option("--parts", partsDir, "Directory of the parts and logs (default: OUTPUT.parts)");
    submit->add_option("--indices", indicesText, "Only these parts, e.g. 5 or 1,3-4 (default: all)");
    submit->add_option("--name", jobName, "Job name (default: dsm-farm-<output name>)");
    submit->add_option("--max-running", maxRunning, "Parts running at once (0: the engine's choice)")
        ->check(integerIn(0, 65536));
    submit->add_option("--partition", slurm.partition, "Slurm partition");
    submit->add_option("--cpus-per-task", slurm.cpusPerTask, "Slurm CPUs per part")->check(integerIn(1, 65536));
    submit->add_option("--mem", slurm.memory, "Slurm memory per part, e.g. 4G");
    submit->add_option("--time", slurm.timeLimit, "Slurm time limit per part, e.g. 2:00:00");
    submit->add_option("-j,--threads", threads, "Worker threads of each part (0 = all cores it may use)")
        ->check(integerIn(0, UINT32_MAX));
    submit->add_flag("--wait", wait, "Slurm: follow the jobs to the end; non-zero when any part or the stitch fails");
    submit->add_flag("--dry-run", dryRun, "Write the job description(s) without submitting");
    submit->add_flag("-q,--quiet", quiet, "No progress; print only the job ids");

    if (const int status = parseArguments(app, argc, argv); status >= 0) return status;

    dsm::BuildOptions options;
    dsm::FarmGrid grid;
    std::vector<std::uint32_t> indices;
    try {
        if (!stitch->parsed()) {
            options = parsedBuildOptions(buildText);
            grid = parseGrid(tiles);
        }
        if (submit->parsed() && (engine == "opencue" || engine == "openjd") && !dryRun)
            throw std::invalid_argument("--engine " + engine +
                                        " only writes the job description for you to submit: add --dry-run");
        if (submit->parsed() && wait && engine != "slurm")
            throw std::invalid_argument("--wait applies to --engine slurm (local always waits)");
    } catch (const std::exception& e) {
        std::cerr << kToolName << ": " << e.what() << "\n";
        return kExitUsage;
    }

    try {
        if (stitch->parsed()) {
            checkOutputs({output}, {});
            const dsm::MergeReport r = dsm::stitchFarmParts(partsDir, output);
            if (!quiet)
                std::cout << kToolName << ": wrote '" << output << "' (" << r.width << "x" << r.height << ", "
                          << r.vertices << " level-0 vertices, " << r.fileBytes << " bytes)\n";
            return kExitOk;
        }

        const dsm::Scene scene = loadScene(scenePath, buildText.maxSceneMiB);
        const dsm::FarmPlan farmPlan = dsm::planFarm(scene, options, grid);

        if (plan->parsed()) {
            if (json) {
                nlohmann::json parts = nlohmann::json::array();
                for (const dsm::FarmPart& p : farmPlan.parts) parts.push_back({{"index", p.index}, {"region", p.region}});
                const nlohmann::json out = {{"width", farmPlan.width},
                                            {"height", farmPlan.height},
                                            {"tile_size", farmPlan.tileSize},
                                            {"columns", farmPlan.grid.columns},
                                            {"rows", farmPlan.grid.rows},
                                            {"parts", parts}};
                std::cout << out.dump(2) << "\n";
            } else {
                std::cout << kToolName << ": " << farmPlan.width << "x" << farmPlan.height << " map, tile size "
                          << farmPlan.tileSize << ", " << farmPlan.grid.columns << "x" << farmPlan.grid.rows
                          << " parts\n";
                for (const dsm::FarmPart& p : farmPlan.parts)
                    std::cout << "  part " << p.index << "  region " << regionText(p.region) << "  ("
                              << (p.region[2] - p.region[0]) << "x" << (p.region[3] - p.region[1]) << ")\n";
            }
            return kExitOk;
        }

        if (tile->parsed()) {
            options.threads = usableThreadsNoted(kToolName, threads, quiet);
            const dsm::FarmPartResult r = dsm::buildFarmPart(scene, options, grid, index, partsDir);
            if (!quiet) {
                const std::string region = regionText(farmPlan.parts.at(index).region);
                if (r.skipped)
                    std::cout << kToolName << ": part " << index << " (region " << region << ") is already in '"
                              << dsm::farmPartPath(partsDir, index) << "', skipped\n";
                else
                    std::cout << kToolName << ": wrote part " << index << " of " << farmPlan.parts.size()
                              << " (region " << region << ") to '" << dsm::farmPartPath(partsDir, index) << "' in "
                              << std::fixed << std::setprecision(2) << r.stats.wallSeconds << " s (process CPU "
                              << double(std::clock()) / CLOCKS_PER_SEC << " s)\n";
            }
            return kExitOk;
        }

        // submit
        checkOutputs({output}, {scenePath});
        if (partsDir.empty()) partsDir = output + ".parts";
        indices = indicesText.empty() ? dsm::parseFarmIndexRanges("0-" + std::to_string(grid.count() - 1), grid.count())
                                      : dsm::parseFarmIndexRanges(indicesText, grid.count());
        const std::string parts = absolute(partsDir);
        fs::create_directories(fs::path(parts) / "logs");
        dsm::FarmJob job;
        job.name = jobName.empty() ? std::string("dsm-farm-") + fs::path(output).stem().string() : jobName;
        job.indices = indices;
        job.logDirectory = (fs::path(parts) / "logs").string();
        const std::string self = fs::read_symlink("/proc/self/exe").string();
        std::uint32_t parallel = maxRunning;
        if (engine == "local" && parallel == 0)
            parallel = std::min<std::uint32_t>(std::max(1u, std::thread::hardware_concurrency()), grid.count());
        if (engine == "local" && threads == 0)
            threads = std::max(1u, std::thread::hardware_concurrency() / std::max(1u, parallel));
        job.partCommand = {self, "tile", absolute(scenePath), "--index", dsm::kFarmIndexArgument, "--parts", parts,
                           "--tiles", std::to_string(grid.columns) + "x" + std::to_string(grid.rows)};
        for (const std::string& arg : buildOptionArguments(options, buildText.maxSceneMiB)) job.partCommand.push_back(arg);
        if (threads) job.partCommand.insert(job.partCommand.end(), {"--threads", std::to_string(threads)});
        job.stitchCommand = {self, "stitch", parts, "-o", absolute(output)};
        slurm.maxRunning = maxRunning;

        if (engine == "opencue" || engine == "openjd") {
            const bool cue = engine == "opencue";
            const std::string file = (fs::path(parts) / (job.name + (cue ? ".outline.py" : ".openjd.yaml"))).string();
            const std::string text = cue ? dsm::openCueOutline(job) : dsm::openJdTemplate(job);
            dsm::OutputFile out(file);
            out.write(text.data(), text.size());
            out.commit();
            std::cout << kToolName << ": wrote the " << (cue ? "OpenCue outline" : "OpenJD template") << " '" << file
                      << "' (" << indices.size() << " parts, then the stitch)\n";
            return kExitOk;
        }
        if (engine == "local") {
            ProgressPrinter progress(quiet);
            const dsm::FarmOutcome outcome =
                dsm::runFarmLocally(job, parallel, [&](const dsm::FarmProgress& p) { progress(p); });
            return reportOutcome(outcome, job, output, quiet);
        }
        if (dryRun) {
            const std::string partScript = (fs::path(parts) / (job.name + "-parts.sbatch")).string();
            const std::string stitchScript = (fs::path(parts) / (job.name + "-stitch.sbatch")).string();
            for (const auto& [file, text] : {std::pair{partScript, dsm::slurmPartScript(job, slurm)},
                                             std::pair{stitchScript, dsm::slurmStitchScript(job, slurm)}}) {
                dsm::OutputFile out(file);
                out.write(text.data(), text.size());
                out.commit();
            }
            std::cout << kToolName << ": wrote '" << partScript << "' and '" << stitchScript << "'; submit with\n"
                      << "  id=$(sbatch --parsable '" << partScript << "')\n"
                      << "  sbatch --dependency=afterok:$id --kill-on-invalid-dep=yes '" << stitchScript << "'\n";
            return kExitOk;
        }
        // When Slurm has forgotten the stitch job, a new output file tells that it ran.
        std::error_code ec;
        const auto outputTime = fs::last_write_time(output, ec);
        const bool outputExisted = !ec;
        const dsm::SlurmSubmission s = dsm::submitSlurm(job, slurm, parts);
        std::cout << (quiet ? "" : "dsm-farm: submitted parts job ") << s.partJobId
                  << (quiet ? "\n" : ", stitch job ") << s.stitchJobId << "\n";
        std::cout.flush();
        if (!wait) return kExitOk;
        ProgressPrinter progress(quiet);
        const dsm::FarmBuildKey key = dsm::farmBuildKey(scene, options, grid);
        const dsm::FarmOutcome outcome = dsm::waitSlurm(
            s, job,
            [&](std::uint32_t i) { return dsm::checkFarmPart(parts, i, key).state == dsm::FarmPartState::Done; },
            [&] {
                std::error_code e;
                const auto t = fs::last_write_time(output, e);
                return !e && (!outputExisted || t != outputTime);
            }, [&](const dsm::FarmProgress& p) { progress(p); });
        return reportOutcome(outcome, job, output, quiet);
    } catch (const std::exception& e) {
        reportException(kToolName, e);
        return kExitFailure;
    }
}
