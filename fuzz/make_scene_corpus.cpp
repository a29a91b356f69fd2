// Writes the seed corpus of fuzz_scene: every example scene as it is, the
// example scenes made small (few hairs, low resolution), and one small scene
// per object type, light type and transform form of spec/scene.md. Every seed
// is checked to parse.
//
//   fuzz_make_scene_corpus EXAMPLES_DIR DIR   writes DIR/seed-*.json
#include <dsm/error.h>
#include <dsm/scene.h>

#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace {

using nlohmann::json;

std::string readFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot read " + path.string());
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeSeed(const std::filesystem::path& dir, const std::string& name, const std::string& text,
               const std::filesystem::path& examples) {
    dsm::parseScene(text, examples.string(), name);  // throws when a seed is not a valid scene
    const std::filesystem::path path = dir / ("seed-" + name + ".json");
    std::ofstream out(path, std::ios::binary);
    out << text;
    if (!out) throw std::runtime_error("cannot write " + path.string());
    std::printf("fuzz_make_scene_corpus: %s (%zu bytes)\n", path.string().c_str(), text.size());
}

/// An example made cheap to parse: few hairs, a small map.
json smaller(json scene) {
    scene["light"]["resolution"] = json::array({16, 12});
    for (json& object : scene["objects"])
        if (object.contains("hairball")) {
            object["hairball"]["count"] = 12;
            object["hairball"]["segments"] = 3;
        }
    return scene;
}

json spotLight() {
    return json::parse(R"({"type": "spot", "position": [0, 5, 1], "look_at": [0, 0, 0], "fov": 40,
                           "resolution": [8, 8], "near": 0.5})");
}

/// One object of each type and each optional key.
std::vector<std::pair<std::string, json>> objects() {
    return {
        {"mesh-inline", json::parse(R"({"type": "mesh", "positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]],
                                        "triangles": [[0, 1, 2], [1, 3, 2]], "opacity": [0.5, 0.25, 1]})")},
        {"mesh-file", json::parse(R"({"type": "mesh", "file": "pipes.obj", "name": "pipes"})")},
        {"sphere", json::parse(R"({"type": "sphere", "center": [0, 1, 0], "radius": 0.5, "motion": [1, 0, 0]})")},
        {"quad", json::parse(R"({"type": "quad", "center": [0, 0.5, 0], "u": [1, 0, 0], "v": [0, 0, 0.5],
                                 "opacity": 0.75})")},
        {"plane", json::parse(R"({"type": "plane", "normal": [0, 1, 0], "size": [4, 2]})")},
        {"hairball", json::parse(R"({"type": "hair", "hairball": {"center": [0, 1, 0], "radius": 0.3,
                                     "count": 8, "length": 0.2, "curl": 3, "width": 0.01, "segments": 4,
                                     "seed": 7}})")},
        {"curves", json::parse(R"({"type": "curves", "points_per_curve": [2, 3],
                                   "points": [[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 0.5, 0.2], [1, 1, 0]],
                                   "width": [0.1, 0.1, 0.05, 0.05, 0.02]})")},
        {"volume-homogeneous", json::parse(R"({"type": "volume", "bounds": [[-1, 0, -1], [1, 1, 1]],
                                               "density": {"type": "homogeneous", "value": 0.5},
                                               "scale": 2, "step": 0.1})")},
        {"volume-noise", json::parse(R"({"type": "volume", "bounds": [[-1, 0, -1], [1, 2, 1]],
                                         "density": {"type": "noise", "density": 1, "frequency": 1.5,
                                                     "octaves": 3, "seed": 2, "falloff": 0.5}})")},
        {"transform-matrix", json::parse(R"({"type": "sphere", "radius": 1,
                                             "transform": [1, 0, 0, 5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]})")},
        {"transform-trs", json::parse(R"({"type": "sphere", "radius": 1, "transform": {"scale": [2, 1, 1],
                                          "rotate": {"axis": [0, 0, 1], "angle": 90}, "translate": [1, 0, 0]}})")},
        {"transform-list", json::parse(R"({"type": "quad", "u": [1, 0, 0], "v": [0, 1, 0],
                                           "transform": [{"translate": [1, 0, 0]}, {"scale": 0.5},
                                                         {"rotate": {"axis": [0, 1, 0], "angle": -30}}]})")},
    };
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s EXAMPLES_DIR DIR\n", argv[0]);
        return 2;
    }
    const std::filesystem::path examples = argv[1], dir = argv[2];
    try {
        std::filesystem::create_directories(dir);
        for (const auto& entry : std::filesystem::directory_iterator(examples)) {
            if (entry.path().extension() != ".json") continue;
            const std::string text = readFile(entry.path());
            const std::string name = entry.path().stem().string();
            writeSeed(dir, name, text, examples);
            writeSeed(dir, name + "-small", smaller(json::parse(text)).dump(1), examples);
        }
        for (const auto& [name, object] : objects())
            writeSeed(dir, name, json{{"light", spotLight()}, {"objects", json::array({object})}}.dump(1), examples);
        // The other light type, with every key it takes, over an empty scene.
        const json distant = json::parse(R"({"type": "distant", "position": [0, 10, 0], "direction": [0, -1, 0],
                                             "up": [0, 0, 1], "extent": 3, "resolution": 32, "near": 1})");
        writeSeed(dir, "distant-empty", json{{"light", distant}, {"objects", json::array()}}.dump(), examples);
        json area = spotLight();
        area["area_radius"] = 0.25;
        area.erase("look_at");
        area["direction"] = {0, -1, -0.2};
        writeSeed(dir, "spot-area", json{{"light", area}, {"objects", json::array({objects()[2].second})}}.dump(),
                  examples);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_make_scene_corpus: %s\n", e.what());
        return 1;
    }
    return 0;
}
