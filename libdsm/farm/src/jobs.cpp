// The job descriptions of a farm build: Slurm batch scripts, an OpenCue
// outline and an Open Job Description template, all running the same
// per-part command line.
#include "dsm/error.h"
#include "dsm/farm_jobs.h"
#include "text.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <charconv>

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

/// `text` quoted for a POSIX shell.
std::string shellQuoted(const std::string& text) {
    std::string out = "'";
    for (const char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

/// A double-quoted string literal that Python and YAML both read back as
/// `text` (JSON's escapes, non-ASCII as \u escapes, are valid in both).
std::string quotedLiteral(const std::string& text) {
    return nlohmann::json(text).dump(-1, ' ', true, nlohmann::json::error_handler_t::replace);
}

/// argv as shell words, the index argument replaced by `index` (unquoted).
std::string shellCommand(const std::vector<std::string>& argv, const std::string& index) {
    std::string out;
    for (const std::string& arg : argv) out += (out.empty() ? "" : " ") + (arg == kFarmIndexArgument ? index : shellQuoted(arg));
    return out;
}

/// argv as a list of string literals, the index argument replaced by `index`.
std::string literalList(const std::vector<std::string>& argv, const std::string& index, std::size_t from = 0) {
    std::string out = "[";
    for (std::size_t i = from; i < argv.size(); ++i)
        out += (i == from ? "" : ", ") + quotedLiteral(argv[i] == kFarmIndexArgument ? index : argv[i]);
    return out + "]";
}

std::string slurmHeader(const SlurmJobOptions& options) {
    std::string out;
    if (!options.partition.empty()) out += "#SBATCH --partition=" + options.partition + "\n";
    if (options.cpusPerTask) out += concat("#SBATCH --cpus-per-task=", options.cpusPerTask, "\n");
    if (!options.memory.empty()) out += "#SBATCH --mem=" + options.memory + "\n";
    if (!options.timeLimit.empty()) out += "#SBATCH --time=" + options.timeLimit + "\n";
    return out;
}

void requireCommands(const FarmJob& job) {
    if (job.partCommand.empty() || job.stitchCommand.empty() || job.indices.empty())
        throw Error(ErrorCode::argument, "farm job '" + job.name + "': no command or no parts");
}

}  // namespace

std::string farmIndexRanges(const std::vector<std::uint32_t>& indices) {
    std::string out;
    for (std::size_t i = 0; i < indices.size();) {
        std::size_t j = i;
        while (j + 1 < indices.size() && indices[j + 1] == indices[j] + 1) ++j;
        if (!out.empty()) out += ',';
        out += std::to_string(indices[i]);
        if (j > i) out += concat("-", indices[j]);
        i = j + 1;
    }
    return out;
}

std::vector<std::uint32_t> parseFarmIndexRanges(const std::string& text, std::uint32_t count) {
    std::vector<std::uint32_t> indices;
    const auto bad = [&](const std::string& why) {
        return Error(ErrorCode::argument, concat("farm: index list '", detail::clip(text), "': ", why));
    };
    const auto number = [&](std::string_view s) {
        std::uint32_t value = 0;
        const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
        if (s.empty() || ec != std::errc() || end != s.data() + s.size())
            throw bad("expected indices or ranges A-B separated by commas");
        if (value >= count) throw bad(concat("index ", value, " is outside the ", count, " parts"));
        return value;
    };
    std::size_t start = 0;
    while (start <= text.size()) {
        const std::size_t end = std::min(text.find(',', start), text.size());
        const std::string_view item = std::string_view(text).substr(start, end - start);
        const std::size_t dash = item.find('-');
        const std::uint32_t first = number(item.substr(0, dash));
        const std::uint32_t last = dash == std::string_view::npos ? first : number(item.substr(dash + 1));
        if (last < first) throw bad(concat("range ", first, "-", last, " runs backwards"));
        for (std::uint32_t i = first; i <= last; ++i) indices.push_back(i);
        start = end + 1;
    }
    std::sort(indices.begin(), indices.end());
    indices.erase(std::unique(indices.begin(), indices.end()), indices.end());
    return indices;
}

std::string slurmPartScript(const FarmJob& job, const SlurmJobOptions& options) {
    requireCommands(job);
    return concat("#!/bin/sh\n", "# The parts of the farm build ", job.name, ": one array task per part index.\n",
                  "#SBATCH --job-name=", job.name, "-parts\n", "#SBATCH --array=", farmIndexRanges(job.indices),
                  options.maxRunning ? concat("%", options.maxRunning) : std::string(), "\n",
                  "#SBATCH --output=", job.logDirectory, "/part-%4a.log\n", slurmHeader(options),
                  "exec ", shellCommand(job.partCommand, "\"$SLURM_ARRAY_TASK_ID\""), "\n");
}

std::string slurmStitchScript(const FarmJob& job, const SlurmJobOptions& options) {
    requireCommands(job);
    SlurmJobOptions one = options;
    one.cpusPerTask = 0;  // the stitch is one thread
    return concat("#!/bin/sh\n", "# The stitch of the farm build ", job.name, ", after every part succeeded.\n",
                  "#SBATCH --job-name=", job.name, "-stitch\n", "#SBATCH --output=", job.logDirectory,
                  "/stitch.log\n", slurmHeader(one), "exec ", shellCommand(job.stitchCommand, ""), "\n");
}

std::string openCueOutline(const FarmJob& job) {
    requireCommands(job);
    return concat("# OpenCue outline of the farm build ", job.name, ", written by dsm-farm.\n",
                  "# Submit it with OpenCue's pyoutline configured: python3 <this file>\n",
                  "from outline import Outline, cuerun\n", "from outline.modules.shell import Shell\n\n",
                  "outline = Outline(", quotedLiteral(job.name), ")\n",
                  "parts = Shell(\"parts\", command=", literalList(job.partCommand, "#IFRAME#"), ", range=",
                  quotedLiteral(farmIndexRanges(job.indices)), ", chunk=1)\n",
                  "stitch = Shell(\"stitch\", command=", literalList(job.stitchCommand, ""), ", range=\"0\")\n",
                  "stitch.depend_all(parts)\n", "outline.add_layer(parts)\n", "outline.add_layer(stitch)\n\n",
                  "if __name__ == \"__main__\":\n", "    cuerun.launch(outline, use_pycuerun=False)\n");
}

std::string openJdTemplate(const FarmJob& job) {
    requireCommands(job);
    const auto action = [](const std::vector<std::string>& argv, const std::string& index) {
        return concat("    script:\n      actions:\n        onRun:\n          command: ", quotedLiteral(argv[0]),
                      "\n          args: ", literalList(argv, index, 1), "\n");
    };
    return concat("# Open Job Description template of the farm build ", job.name, ", written by dsm-farm.\n",
                  "specificationVersion: jobtemplate-2023-09\n", "name: ", quotedLiteral(job.name), "\n",
                  "steps:\n", "  - name: parts\n", "    parameterSpace:\n", "      taskParameterDefinitions:\n",
                  "        - name: Index\n", "          type: INT\n", "          range: ",
                  quotedLiteral(farmIndexRanges(job.indices)), "\n", action(job.partCommand, "{{Task.Param.Index}}"),
                  "  - name: stitch\n", "    dependencies:\n", "      - dependsOn: parts\n",
                  action(job.stitchCommand, ""));
}

DSM_NAMESPACE_END
