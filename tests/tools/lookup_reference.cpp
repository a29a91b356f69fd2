// The library's own answers, for the dsm-lookup checks (check_dsm_lookup.cmake),
// and a small monochrome map whose answers are known in closed form.
//
//   lookup_reference MAP SPACE FILTER WIDTH LEVEL BIAS < points
//       reads "x y z" per line (std::istream >>, nothing else) and prints, per
//       point, the dsm::LookupContext answer as "%.9g" values separated by
//       commas: V or R,G,B, then the error bound. SPACE is world, light or
//       raster; FILTER box, triangle or gaussian; LEVEL -1 for automatic;
//       BIAS a number or auto (here and below).
//   lookup_reference --soft MAP SPACE SHAPE W H METHOD SAMPLES LAYERS ZTHRESHOLD BIAS SEED < points
//       the same for dsm::SoftShadowContext with the light
//       AreaLight::forMap(SHAPE disk: radius W; rect: W wide, H high):
//       V or R,G,B, then for METHOD mtsm the rays and classifiedLit (0 or 1),
//       for pcf the blocker depth and filter width. SPACE is world or light
//       (converted with AreaLight::lightToWorld).
//   lookup_reference --write-mono OUT
//       writes an 8 x 8 monochrome map, tiles of 4, 2 levels, tolerance 0, an
//       orthographic light with window [0, 8] x [0, 8] and
//       light = world + (1, -2, 0.5), so raster (rx, ry) = (lx, 8 - ly).
//       Pixel (i, j) holds V = 1 up to z = 1, then falls linearly to
//       k(i, j) / 16 at z = 2 and stays there, with k = (5 i + 3 j + i j) % 16.
//
// Exit status 0 on success, 1 on any error (one line on stderr).
#include <array>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "dsm/dsm.h"

namespace {

constexpr std::uint32_t kMonoSize = 8;

std::uint32_t monoNumerator(std::uint32_t i, std::uint32_t j) { return (5 * i + 3 * j + i * j) % 16; }

void writeMono(const std::string& path) {
    dsm::WriterOptions o;
    o.width = kMonoSize;
    o.height = kMonoSize;
    o.tileSize = 4;
    o.channels = 1;
    o.mipLevels = 2;
    o.tolerance = 0.0;
    o.camera.projection = dsm::Projection::Orthographic;
    o.camera.worldToLight = {1, 0, 0, 1, 0, 1, 0, -2, 0, 0, 1, 0.5, 0, 0, 0, 1};
    o.camera.screenWindow = {0.0, 8.0, 0.0, 8.0};
    o.metadata = R"({"generator":"lookup_reference"})";
    dsm::MapWriter writer(path, o);
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<dsm::VisibilityFunction> pixels;
            for (std::uint32_t y = 0; y < writer.tileHeight(ty); ++y)
                for (std::uint32_t x = 0; x < writer.tileWidth(tx); ++x) {
                    dsm::VisibilityFunction f(1);
                    f.append(1.0f, 1.0f);
                    f.append(2.0f, static_cast<float>(monoNumerator(tx * 4 + x, ty * 4 + y)) / 16.0f);
                    pixels.push_back(std::move(f));
                }
            writer.writeTile(tx, ty, pixels);
        }
    writer.finish();
}

dsm::PixelFilter filterNamed(const std::string& name) {
    if (name == "box") return dsm::PixelFilter::Box;
    if (name == "triangle") return dsm::PixelFilter::Triangle;
    if (name == "gaussian") return dsm::PixelFilter::Gaussian;
    throw std::runtime_error("unknown filter '" + name + "'");
}

void printAnswers(const std::vector<std::string>& args) {
    const auto map = dsm::DeepShadowMap::open(args[0]);
    const std::string& space = args[1];
    if (space != "world" && space != "light" && space != "raster")
        throw std::runtime_error("unknown space '" + space + "'");
    dsm::LookupOptions options;
    options.filter = filterNamed(args[2]);
    options.filterWidth = std::stod(args[3]);
    if (const int level = std::stoi(args[4]); level >= 0) options.level = static_cast<unsigned>(level);
    if (args[5] != "auto") options.bias = std::stod(args[5]);
    dsm::LookupContext context(map);
    std::array<double, 3> p{};
    while (std::cin >> p[0] >> p[1] >> p[2]) {
        const dsm::LookupResult r = space == "world"   ? context.world(p, options)
                                    : space == "light" ? context.light(p, options)
                                                       : context.raster(p[0], p[1], p[2], options);
        for (int c = 0; c < (map->info().channels == 3 ? 3 : 1); ++c)
            std::printf("%.9g,", r.v[static_cast<std::size_t>(c)]);
        std::printf("%.9g\n", r.errorBound);
    }
    if (!std::cin.eof()) throw std::runtime_error("unreadable point");
}

void printSoftAnswers(const std::vector<std::string>& args) {
    const auto map = dsm::DeepShadowMap::open(args[0]);
    const std::string& space = args[1];
    if (space != "world" && space != "light") throw std::runtime_error("unknown space '" + space + "'");
    const bool disk = args[2] == "disk";
    if (!disk && args[2] != "rect") throw std::runtime_error("unknown shape '" + args[2] + "'");
    const double width = std::stod(args[3]), height = std::stod(args[4]);
    const dsm::AreaLight light =
        disk ? dsm::AreaLight::forMap(map->info(), dsm::AreaLightShape::Disk, width, width)
             : dsm::AreaLight::forMap(map->info(), dsm::AreaLightShape::Rectangle, width / 2.0, height / 2.0);
    const bool pcf = args[5] == "pcf";
    if (!pcf && args[5] != "mtsm") throw std::runtime_error("unknown method '" + args[5] + "'");
    dsm::SoftShadowOptions options;
    options.samples = std::stoi(args[6]);
    if (const int layers = std::stoi(args[7]); layers != 0) options.layers = layers;
    options.zThreshold = std::stod(args[8]);
    if (args[9] != "auto") options.bias = std::stod(args[9]);
    options.seed = std::stoull(args[10]);
    dsm::SoftShadowContext context(std::make_shared<dsm::SoftShadowTracer>(map, light));
    dsm::Vec3 p{};
    while (std::cin >> p[0] >> p[1] >> p[2]) {
        const dsm::Vec3 receiver = space == "light" ? light.lightToWorld(p) : p;
        const dsm::SoftShadowResult r =
            pcf ? context.pcfVisibility(receiver, options) : context.visibility(receiver, options);
        for (int c = 0; c < (map->info().channels == 3 ? 3 : 1); ++c)
            std::printf("%.9g,", r.v[static_cast<std::size_t>(c)]);
        if (pcf) std::printf("%.9g,%.9g\n", r.blockerDepth, r.filterWidth);
        else std::printf("%d,%d\n", r.rays, r.classifiedLit ? 1 : 0);
    }
    if (!std::cin.eof()) throw std::runtime_error("unreadable point");
}

}  // namespace

int main(int argc, char** argv) {
    try {
        const std::vector<std::string> args(argv + 1, argv + argc);
        if (args.size() == 2 && args[0] == "--write-mono") {
            writeMono(args[1]);
        } else if (args.size() == 12 && args[0] == "--soft") {
            printSoftAnswers(std::vector<std::string>(args.begin() + 1, args.end()));
        } else if (args.size() == 6) {
            printAnswers(args);
        } else {
            std::cerr << "usage: lookup_reference MAP SPACE FILTER WIDTH LEVEL BIAS < points | --write-mono OUT\n"
                         "       lookup_reference --soft MAP SPACE SHAPE W H METHOD SAMPLES LAYERS ZTHRESHOLD BIAS "
                         "SEED < points\n";
            return 2;
        }
    } catch (const std::exception& e) {
        std::cerr << "lookup_reference: " << e.what() << '\n';
        return 1;
    }
    return 0;
}
