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
#include <map>
#include <new>
#include <string>
#include <string_view>
#include <system_error>
#include <unistd.h>
#include <vector>

#include <CLI/CLI.hpp>

#include "dsm/error.h"
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

/// `<tool>: ERROR '<file>': <message>`, or `<tool>: ERROR: <message>` for an
/// empty file.
inline std::string errorLine(std::string_view tool, const std::string& file, const std::string& message) {
    if (file.empty()) return oneLine(std::string(tool) + ": ERROR: " + message);
    return oneLine(std::string(tool) + ": ERROR '" + file + "': " + message);
}

/// Prints errorLine() to standard error, after flushing standard output so the
/// two stay in order on a terminal.
inline void reportError(std::string_view tool, const std::string& file, const std::string& message) {
    std::cout.flush();
    std::cerr << errorLine(tool, file, message) << '\n';
}

/// What to print for files whose path is not what the user gave: path ->
/// name. A map or image read from standard input is opened as a temporary copy
/// (InputFile::path()) and printed as "<stdin>" (InputFile::name()).
using DisplayNames = std::map<std::string, std::string>;

/// Adds `input` to `names` when it is printed under another name than its path.
inline void addDisplayName(DisplayNames& names, const InputFile& input) {
    if (input.path() != input.name()) names[input.path()] = input.name();
}

/// Reports an exception as one error line (reportError()). A dsm::Error that
/// names a file is printed as that file and its Error::detail(); anything else
/// as `fallbackFile` (the file the failed step was working on, or empty) and
/// its whole message. A path in `displayNames` is printed under its name, also
/// where the message quotes it (OpenEXR names the file it could not read).
inline void reportException(std::string_view tool, const std::exception& e, const std::string& fallbackFile = {},
                            const DisplayNames& displayNames = {}) {
    std::string file = fallbackFile;
    std::string message = exceptionMessage(e);
    if (const auto* error = dynamic_cast<const dsm::Error*>(&e); error && !error->file().empty()) {
        file = error->file();
        message = error->detail();
    }
    for (const auto& [path, name] : displayNames) {
        if (file == path) file = name;
        for (std::size_t at = message.find(path); at != std::string::npos; at = message.find(path, at + name.size()))
            message.replace(at, path.size(), name);
    }
    reportError(tool, file, message);
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
