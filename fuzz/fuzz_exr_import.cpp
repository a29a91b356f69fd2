// libFuzzer target: the input bytes as a deep OpenEXR file, imported with
// dsm::importDeepExr() into a map. The import must either succeed, writing a
// map that dsm::validate() accepts, or throw dsm::Error and leave no file
// behind. Anything else, a crash, a hang, a sanitizer report, a leak, an
// allocation over the run's -malloc_limit_mb or an exception of another type
// (OpenEXR's own, std::bad_alloc), is a finding. Built by fuzz/CMakeLists.txt.
//
// OpenEXR itself is not instrumented: ASan sees its allocations (the limits)
// and its memory errors on the heap, not its branches.
#include <dsm/error.h>
#include <dsm/exr_deep.h>
#include <dsm/reader.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "scratch_file.h"

namespace {

/// Inputs whose display window holds more pixels are skipped: the importer
/// accepts maps up to 131072 pixels wide and would spend the run writing one
/// (the size of the output, not a fault). The library's own bound on the
/// window is covered by tests/test_exr_deep.cpp.
constexpr std::uint64_t kMaxFuzzPixels = 256 * 256;

/// The display window of the file's first header, read from the attribute
/// list (OpenEXR's documented layout: magic, version, then name\0 type\0
/// int32-size value ..., ending in an empty name). False when the bytes do
/// not say.
bool displayWindowPixels(const std::uint8_t* data, std::size_t size, std::uint64_t& pixels) {
    std::size_t at = 8;
    const auto name = [&](std::string& out) {
        const void* end = at < size ? std::memchr(data + at, 0, size - at) : nullptr;
        if (!end) return false;
        out.assign(reinterpret_cast<const char*>(data + at), static_cast<const std::uint8_t*>(end) - (data + at));
        at += out.size() + 1;
        return true;
    };
    const auto int32 = [&](std::size_t offset) {
        std::uint32_t v = 0;
        for (int i = 0; i < 4; ++i) v |= std::uint32_t(data[offset + std::size_t(i)]) << (8 * i);
        return static_cast<std::int32_t>(v);
    };
    std::string attribute, type;
    while (name(attribute) && !attribute.empty() && name(type) && at + 4 <= size) {
        const std::int32_t length = int32(at);
        at += 4;
        if (length < 0 || std::size_t(length) > size - at) return false;
        if (attribute == "displayWindow" && type == "box2i" && length == 16) {
            const std::int64_t w = std::int64_t(int32(at + 8)) - int32(at) + 1;
            const std::int64_t h = std::int64_t(int32(at + 12)) - int32(at + 4) + 1;
            pixels = w > 0 && h > 0 ? std::uint64_t(w) * std::uint64_t(h) : 0;
            return true;
        }
        at += std::size_t(length);
    }
    return false;
}

/// A directory of its own for the map each input becomes.
std::filesystem::path outputDirectory() {
    std::error_code ec;
    const std::filesystem::path base =
        std::filesystem::is_directory("/dev/shm", ec) ? "/dev/shm" : std::filesystem::temp_directory_path();
    std::string pattern = (base / "fuzz_exr_import-XXXXXX").string();
    if (!::mkdtemp(pattern.data())) {
        std::perror("fuzz_exr_import: cannot create an output directory");
        std::abort();
    }
    return pattern;
}

struct Output {
    std::filesystem::path directory = outputDirectory();
    std::filesystem::path map = directory / "out.dsm";
    ~Output() {
        std::error_code ec;
        std::filesystem::remove_all(directory, ec);
    }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static ScratchFile input("fuzz_exr_import.exr");
    static Output output;
    std::uint64_t pixels = 0;
    if (displayWindowPixels(data, size, pixels) && pixels > kMaxFuzzPixels) return 0;
    input.write(data, size);

    dsm::ExrImportOptions options;
    options.tileSize = 16;
    bool imported = false;
    try {
        dsm::importDeepExr(input.path, output.map.string(), options);
        imported = true;
    } catch (const dsm::Error& e) {
        if (!*e.what()) std::abort();  // errors must say what is wrong
    }
    // A failed import leaves nothing; a successful one a valid map.
    std::error_code ec;
    if (imported) dsm::validate(output.map.string());
    for (const auto& entry : std::filesystem::directory_iterator(output.directory, ec)) {
        if (!imported || entry.path() != output.map) std::abort();
    }
    std::filesystem::remove(output.map, ec);
    return 0;
}
