// A uniquely named temporary directory, removed with everything in it when
// the object goes away. Tests that touch files work only inside one.
#pragma once

#include <filesystem>

namespace dsm::test {

class TempDir {
public:
    TempDir();
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    const std::filesystem::path& path() const { return path_; }
    std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

private:
    std::filesystem::path path_;
};

}  // namespace dsm::test
