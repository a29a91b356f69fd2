// Attaching the file a caller named to the errors raised below an entry point (internal).
#pragma once

#include <string>
#include <vector>

#include "dsm/error.h"

namespace dsm::detail {

/// Runs `action` and returns what it returns; a dsm::Error it throws whose
/// message starts with `file` quoted leaves carrying that file
/// (Error::withFile). Entry points that take a path wrap their work in it, so
/// the many throw sites below only have to quote the file in the message.
template <class Action>
decltype(auto) namingFile(const std::string& file, Action&& action) {
    try {
        return action();
    } catch (const Error& e) {
        throw e.withFile(file);
    }
}

/// `error` carrying the first of `files` that its message starts with
/// (Error::withFile): for an entry point that takes several files (inputs and
/// an output).
inline Error withOneOf(const Error& error, const std::vector<std::string>& files) {
    for (const std::string& file : files) {
        Error named = error.withFile(file);
        if (!named.file().empty()) return named;
    }
    return error;
}

/// namingFile() for several files (withOneOf()).
template <class Action>
decltype(auto) namingFiles(const std::vector<std::string>& files, Action&& action) {
    try {
        return action();
    } catch (const Error& e) {
        throw withOneOf(e, files);
    }
}

}  // namespace dsm::detail
