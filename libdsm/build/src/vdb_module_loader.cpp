#include "vdb_module_loader.h"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN
namespace {

namespace fs = std::filesystem;

// Where the module may be, in the order vdbModule() tries them.
std::vector<fs::path> moduleCandidates() {
    if (const char* named = std::getenv("DSM_VDB_MODULE"); named && *named) return {fs::path(named)};
    std::vector<fs::path> homes;  // directories of the code running now
    Dl_info info{};
    if (dladdr(reinterpret_cast<const void*>(&moduleCandidates), &info) != 0 && info.dli_fname &&
        fs::path(info.dli_fname).is_absolute())
        homes.push_back(fs::path(info.dli_fname).parent_path());
    std::error_code ec;
    const fs::path program = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) homes.push_back(program.parent_path());
    std::vector<fs::path> candidates;
    for (const fs::path& home : homes) {
        candidates.push_back(home / "dsm" / DSM_VDB_MODULE_FILE);
        candidates.push_back(home / ".." / DSM_INSTALL_LIBDIR / "dsm" / DSM_VDB_MODULE_FILE);
    }
    candidates.push_back(fs::path(DSM_VDB_MODULE_INSTALL_DIR) / DSM_VDB_MODULE_FILE);
    return candidates;
}

struct LoadedModule {
    const DsmVdbModule* module = nullptr;
    std::string failure;  // why none loaded
};

LoadedModule load() {
    LoadedModule loaded;
    std::string tried;
    for (const fs::path& candidate : moduleCandidates()) {
        std::error_code ec;
        if (!fs::is_regular_file(candidate, ec)) {
            tried += (tried.empty() ? "" : ", ") + candidate.lexically_normal().string();
            continue;
        }
        // Kept for the life of the process: its grids and code are in use.
        void* handle = dlopen(candidate.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (!handle) {
            const char* why = dlerror();
            loaded.failure = detail::concat("the OpenVDB module '", candidate.string(), "' does not load: ", why ? why : "");
            return loaded;
        }
        const auto entry = reinterpret_cast<DsmVdbModuleEntry>(dlsym(handle, DSM_VDB_MODULE_ENTRY));
        const DsmVdbModule* module = entry ? entry() : nullptr;
        if (!module || module->version != DSM_VDB_MODULE_VERSION) {
            loaded.failure = detail::concat("'", candidate.string(), "' is not an OpenVDB module of this libdsm (version ",
                                            DSM_VDB_MODULE_VERSION, ")");
            return loaded;
        }
        loaded.module = module;
        return loaded;
    }
    loaded.failure = "the OpenVDB module " DSM_VDB_MODULE_FILE " was not found (looked for " + tried +
                     "; DSM_VDB_MODULE may name it)";
    return loaded;
}

}  // namespace

const DsmVdbModule& vdbModule(const std::string& where, const std::string& file) {
    static const LoadedModule loaded = load();  // once, thread-safe
    if (!loaded.module)
        throw Error(ErrorCode::unsupported, where + ": " + detail::clip(loaded.failure, detail::kMaxQuotedPath), file);
    return *loaded.module;
}

DSM_NAMESPACE_END
