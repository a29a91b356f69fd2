// The engines this library drives itself: Slurm through its command-line
// clients (sbatch, scontrol), and child processes on this machine.
#include "dsm/error.h"
#include "dsm/farm_jobs.h"
#include "dsm/output_file.h"
#include "process.h"
#include "text.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <sstream>
#include <thread>

DSM_NAMESPACE_BEGIN

using detail::clip;
using detail::concat;

namespace {

using Clock = std::chrono::steady_clock;
constexpr auto kPollInterval = std::chrono::milliseconds(500);

void writeScript(const std::string& path, const std::string& text) {
    OutputFile out(path);
    out.write(text.data(), text.size());
    out.commit();
}

/// sbatch --parsable prints "JOBID" or "JOBID;CLUSTER".
std::string submit(const std::vector<std::string>& argv) {
    const detail::CommandResult r = detail::runCommand(argv);
    std::string id = r.output.substr(0, r.output.find_first_of(";\n"));
    if (r.status != 0 || id.empty() || id.find_first_not_of("0123456789") != std::string::npos)
        throw Error(ErrorCode::io, concat("sbatch failed (status ", r.status, "): ", clip(r.output, 240)));
    return id;
}

enum class TaskState : std::uint8_t { Pending, Running, Done, Failed };

TaskState taskState(const std::string& slurmState) {
    if (slurmState == "COMPLETED") return TaskState::Done;
    if (slurmState == "PENDING" || slurmState == "REQUEUED" || slurmState == "SUSPENDED" ||
        slurmState == "REQUEUE_HOLD" || slurmState == "REQUEUE_FED" || slurmState == "RESV_DEL_HOLD")
        return TaskState::Pending;
    if (slurmState == "RUNNING" || slurmState == "CONFIGURING" || slurmState == "COMPLETING" ||
        slurmState == "STAGE_OUT" || slurmState == "SIGNALING" || slurmState == "RESIZING")
        return TaskState::Running;
    return TaskState::Failed;  // FAILED, CANCELLED, TIMEOUT, NODE_FAIL, OUT_OF_MEMORY, BOOT_FAIL, DEADLINE, ...
}

/// The value of `Key=` in one line of `scontrol -o show job`.
std::string field(const std::string& line, const std::string& key) {
    const std::string needle = key + "=";
    std::size_t at = 0;
    while ((at = line.find(needle, at)) != std::string::npos) {
        if (at == 0 || line[at - 1] == ' ') {
            const std::size_t start = at + needle.size();
            return line.substr(start, line.find(' ', start) - start);
        }
        at += needle.size();
    }
    return {};
}

/// Indices of an ArrayTaskId value: "3", "4-15", "4-15%2", "1,3-5".
std::vector<std::uint32_t> arrayIndices(std::string text) {
    text = text.substr(0, text.find('%'));
    std::vector<std::uint32_t> out;
    std::istringstream items(text);
    std::string item;
    while (std::getline(items, item, ',')) {
        unsigned first = 0, last = 0;
        const int got = std::sscanf(item.c_str(), "%u-%u", &first, &last);
        if (got < 1) continue;
        if (got == 1) last = first;
        for (unsigned i = first; i <= last && i - first < 1'000'000; ++i) out.push_back(i);
    }
    return out;
}

/// The state of each listed task of `jobId`; empty when Slurm no longer knows
/// the job (gone after MinJobAge); nothing when scontrol failed otherwise (the
/// controller busy or restarting: ask again).
std::optional<std::map<std::uint32_t, std::string>> jobStates(const std::string& jobId, bool array) {
    std::map<std::uint32_t, std::string> states;
    const detail::CommandResult r = detail::runCommand({"scontrol", "-o", "show", "job", jobId});
    if (r.status != 0) {
        if (r.output.find("Invalid job id") != std::string::npos) return states;
        return std::nullopt;
    }
    std::istringstream lines(r.output);
    std::string line;
    while (std::getline(lines, line)) {
        const std::string state = field(line, "JobState");
        if (state.empty()) continue;
        if (!array) {
            states[0] = state;
            continue;
        }
        for (const std::uint32_t index : arrayIndices(field(line, "ArrayTaskId"))) states[index] = state;
    }
    return states;
}

/// jobStates(), asked again while scontrol fails, for at most a minute.
std::map<std::uint32_t, std::string> jobStatesRetried(const std::string& jobId, bool array) {
    constexpr int kAttempts = 120;
    for (int attempt = 1;; ++attempt) {
        if (auto states = jobStates(jobId, array)) return *states;
        if (attempt == kAttempts) {
            const detail::CommandResult r = detail::runCommand({"scontrol", "-o", "show", "job", jobId});
            throw Error(ErrorCode::io, concat("scontrol cannot show job ", jobId, " for a minute: ",
                                              clip(r.output, 240)));
        }
        std::this_thread::sleep_for(kPollInterval);
    }
}

FarmProgress progressOf(const std::map<std::uint32_t, TaskState>& tasks, Clock::time_point start,
                        const FarmProgress& total) {
    FarmProgress p = total;
    for (const auto& [index, state] : tasks) {
        p.done += state == TaskState::Done;
        p.running += state == TaskState::Running;
        p.failed += state == TaskState::Failed;
    }
    p.elapsedSeconds = std::chrono::duration<double>(Clock::now() - start).count();
    const std::uint32_t finished = p.done + p.failed;
    p.etaSeconds = finished ? p.elapsedSeconds * double(p.total - finished) / double(finished) : -1.0;
    return p;
}

}  // namespace

SlurmSubmission submitSlurm(const FarmJob& job, const SlurmJobOptions& options, const std::string& scriptDirectory) {
    const std::string partScript = (std::filesystem::path(scriptDirectory) / (job.name + "-parts.sbatch")).string();
    const std::string stitchScript = (std::filesystem::path(scriptDirectory) / (job.name + "-stitch.sbatch")).string();
    writeScript(partScript, slurmPartScript(job, options));
    writeScript(stitchScript, slurmStitchScript(job, options));
    SlurmSubmission s;
    s.partJobId = submit({"sbatch", "--parsable", partScript});
    s.stitchJobId = submit({"sbatch", "--parsable", "--dependency=afterok:" + s.partJobId,
                            "--kill-on-invalid-dep=yes", stitchScript});
    return s;
}

FarmOutcome waitSlurm(const SlurmSubmission& submission, const FarmJob& job,
                      const std::function<bool(std::uint32_t)>& isPartDone, const std::function<bool()>& isStitched,
                      const std::function<void(const FarmProgress&)>& progress) {
    const Clock::time_point start = Clock::now();
    FarmProgress total;
    total.total = static_cast<std::uint32_t>(job.indices.size());
    std::map<std::uint32_t, TaskState> tasks;
    for (;;) {
        const auto states = jobStatesRetried(submission.partJobId, true);
        bool finished = true;
        for (const std::uint32_t index : job.indices) {
            const auto it = states.find(index);
            // A task Slurm no longer lists has ended: its files tell how.
            const TaskState state = it != states.end() ? taskState(it->second)
                                    : isPartDone(index) ? TaskState::Done
                                                        : TaskState::Failed;
            tasks[index] = state;
            finished = finished && (state == TaskState::Done || state == TaskState::Failed);
        }
        if (progress) progress(progressOf(tasks, start, total));
        if (finished) break;
        std::this_thread::sleep_for(kPollInterval);
    }
    FarmOutcome outcome;
    for (const auto& [index, state] : tasks)
        if (state == TaskState::Failed) outcome.failedParts.push_back(index);
    // The stitch ends soon after the parts: it runs, or is cancelled because
    // its dependency can never be met.
    for (;;) {
        const auto states = jobStatesRetried(submission.stitchJobId, false);
        if (states.empty()) {
            outcome.stitched = isStitched();
            outcome.stitchState = outcome.stitched ? "COMPLETED" : "UNKNOWN";
            break;
        }
        const std::string& state = states.begin()->second;
        const TaskState s = taskState(state);
        if (s == TaskState::Done || s == TaskState::Failed) {
            outcome.stitched = s == TaskState::Done;
            outcome.stitchState = state;
            break;
        }
        std::this_thread::sleep_for(kPollInterval);
    }
    return outcome;
}

FarmOutcome runFarmLocally(const FarmJob& job, std::uint32_t parallel,
                           const std::function<void(const FarmProgress&)>& progress) {
    const Clock::time_point start = Clock::now();
    FarmProgress total;
    total.total = static_cast<std::uint32_t>(job.indices.size());
    std::map<std::uint32_t, TaskState> tasks;
    std::map<std::uint32_t, pid_t> running;
    std::size_t next = 0;
    const auto logFile = [&](const std::string& name) {
        return (std::filesystem::path(job.logDirectory) / name).string();
    };
    FarmOutcome outcome;
    while (next < job.indices.size() || !running.empty()) {
        while (next < job.indices.size() && running.size() < std::max<std::uint32_t>(parallel, 1)) {
            const std::uint32_t index = job.indices[next++];
            std::vector<std::string> argv = job.partCommand;
            for (std::string& arg : argv)
                if (arg == kFarmIndexArgument) arg = std::to_string(index);
            char name[32];
            std::snprintf(name, sizeof name, "part-%04u.log", index);
            try {
                running[index] = detail::startCommand(argv, logFile(name));
                tasks[index] = TaskState::Running;
            } catch (const Error&) {
                tasks[index] = TaskState::Failed;
            }
        }
        bool changed = false;
        for (auto it = running.begin(); it != running.end();) {
            const int status = detail::pollCommand(it->second);
            if (status == -2) {
                ++it;
                continue;
            }
            tasks[it->first] = status == 0 ? TaskState::Done : TaskState::Failed;
            it = running.erase(it);
            changed = true;
        }
        if (progress) progress(progressOf(tasks, start, total));
        if (!changed) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    for (const auto& [index, state] : tasks)
        if (state == TaskState::Failed) outcome.failedParts.push_back(index);
    if (!outcome.failedParts.empty()) {
        outcome.stitchState = "NOT RUN";
        return outcome;
    }
    const pid_t stitch = detail::startCommand(job.stitchCommand, logFile("stitch.log"));
    int status = -2;
    while ((status = detail::pollCommand(stitch)) == -2) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    outcome.stitched = status == 0;
    outcome.stitchState = outcome.stitched ? "COMPLETED" : concat("FAILED (status ", status, ")");
    return outcome;
}

DSM_NAMESPACE_END
