// What every dsm-* tool shares: exit codes, the one-line error format, the
// CLI11 conventions (--help to stdout with status 0, --version, usage errors
// to stderr with status 2) and "-" as standard input. Tools only; not part of
// the library's API.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <new>
#include <string>
#include <string_view>
#include <system_error>
#include <unistd.h>
#include <vector>

#include <CLI/CLI.hpp>

#include "dsm/output_file.h"

#include "input_file.h"

#ifndef DSM_TOOLS_VERSION
#define DSM_TOOLS_VERSION "unknown"
#endif

namespace dsm::tools {

/// Exit codes shared by all tools.
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;  ///< a file could not be read, written or checked
constexpr int kExitUsage = 2;    ///< bad arguments

/// Makes a message safe to print as one line.
inline std::string oneLine(std::string s) {
    for (char& c : s)
        if (c == '\n' || c == '\r') c = ' ';
    return s;
}

/// The message to print for an exception. An allocation failure is an input
/// that needs more memory than the process may have (ErrorCode::limit): it is
/// said so in words rather than as "std::bad_alloc".
inline std::string exceptionMessage(const std::exception& e) {
    if (dynamic_cast<const std::bad_alloc*>(&e))
        return "out of memory (the input needs more memory than this process may use)";
    return e.what();
}

/// `<tool>: ERROR '<file>': <message>`. libdsm's messages already start with
/// the quoted file name ("'a.dsm': ..." or "'a.dsm' level 1 tile 0,2: ..."):
/// that prefix is replaced rather than repeated. An empty file gives
/// `<tool>: ERROR: <message>`.
inline std::string errorLine(std::string_view tool, const std::string& file, const std::string& message) {
    if (file.empty()) return oneLine(std::string(tool) + ": ERROR: " + message);
    const std::string quoted = "'" + file + "'";
    std::string_view rest = message;
    if (rest.substr(0, quoted.size()) == quoted) {
        rest.remove_prefix(quoted.size());
        if (rest.substr(0, 2) == ": ") rest.remove_prefix(2);
        else if (rest.substr(0, 1) == " ") rest.remove_prefix(1);
    }
    return oneLine(std::string(tool) + ": ERROR " + quoted + ": " + std::string(rest));
}

/// Prints errorLine() to standard error, after flushing standard output so the
/// two stay in order on a terminal.
inline void reportError(std::string_view tool, const std::string& file, const std::string& message) {
    std::cout.flush();
    std::cerr << errorLine(tool, file, message) << '\n';
}

/// Sets the conventions on a CLI11 app: --version prints "<tool> <version>",
/// a usage error prints "<tool>: <what>" and a hint to standard error.
inline void configureApp(CLI::App& app, std::string_view tool, const std::string& documentation) {
    app.set_version_flag("--version", std::string(tool) + " " + DSM_TOOLS_VERSION);
    app.footer("Documentation: " + documentation);
    const std::string name(tool);
    app.failure_message([name](const CLI::App*, const CLI::Error& e) {
        return name + ": " + e.what() + "\nRun with --help for more information.\n";
    });
}

/// Parses; returns -1 to go on, or the exit status to return at once
/// (kExitOk after --help / --version, kExitUsage after a usage error).
inline int parseArguments(CLI::App& app, int argc, char** argv) {
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e) == 0 ? kExitOk : kExitUsage;
    }
    return -1;
}

/// Refuses, before any work, outputs that cannot be written or would destroy
/// an input: every output is checked (dsm::checkOutputPath), no output is the
/// same file as an input ("-" stands for the file standard input comes from)
/// and no two outputs are the same file. Throws dsm::Error naming the output.
inline void checkOutputs(const std::vector<std::string>& outputs, const std::vector<std::string>& inputs) {
    std::vector<std::string> files;
    for (const std::string& input : inputs) files.push_back(input == "-" ? "/dev/stdin" : input);
    for (const std::string& output : outputs) {
        dsm::checkOutputPath(output);
        dsm::refuseOutputOverInputs(output, files);
    }
    dsm::refuseSharedOutputs(outputs);
}

}  // namespace dsm::tools
