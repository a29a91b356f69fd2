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
        scene = dsm::parseScene(text, DSM_EXAMPLES_DIR, kSceneName);
    } catch (const dsm::Error& e) {
        // Every message names the scene (spec/scene.md, Errors).
        if (std::string(e.what()).rfind(std::string("scene '") + kSceneName + "'", 0) != 0) std::abort();
        return 0;
    }
    checkCamera(dsm::lightCamera(scene.light));
    (void)scene.isColoured();
    return 0;
}
