// libFuzzer target: the input bytes as a scene (spec/scene.md), parsed from
// memory with dsm::parseScene(). The parser must either return a scene or
// throw dsm::Error whose message names the scene; a returned scene must give a
// light camera (dsm::lightCamera) with finite numbers. Anything else, a crash,
// a hang, a sanitizer report, a leak or an exception of another type (a JSON
// library exception, std::bad_alloc), is a finding. Built by
// fuzz/CMakeLists.txt.
//
// Relative file names in a scene resolve against the examples directory
// (DSM_EXAMPLES_DIR), so that the seed scenes' OBJ mesh is read too.
#include <dsm/error.h>
#include <dsm/scene.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#ifndef DSM_EXAMPLES_DIR
#error "DSM_EXAMPLES_DIR must name the examples directory"
#endif

namespace {

constexpr const char* kSceneName = "fuzz.json";

/// Hair balls are generated while the scene is parsed: a valid scene within
/// the library's cap of 10^8 points takes a minute and gigabytes under the
/// sanitizers, the size of the work rather than a fault. The bound itself is
/// covered by tests/test_scene_limits.cpp.
dsm::SceneReadOptions fuzzReadOptions() {
    dsm::SceneReadOptions options;
    options.maxHairPoints = 100'000;
    return options;
}

// A scene the parser accepts makes a valid light camera.
void checkCamera(const dsm::LightCamera& camera) {
    try {
        camera.validate();
    } catch (const dsm::Error&) {
        std::abort();
    }
    for (const double v : camera.worldToLight)
        if (!std::isfinite(v)) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    dsm::Scene scene;
    try {
        scene = dsm::parseScene(text, DSM_EXAMPLES_DIR, kSceneName, fuzzReadOptions());
    } catch (const dsm::Error& e) {
        // Every message names the scene (spec/scene.md, Errors).
        if (std::string(e.what()).rfind(std::string("scene '") + kSceneName + "'", 0) != 0) std::abort();
        return 0;
    }
    checkCamera(dsm::lightCamera(scene.light));
    (void)scene.isColoured();
    return 0;
}
