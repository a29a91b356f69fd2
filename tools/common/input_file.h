// Input files of the dsm-* tools: only regular files are opened (a FIFO or a
// device would block or never end), and "-" is standard input, copied to an
// unlinked temporary file up to a bounded size. Tools only.
#pragma once

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dsm/error.h"

namespace dsm::tools {

/// Refuses a path that exists but is not a regular file (a FIFO, a device, a
/// directory, a socket) without opening it: opening a FIFO blocks until a
/// writer comes, and a device such as /dev/zero never ends. A path that does
/// not exist is left for the opener to report.
inline void requireRegularFile(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return;
    if (S_ISDIR(st.st_mode)) throw Error(ErrorCode::io, "'" + path + "': is a directory, not a regular file", path);
    if (!S_ISREG(st.st_mode)) throw Error(ErrorCode::io, "'" + path + "': not a regular file", path);
}

/// Bytes of standard input a tool copies before giving up, unless the
/// environment variable DSM_STDIN_LIMIT says otherwise.
constexpr std::uint64_t kDefaultStdinLimit = std::uint64_t{4} << 30;  // 4 GiB
constexpr const char* kStdinLimitVariable = "DSM_STDIN_LIMIT";

/// A byte count: digits with an optional binary suffix K, M, G or T (KiB ...).
/// Throws dsm::Error(argument) for anything else, or 0.
inline std::uint64_t parseByteCount(std::string_view text, std::string_view what) {
    std::uint64_t value = 0;
    std::size_t i = 0;
    const auto bad = [&] {
        return Error(ErrorCode::argument, std::string(what) + ": expected a byte count > 0 such as 512M or 4G, got '" +
                                              std::string(text.substr(0, 32)) + "'");
    };
    for (; i < text.size() && text[i] >= '0' && text[i] <= '9'; ++i) {
        if (value > (UINT64_MAX - 9) / 10) throw bad();
        value = value * 10 + static_cast<std::uint64_t>(text[i] - '0');
    }
    if (i == 0) throw bad();
    if (i < text.size()) {
        const std::string_view suffixes = "KMGT";
        const std::size_t power = suffixes.find(text[i]);
        if (power == std::string_view::npos || i + 1 != text.size()) throw bad();
        const unsigned shift = 10 * static_cast<unsigned>(power + 1);
        if (value > (UINT64_MAX >> shift)) throw bad();
        value <<= shift;
    }
    if (value == 0) throw bad();
    return value;
}

/// The most bytes of standard input to copy: DSM_STDIN_LIMIT, or 4 GiB.
inline std::uint64_t stdinLimit() {
    const char* text = std::getenv(kStdinLimitVariable);
    return text ? parseByteCount(text, kStdinLimitVariable) : kDefaultStdinLimit;
}

/// "4 GiB", "512 MiB", "1000 bytes": a limit as the user would write it.
inline std::string limitText(std::uint64_t bytes) {
    const char* units[] = {"bytes", "KiB", "MiB", "GiB", "TiB"};
    int unit = 0;
    while (unit < 4 && bytes % 1024 == 0 && bytes >= 1024) {
        bytes /= 1024;
        ++unit;
    }
    return std::to_string(bytes) + " " + units[unit];
}

/// A file argument that may be "-" (standard input). Library readers need a
/// seekable file, so standard input is copied, at most stdinLimit() bytes, to
/// a temporary file that is unlinked as soon as it is created: nothing is left
/// in the temporary directory however the tool ends. The library opens the
/// copy through /proc/self/fd while this object holds it. path() is what to
/// open; name() is what to print in messages ("<stdin>" for "-"). Any other
/// argument must be a regular file (requireRegularFile()).
class InputFile {
public:
    explicit InputFile(const std::string& argument) : name_(argument), path_(argument) {
        if (argument != "-") {
            requireRegularFile(argument);
            return;
        }
        name_ = "<stdin>";
        const std::uint64_t limit = stdinLimit();
        std::string pattern = (std::filesystem::temp_directory_path() / "dsm-stdin-XXXXXX").string();
        copy_.fd = ::mkstemp(pattern.data());
        if (copy_.fd < 0) throw failure("cannot create a temporary file for it");
        ::unlink(pattern.c_str());
        path_ = "/proc/self/fd/" + std::to_string(copy_.fd);

        char buffer[1 << 16];
        std::uint64_t total = 0;
        for (;;) {
            const ssize_t got = ::read(STDIN_FILENO, buffer, sizeof buffer);
            if (got < 0 && errno == EINTR) continue;
            if (got < 0) throw failure("cannot read");
            if (got == 0) break;
            total += static_cast<std::uint64_t>(got);
            if (total > limit)
                throw Error(ErrorCode::limit, "'<stdin>': longer than the limit of " + limitText(limit) +
                                                  " (set " + kStdinLimitVariable +
                                                  " to raise it, or give the file's path)",
                            name_);
            for (ssize_t done = 0; done < got;) {
                const ssize_t put = ::write(copy_.fd, buffer + done, static_cast<std::size_t>(got - done));
                if (put < 0 && errno == EINTR) continue;
                if (put < 0) throw failure("cannot copy it to a temporary file");
                done += put;
            }
        }
        if (total == 0) throw Error(ErrorCode::format, "'<stdin>': empty (no file on standard input)", name_);
    }
    InputFile(const InputFile&) = delete;
    InputFile& operator=(const InputFile&) = delete;

    const std::string& path() const { return path_; }
    const std::string& name() const { return name_; }

private:
    /// Closes the copy when the object goes away, also when the constructor
    /// throws (a member's destructor runs then; the object's does not).
    struct Descriptor {
        int fd = -1;
        ~Descriptor() {
            if (fd >= 0) ::close(fd);
        }
    };

    static Error failure(const std::string& what) {
        return Error(ErrorCode::io, "'<stdin>': " + what + ": " + std::strerror(errno), "<stdin>");
    }

    Descriptor copy_;
    std::string name_;
    std::string path_;
};

}  // namespace dsm::tools
