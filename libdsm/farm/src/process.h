// Child processes for the farm engines: run a command and capture its
// output, or start one logging into a file and wait for it.
#pragma once

#include <string>
#include <vector>

#include <sys/types.h>

namespace dsm::detail {

struct CommandResult {
    int status = -1;     ///< exit status, or 128 + signal; -1 when it could not start
    std::string output;  ///< standard output and standard error together
};

/// Runs argv (looked up on PATH) to its end.
CommandResult runCommand(const std::vector<std::string>& argv);

/// Starts argv with standard output and error into `logFile` (truncated);
/// throws dsm::Error (io) when it cannot start.
pid_t startCommand(const std::vector<std::string>& argv, const std::string& logFile);

/// The exit status of a finished child (as CommandResult::status), or -2
/// while it runs.
int pollCommand(pid_t pid);

}  // namespace dsm::detail
