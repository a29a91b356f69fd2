#include "temp_dir.h"

#include <atomic>
#include <random>
#include <string>
#include <system_error>

#include <unistd.h>

namespace dsm::test {

TempDir::TempDir() {
    static std::atomic<unsigned> serial{0};
    std::random_device device;
    const std::string name = "dsm-test-" + std::to_string(::getpid()) + "-" + std::to_string(serial++) + "-" +
                             std::to_string(device());
    path_ = std::filesystem::temp_directory_path() / name;
    std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
}

}  // namespace dsm::test
