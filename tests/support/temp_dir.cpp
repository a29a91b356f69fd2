#include "temp_dir.h"

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <system_error>

#include <unistd.h>

namespace dsm::test {
namespace {

// FNV-1a over the bytes: names an archived map by its content, so a map
// written by many tests (or by many runs) is kept once.
std::uint64_t contentHash(const std::string& bytes) {
    std::uint64_t hash = 14695981039346656037ull;
    for (const unsigned char byte : bytes) hash = (hash ^ byte) * 1099511628211ull;
    return hash;
}

// When DSM_TEST_MAP_ARCHIVE names a directory, every .dsm file a test leaves
// in its temporary directory is copied there before the directory goes, so
// the independent reader (spec/dsm_reader.py) can afterwards read every map
// the test suite wrote (tests/tools/check_every_map.py). Best effort: an
// archive that cannot be written never fails the test that wrote the map.
void archiveMaps(const std::filesystem::path& directory) {
    const char* archive = std::getenv("DSM_TEST_MAP_ARCHIVE");
    if (archive == nullptr || *archive == '\0') return;
    std::error_code error;
    std::filesystem::create_directories(archive, error);
    for (std::filesystem::recursive_directory_iterator it(directory, error), end; !error && it != end;
         it.increment(error)) {
        if (!it->is_regular_file(error) || it->path().extension() != ".dsm") continue;
        std::ifstream in(it->path(), std::ios::binary);
        const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
        if (!in.good() && !in.eof()) continue;
        char name[32];
        std::snprintf(name, sizeof name, "%016llx.dsm", static_cast<unsigned long long>(contentHash(bytes)));
        const std::filesystem::path target = std::filesystem::path(archive) / name;
        if (std::filesystem::exists(target, error)) continue;
        const std::filesystem::path partial = target.string() + "." + std::to_string(::getpid()) + ".part";
        {
            std::ofstream out(partial, std::ios::binary);
            out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
            if (!out.good()) {
                std::filesystem::remove(partial, error);
                continue;
            }
        }
        std::filesystem::rename(partial, target, error);
    }
}

}  // namespace

TempDir::TempDir() {
    static std::atomic<unsigned> serial{0};
    std::random_device device;
    const std::string name = "dsm-test-" + std::to_string(::getpid()) + "-" + std::to_string(serial++) + "-" +
                             std::to_string(device());
    path_ = std::filesystem::temp_directory_path() / name;
    std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
    archiveMaps(path_);
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
}

}  // namespace dsm::test
