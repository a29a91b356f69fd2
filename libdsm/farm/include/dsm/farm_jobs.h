// Running a farm build through a job engine: the per-part command line every
// engine runs (one "frame" per part index), the job descriptions for Slurm,
// OpenCue and Open Job Description, and the engines this library drives
// itself (Slurm's command-line clients, and local processes).
// The user-facing description: docs/dsm-farm.md.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// The argument that stands for the part index in FarmJob::partCommand; each
/// engine puts its own frame variable there.
inline constexpr const char* kFarmIndexArgument = "{index}";

struct FarmJob {
    std::string name;                         ///< job name (letters, digits, '-', '_', '.')
    std::vector<std::string> partCommand;     ///< argv of one part, kFarmIndexArgument for the index
    std::vector<std::string> stitchCommand;   ///< argv of the stitch
    std::vector<std::uint32_t> indices;       ///< the parts to run, ascending, no repeats
    std::string logDirectory;                 ///< absolute; logs part-NNNN.log and stitch.log
};

/// Compact index list, "0-15" or "1,3-5,9" (Slurm's --array and OpenCue's
/// frame ranges both take it).
DSM_API std::string farmIndexRanges(const std::vector<std::uint32_t>& indices);
/// Parses such a list (also "7"); throws dsm::Error (argument) on a malformed
/// list or an index >= count. The result is ascending without repeats.
DSM_API std::vector<std::uint32_t> parseFarmIndexRanges(const std::string& text, std::uint32_t count);

struct SlurmJobOptions {
    std::uint32_t maxRunning = 0;  ///< parts running at once; 0 = no limit
    std::string partition;         ///< empty: the cluster's default
    std::uint32_t cpusPerTask = 0; ///< 0: the cluster's default
    std::string memory;            ///< --mem, e.g. "4G"; empty: the default
    std::string timeLimit;         ///< --time, e.g. "2:00:00"; empty: the default
};

/// The batch script of the parts' array job and of the stitch job (which is
/// submitted with a dependency on the array job's success).
DSM_API std::string slurmPartScript(const FarmJob& job, const SlurmJobOptions& options);
DSM_API std::string slurmStitchScript(const FarmJob& job, const SlurmJobOptions& options);
/// An OpenCue outline (Python, run with OpenCue's pycuerun or python): a
/// "parts" shell layer over the frame range and a "stitch" layer depending on
/// all of it.
DSM_API std::string openCueOutline(const FarmJob& job);
/// An Open Job Description template (YAML, jobtemplate-2023-09): a "parts"
/// step with an INT task parameter over the indices and a "stitch" step that
/// depends on it.
DSM_API std::string openJdTemplate(const FarmJob& job);

/// How the parts stand, reported while waiting.
struct FarmProgress {
    std::uint32_t total = 0;
    std::uint32_t done = 0;
    std::uint32_t running = 0;
    std::uint32_t failed = 0;
    double elapsedSeconds = 0.0;
    /// Time left from the rate of finished parts; negative when unknown.
    double etaSeconds = -1.0;
};

struct FarmOutcome {
    std::vector<std::uint32_t> failedParts;  ///< indices, ascending
    bool stitched = false;                   ///< the stitch ran and succeeded
    std::string stitchState;                 ///< the engine's word for how the stitch ended
};

struct SlurmSubmission {
    std::string partJobId;
    std::string stitchJobId;
};

/// Writes the two scripts into `scriptDirectory` and submits them with
/// sbatch: the array job, then the stitch with --dependency=afterok on it and
/// --kill-on-invalid-dep=yes (so a failed part cancels the stitch). Throws
/// dsm::Error (io) with sbatch's message when a submission fails.
DSM_API SlurmSubmission submitSlurm(const FarmJob& job, const SlurmJobOptions& options,
                                    const std::string& scriptDirectory);

/// Follows a submission to its end with `scontrol -o show job`, calling
/// `progress` when the counts change and every few seconds. A job that has
/// left scontrol's memory (MinJobAge) is judged by `isPartDone` (the part's
/// files) and the stitch by `isStitched`.
DSM_API FarmOutcome waitSlurm(const SlurmSubmission& submission, const FarmJob& job,
                              const std::function<bool(std::uint32_t)>& isPartDone,
                              const std::function<bool()>& isStitched,
                              const std::function<void(const FarmProgress&)>& progress);

/// Runs the parts' commands as child processes on this machine, `parallel` at
/// a time (at least 1), each logging into the log directory, then the stitch
/// when every part succeeded.
DSM_API FarmOutcome runFarmLocally(const FarmJob& job, std::uint32_t parallel,
                                   const std::function<void(const FarmProgress&)>& progress);

DSM_NAMESPACE_END
