// dsm-view: looks inside deep shadow maps in a web browser. Serves a page and
// the pictures, pixel functions and tile statistics of the maps named on the
// command line, on the loopback address unless told otherwise.
// Documentation: docs/dsm-view.md.
//
// The pictures come from libdsm (map_images.h, soft_shadow_image.h); the HTTP
// side is view_server.cpp; the page is tools/dsm_view/page/, built in.
#include <csignal>
#include <exception>
#include <iostream>
#include <memory>
#include <spawn.h>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "dsm/error.h"
#include "dsm/reader.h"
#include "option_checks.h"
#include "tool_support.h"
#include "view_server.h"

extern char** environ;

namespace {

namespace tools = dsm::tools;

constexpr const char* kToolName = "dsm-view";

/// Starts the desktop's browser on `url` without waiting for it (xdg-open,
/// else Debian's sensible-browser or x-www-browser); false when there is none.
bool openBrowser(const std::string& url) {
    std::signal(SIGCHLD, SIG_IGN);  // the launcher is reaped, never a zombie
    for (std::string command : {"xdg-open", "sensible-browser", "x-www-browser"}) {
        char* args[] = {command.data(), const_cast<char*>(url.c_str()), nullptr};
        pid_t pid = 0;
        if (posix_spawnp(&pid, command.c_str(), nullptr, nullptr, args, environ) == 0) return true;
    }
    return false;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> files;
    std::string host = "127.0.0.1";
    unsigned port = 0;
    bool open = false;
    CLI::App app{"Look inside deep shadow maps in a web browser: pictures of any level (opacity, depth slices, "
                 "vertex and layer counts, tiles, soft shadows), each pixel's visibility function, and two maps "
                 "side by side or their difference. Serves only the maps given, on 127.0.0.1 unless --host says "
                 "otherwise; stops on Ctrl-C.",
                 kToolName};
    app.add_option("MAP", files, "One or two deep shadow map (.dsm) files")->required()->expected(1, 2)->type_name("");
    app.add_option("--host", host, "Address to listen on (default 127.0.0.1, this machine only)")->type_name("ADDR");
    app.add_option("--port", port, "Port to listen on; 0 or none picks a free one")
        ->type_name("P")
        ->check(tools::integerIn(0, 65535));
    app.add_flag("--open", open, "Open the page in the desktop's web browser");
    tools::configureApp(app, kToolName, "docs/dsm-view.md");
    app.footer("Prints the page's URL once it listens. Exit status: 0 after Ctrl-C, 1 when a map cannot be read "
               "or the address cannot be bound, 2 on a usage error.\nDocumentation: docs/dsm-view.md");
    if (const int status = tools::parseArguments(app, argc, argv); status >= 0) return status;

    std::vector<tools::ViewedMap> maps;
    for (const std::string& file : files) {
        try {
            if (file == "-") throw dsm::Error(dsm::ErrorCode::argument, "standard input cannot be viewed; name a file");
            maps.push_back({file, dsm::DeepShadowMap::open(file)});
        } catch (const std::exception& e) {
            tools::reportException(kToolName, e, file);
            return tools::kExitFailure;
        }
    }
    const bool served = tools::serveMaps(maps, host, static_cast<int>(port), [&](const std::string& url) {
        std::cout << kToolName << ": " << url << '\n' << std::flush;
        if (open && !openBrowser(url))
            std::cerr << kToolName << ": note: no browser could be started (no xdg-open, sensible-browser or x-www-browser); open " << url
                      << " yourself\n";
    });
    if (!served) {
        std::cerr << tools::errorLine(kToolName, "",
                                      "cannot listen on " + host + (port ? ":" + std::to_string(port) : ""))
                  << '\n';
        return tools::kExitFailure;
    }
    return tools::kExitOk;
}
