#include "process.h"

#include "dsm/error.h"
#include "text.h"

#include <cerrno>
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace dsm::detail {
namespace {

std::vector<char*> argvOf(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    return argv;
}

int statusOf(int raw) { return WIFEXITED(raw) ? WEXITSTATUS(raw) : 128 + WTERMSIG(raw); }

/// posix_spawn file actions, released at the end of the scope.
struct FileActions {
    posix_spawn_file_actions_t actions;
    FileActions() { posix_spawn_file_actions_init(&actions); }
    ~FileActions() { posix_spawn_file_actions_destroy(&actions); }
};

}  // namespace

CommandResult runCommand(const std::vector<std::string>& args) {
    CommandResult result;
    int pipeEnds[2];
    if (args.empty() || ::pipe2(pipeEnds, O_CLOEXEC) != 0) return result;
    FileActions files;
    posix_spawn_file_actions_adddup2(&files.actions, pipeEnds[1], 1);
    posix_spawn_file_actions_adddup2(&files.actions, pipeEnds[1], 2);
    pid_t pid = 0;
    const int spawned = ::posix_spawnp(&pid, args[0].c_str(), &files.actions, nullptr, argvOf(args).data(), environ);
    ::close(pipeEnds[1]);
    if (spawned != 0) {
        ::close(pipeEnds[0]);
        result.output = concat(args[0], ": cannot be run");
        return result;
    }
    char buffer[4096];
    for (;;) {
        const ssize_t got = ::read(pipeEnds[0], buffer, sizeof buffer);
        if (got > 0) result.output.append(buffer, std::size_t(got));
        else if (got == 0 || errno != EINTR) break;
    }
    ::close(pipeEnds[0]);
    int raw = 0;
    while (::waitpid(pid, &raw, 0) < 0 && errno == EINTR) {
    }
    result.status = statusOf(raw);
    return result;
}

pid_t startCommand(const std::vector<std::string>& args, const std::string& logFile) {
    FileActions files;
    posix_spawn_file_actions_addopen(&files.actions, 1, logFile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&files.actions, 1, 2);
    pid_t pid = 0;
    if (args.empty() ||
        ::posix_spawnp(&pid, args[0].c_str(), &files.actions, nullptr, argvOf(args).data(), environ) != 0)
        throw Error(ErrorCode::io, concat(quotedPath(args.empty() ? "" : args[0]), ": cannot be started (log ",
                                          quotedPath(logFile), ")"));
    return pid;
}

int pollCommand(pid_t pid) {
    int raw = 0;
    pid_t got = 0;
    while ((got = ::waitpid(pid, &raw, WNOHANG)) < 0 && errno == EINTR) {
    }
    if (got == 0) return -2;
    return got < 0 ? -1 : statusOf(raw);
}

}  // namespace dsm::detail
