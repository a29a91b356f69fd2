// Signed error of the L-infinity compressor against its own input, greedy
// (Lokovic & Veach) and centred (--centred-compression), on maps built from
// scenes: each scene is built from the same samples with tolerance 0 (the
// compressor's input, kept exactly) and at the tolerance `dsm-build` chooses
// with each rule, all without mip levels; every pixel of a compressed map is
// compared with the same pixel of the lossless one over depth.
//
// Prints, per scene, in units of the tolerance eps (compressed - input):
//   - the mean signed error on each pixel's plateau, the longest stretch
//     where its input stays at one value 0 < V < 1 (behind a semi-transparent
//     occluder, in front of the receiver), averaged over such pixels: what a
//     receiver there reads too dark (< 0) or too light;
//   - the mean signed error just before the plateau's end, where the next
//     surface (a receiver) starts the fall that closes it: what that
//     receiver reads, over the pixels whose plateau is closed so;
//   - the mean signed error over the ramps in front of the plateaus (the
//     input falling through the occluders, a staircase of sample steps);
//   - the largest error anywhere (at most 1: the stated bound);
//   - level 0's vertices before and after compression (and how many of the
//     latter are vertical steps: at the depth of the vertex before), and the
//     file's size
//     (centred against greedy, in the same run).
// The error is integrated exactly over each stretch (both functions are
// linear between the depths where either has a vertex).
//
//   bench_compression_bias [--smoke] [--size=N] [--spp=N] [SCENE.json ...]
//     --smoke: one small built-in scene at 64^2; default: the built-in scenes
//     (a sphere and a tilted quad of opacity 0.4 over a ground plane) and
//     the given scene files at 256^2, 16 samples per pixel.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <unistd.h>

#include "dsm/dsm.h"
#include "dsm/sampler.h"
#include "dsm/scene.h"

namespace {

namespace fs = std::filesystem;
using namespace dsm;

struct NamedScene {
    std::string name;
    Scene scene;
};

// A semi-transparent occluder (opacity 0.4, as behind the bunny of the
// accuracy scenes) over a ground plane, seen by a spot light.
std::string occluderOverGround(const std::string& occluder) {
    return R"({"light": {"type": "spot", "position": [0, 6, 0.5], "look_at": [0, 0, 0], "fov": 50},
               "objects": [)" +
           occluder + R"(, {"type": "plane", "normal": [0, 1, 0], "size": 12}]})";
}

struct Sums {
    double plateauError = 0.0;  // the sum over pixels of each plateau's mean error
    std::size_t plateauPixels = 0;
    double rampError = 0.0, rampLength = 0.0;
    double receiverError = 0.0;  // the sum over pixels of the error just before the plateau's end
    std::size_t receiverPixels = 0;
    double largest = 0.0;
    std::uint64_t verticalSteps = 0;  // compressed vertices at the depth of the one before
};

// Adds one pixel's comparison of `compressed` against `input` (layer 0,
// channel 0: the scenes are monochrome). The input's plateau is its longest
// stretch at one value 0 < V < 1 (behind an occluder, in front of the next;
// past the last vertex it counts as long as the function's depth range). Its
// ramp is everything in front of the plateau.
void compare(const VisibilityView& input, const VisibilityView& compressed, Sums& sums) {
    const std::size_t n = input.lightEnd();
    if (n == 0) return;
    for (std::size_t i = 1; i < compressed.lightEnd(); ++i) sums.verticalSteps += compressed.z(i) == compressed.z(i - 1);
    std::vector<double> depths;
    for (const VisibilityView* f : {&input, &compressed})
        for (std::size_t i = 0; i < f->lightEnd(); ++i) depths.push_back(f->z(i));
    std::sort(depths.begin(), depths.end());
    depths.erase(std::unique(depths.begin(), depths.end()), depths.end());
    // The plateau: the longest stretch [plateauStart, plateauEnd) over which
    // the input keeps one value 0 < V < 1.
    const bool endsOpen = input.value(n - 1) > 0.0f;
    double plateauStart = 0.0, plateauEnd = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const float v = input.value(i);
        if (!(v > 0.0f && v < 1.0f)) continue;
        std::size_t j = i + 1;
        while (j < n && input.value(j) == v) ++j;
        // Ends at the next vertex that changes the value (or, past the last
        // vertex, as far beyond it as the function's depth range).
        const double end = j < n ? input.z(j) : input.z(n - 1) + (input.z(n - 1) - input.z(0));
        if (end - input.z(i) > plateauEnd - plateauStart) {
            plateauStart = input.z(i);
            plateauEnd = end;
        }
        i = j - 1;
    }
    const bool hasPlateau = plateauEnd > plateauStart;
    if (endsOpen) depths.push_back(input.z(n - 1) + (input.z(n - 1) - input.z(0)));

    const auto before = [](const VisibilityView& f, double z) {
        return f.evaluateLayer(0, std::nextafter(z, -std::numeric_limits<double>::infinity()));
    };
    double plateauIntegral = 0.0;
    for (std::size_t k = 0; k + 1 < depths.size(); ++k) {
        const double z0 = depths[k], z1 = depths[k + 1];
        const double d0 = compressed.evaluateLayer(0, z0) - input.evaluateLayer(0, z0);
        const double d1 = before(compressed, z1) - before(input, z1);
        sums.largest = std::max({sums.largest, std::abs(d0), std::abs(d1)});
        const double integral = 0.5 * (d0 + d1) * (z1 - z0);
        if (hasPlateau && z0 >= plateauStart && z1 <= plateauEnd) {
            plateauIntegral += integral;
        } else if (z1 <= plateauStart) {
            sums.rampError += integral;
            sums.rampLength += z1 - z0;
        }
    }
    if (hasPlateau) {
        sums.plateauError += plateauIntegral / (plateauEnd - plateauStart);
        ++sums.plateauPixels;
        if (plateauEnd <= input.z(n - 1)) {  // closed by the next surface: a receiver reads it there
            sums.receiverError += before(compressed, plateauEnd) - before(input, plateauEnd);
            ++sums.receiverPixels;
        }
    }
}

void measure(const NamedScene& s, std::uint32_t size, std::uint32_t spp, const fs::path& dir) {
    BuildOptions o;
    o.width = o.height = size;
    o.samplesPerPixel = spp;
    o.mipLevels = 1;
    const fs::path lossless = dir / "lossless.dsm", compressed = dir / "compressed.dsm";
    o.tolerance = 0.0;
    buildMap(s.scene, o, lossless.string());
    const auto in = DeepShadowMap::open(lossless.string());
    o.tolerance.reset();
    std::uintmax_t greedyBytes = 0;
    for (const bool centred : {false, true}) {
        o.centredCompression = centred;
        buildMap(s.scene, o, compressed.string());
        const auto out = DeepShadowMap::open(compressed.string());
        const double eps = out->info().levels[0].tolerance;
        Sums sums;
        for (std::uint32_t y = 0; y < size; ++y)
            for (std::uint32_t x = 0; x < size; ++x)
                compare(in->pixel(0, x, y).view(), out->pixel(0, x, y).view(), sums);
        const std::uintmax_t bytes = fs::file_size(compressed);
        if (!centred) greedyBytes = bytes;
        std::printf("%-24s %-7s eps %.4f  plateau %+.3f (%zu pixels)  at its end %+.3f (%zu)  ramp %+.3f  largest "
                    "|error| %.3f  vertices %llu -> %llu (%llu vertical steps)  file %llu bytes (%.3f x greedy)\n",
                    s.name.c_str(), centred ? "centred" : "greedy", eps,
                    sums.plateauPixels ? sums.plateauError / double(sums.plateauPixels) / eps : 0.0,
                    sums.plateauPixels,
                    sums.receiverPixels ? sums.receiverError / double(sums.receiverPixels) / eps : 0.0,
                    sums.receiverPixels, sums.rampLength > 0.0 ? sums.rampError / sums.rampLength / eps : 0.0,
                    sums.largest / eps, static_cast<unsigned long long>(in->info().levels[0].vertexCount),
                    static_cast<unsigned long long>(out->info().levels[0].vertexCount),
                    static_cast<unsigned long long>(sums.verticalSteps), static_cast<unsigned long long>(bytes), double(bytes) / double(greedyBytes));
    }
    fs::remove(lossless);
    fs::remove(compressed);
}

}  // namespace

int main(int argc, char** argv) {
    bool smoke = false;
    std::uint32_t size = 256, spp = 16;
    std::vector<std::string> files;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--smoke") smoke = true;
        else if (a.rfind("--size=", 0) == 0) size = static_cast<std::uint32_t>(std::stoul(a.substr(7)));
        else if (a.rfind("--spp=", 0) == 0) spp = static_cast<std::uint32_t>(std::stoul(a.substr(6)));
        else if (!a.empty() && a[0] != '-') files.push_back(a);
        else {
            std::fprintf(stderr, "usage: bench_compression_bias [--smoke] [--size=N] [--spp=N] [SCENE.json ...]\n");
            return 2;
        }
    }
    if (smoke) size = 64;
    try {
        std::vector<NamedScene> scenes;
        scenes.push_back({"sphere, opacity 0.4",
                          parseScene(occluderOverGround(
                                         R"({"type": "sphere", "center": [0, 1, 0], "radius": 1, "opacity": 0.4})"),
                                     ".", "sphere")});
        if (!smoke) {
            scenes.push_back(
                {"tilted quad, opacity 0.4",
                 parseScene(occluderOverGround(R"({"type": "quad", "opacity": 0.4, "center": [0, 1.5, 0],
                    "u": [1.5, 0, 0], "v": [0, 1, 1]})"),
                            ".", "quad")});
            for (const std::string& f : files) scenes.push_back({fs::path(f).stem().string(), loadScene(f)});
        }
        const fs::path dir = fs::temp_directory_path() / ("dsm-bias-" + std::to_string(::getpid()));
        fs::create_directories(dir);
        std::printf("%u^2, %u samples per pixel, errors in units of eps (compressed - input)\n", size, spp);
        for (const NamedScene& s : scenes) measure(s, size, spp, dir);
        fs::remove_all(dir);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_compression_bias: %s\n", e.what());
        return 1;
    }
    return 0;
}
