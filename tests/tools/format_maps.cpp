// Maps for the independent reader (spec/dsm_reader.py) to check against
// libdsm's reader, and libdsm's dump of them in the same canonical text.
//
//   format_maps write DIR   writes maps covering the format's features
//   format_maps dump FILE   prints every non-empty pixel of every level
#include <dsm/dsm.h>

#include <algorithm>
#include <bit>
#include <cstdio>
#include <iostream>
#include <random>
#include <string>
#include <vector>

namespace {

// A random valid function: `layers` layers, depths rising from 0.5, values
// falling within each layer, some vertical steps.
dsm::VisibilityFunction randomFunction(std::mt19937_64& rng, int channels, bool counts, int layers) {
    std::uniform_real_distribution<float> gap(0.0f, 0.4f), drop(0.0f, 0.3f);
    std::uniform_int_distribution<int> vertices(1, 7), count(0, 5);
    dsm::VisibilityFunction f(channels, counts);
    float z = std::uniform_real_distribution<float>(0.5f, 40.0f)(rng);
    for (int layer = 0; layer < layers; ++layer) {
        if (layer > 0) f.beginLayer();
        float v[3] = {1.0f, 1.0f, 1.0f};
        const int n = vertices(rng);
        for (int i = 0; i < n; ++i) {
            z += std::bernoulli_distribution(0.2)(rng) ? 0.0f : gap(rng);
            for (int c = 0; c < channels; ++c) v[c] = std::max(0.0f, v[c] - drop(rng));
            f.append(z, v, static_cast<std::uint32_t>(count(rng)));
        }
    }
    return f;
}

struct Variant {
    std::string name;
    std::uint16_t minor;
    int channels;
    bool counts;
    int layers;
    bool quantise;
    int zlibLevel;  // < 0: zstd at level -zlibLevel
    std::uint32_t width, height, tileSize;
};

void write(const std::string& dir) {
    const std::vector<Variant> variants = {
        {"mono-1.0", 0, 1, false, 1, false, 6, 37, 21, 8},
        {"rgb-counts-layers-1.0", 0, 3, true, 3, false, 0, 19, 13, 4},
        {"mono-1.1", 1, 1, false, 1, false, 6, 37, 21, 8},
        {"mono-quantised-1.1", 1, 1, false, 1, true, 9, 40, 33, 16},
        {"rgb-counts-layers-1.1", 1, 3, true, 3, false, 0, 19, 13, 4},
        {"rgb-counts-quantised-1.1", 1, 3, true, 2, true, 6, 23, 17, 8},
        {"one-pixel-1.1", 1, 3, true, 1, true, 6, 1, 1, 2},
        {"rgb-counts-quantised-zstd-1.1", 1, 3, true, 2, true, -19, 23, 17, 8},
    };
    std::mt19937_64 rng(2026);
    for (const Variant& v : variants) {
        dsm::WriterOptions o;
        o.width = v.width;
        o.height = v.height;
        o.tileSize = v.tileSize;
        o.channels = v.channels;
        o.counts = v.counts;
        o.maxLayers = v.layers;
        o.formatMinor = v.minor;
        o.quantiseValues = v.quantise;
        o.zlibLevel = std::max(v.zlibLevel, 0);
        if (v.zlibLevel < 0) {
            o.codec = dsm::TileCodec::Zstd;
            o.zstdLevel = -v.zlibLevel;
        }
        o.tolerance = 0.02;
        o.metadata = "{\"variant\":\"" + v.name + "\"}";
        dsm::MapWriter writer(dir + "/" + v.name + ".dsm", o);
        const double step = v.quantise ? dsm::valueStep(o.tolerance) : 0.0;
        for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
            for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
                std::vector<dsm::VisibilityFunction> pixels;
                const bool emptyTile = (tx + ty) % 3 == 2;
                for (std::uint32_t p = 0; p < writer.tileWidth(tx) * writer.tileHeight(ty); ++p) {
                    const bool empty = emptyTile || std::bernoulli_distribution(0.2)(rng);
                    const int channels = v.channels == 3 && std::bernoulli_distribution(0.6)(rng) ? 3 : 1;
                    const int layers = std::uniform_int_distribution<int>(1, v.layers)(rng);
                    pixels.push_back(empty ? dsm::VisibilityFunction(v.channels, v.counts)
                                           : dsm::roundValues(randomFunction(rng, channels, v.counts, layers), step));
                }
                writer.writeTile(tx, ty, pixels);
            }
        writer.finish();
    }
}

std::string hex(float f) {
    char text[9];
    std::snprintf(text, sizeof text, "%08x", std::bit_cast<std::uint32_t>(f));
    return text;
}

// Appends `item` to a comma-separated list, a comma first unless it starts
// the list. (Piece by piece: GCC 12 at -O3 warns, a false -Wrestrict, about
// its own inlined "," + std::string&&.)
void appendListed(std::string& line, bool comma, const std::string& item) {
    if (comma) line += ',';
    line += item;
}

void dump(const std::string& path) {
    const auto map = dsm::DeepShadowMap::open(path);
    const dsm::MapInfo& info = map->info();
    for (unsigned l = 0; l < info.levels.size(); ++l)
        for (std::uint32_t y = 0; y < info.levels[l].height; ++y)
            for (std::uint32_t x = 0; x < info.levels[l].width; ++x) {
                const dsm::PixelFunction f = map->pixel(l, x, y);
                if (f->empty()) continue;
                std::string line = std::to_string(l) + " " + std::to_string(x) + " " + std::to_string(y) +
                                   " c=" + std::to_string(f->channels()) + " layers=";
                for (std::size_t k = 1; k < f->layerCount(); ++k)
                    appendListed(line, k > 1, std::to_string(f->layerBegin(k)));
                line += " z=";
                for (std::size_t i = 0; i < f->size(); ++i) appendListed(line, i > 0, hex(f->z(i)));
                line += " v=";
                const auto values = f->allValues();
                for (std::size_t i = 0; i < values.size(); ++i) appendListed(line, i > 0, hex(values[i]));
                if (info.hasCounts) {
                    line += " n=";
                    for (std::size_t i = 0; i < f->size(); ++i) appendListed(line, i > 0, std::to_string(f->count(i)));
                }
                std::cout << line << '\n';
            }
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::cerr << "usage: format_maps write DIR | format_maps dump FILE\n";
        return 2;
    }
    try {
        const std::string mode = argv[1];
        if (mode == "write") write(argv[2]);
        else if (mode == "dump") dump(argv[2]);
        else return 2;
    } catch (const std::exception& e) {
        std::cerr << "format_maps: ERROR: " << e.what() << '\n';
        return 1;
    }
    return 0;
}
