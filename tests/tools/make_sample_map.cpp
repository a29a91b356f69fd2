// Writes small deep shadow maps for the tool tests (tests/tools/*.cmake).
//
//   make_sample_map OUT [METADATA] a 48 x 32 RGB map with sample counts, tiles of
//                                  16, 2 mip levels and JSON metadata (or the
//                                  METADATA text given, stored as it is)
//   make_sample_map --corrupt IN OUT
//                                  copies IN to OUT with one byte of the first
//                                  non-empty level-0 tile flipped: the file still
//                                  opens, but dsm::validate() fails its CRC-32
//   make_sample_map --truncate IN OUT BYTES
//                                  copies the first BYTES bytes of IN to OUT
//
// Exit status 0 on success, 1 on any error (one line on stderr).
#include <cstdint>
#include <exception>
#include <fstream>
#include <iostream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "dsm/dsm.h"

namespace {

constexpr std::uint32_t kWidth = 48;
constexpr std::uint32_t kHeight = 32;

// A deterministic function per pixel: empty on a diagonal band, otherwise one
// to three vertices with non-increasing RGB values and sample counts.
dsm::VisibilityFunction samplePixel(std::uint32_t x, std::uint32_t y) {
    dsm::VisibilityFunction f(3, true);
    if ((x + y) % 7 == 0) return f;
    const unsigned vertices = 1 + (x * 3 + y) % 3;
    float r = 1.0f, g = 1.0f, b = 1.0f;
    for (unsigned i = 0; i < vertices; ++i) {
        r *= 0.75f;
        g *= 0.5f + 0.01f * static_cast<float>(x % 10);
        b *= 0.25f;
        const float values[3] = {r, g, b};
        f.append(1.0f + static_cast<float>(i) + 0.01f * static_cast<float>(y), values, 1 + i);
    }
    return f;
}

void writeSample(const std::string& path, const std::string* metadata) {
    dsm::WriterOptions o;
    o.width = kWidth;
    o.height = kHeight;
    o.tileSize = 16;
    o.channels = 3;
    o.counts = true;
    o.mipLevels = 2;
    o.tolerance = 0.01;
    o.filter = dsm::PixelFilter::Triangle;
    o.filterWidth = 2.0;
    o.camera.projection = dsm::Projection::Perspective;
    o.camera.worldToLight = {1, 0, 0, 0.5, 0, 1, 0, -0.25, 0, 0, 1, 2, 0, 0, 0, 1};
    o.camera.screenWindow = {-0.5, 0.5, -0.375, 0.375};
    o.camera.nearPlane = 0.1;
    o.metadata = R"({"generator":"make_sample_map","scene":{"objects":3,"name":"tools test"}})";
    if (metadata) o.metadata = *metadata;

    dsm::MapWriter writer(path, o);
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<dsm::VisibilityFunction> pixels;
            for (std::uint32_t y = 0; y < writer.tileHeight(ty); ++y)
                for (std::uint32_t x = 0; x < writer.tileWidth(tx); ++x)
                    pixels.push_back(samplePixel(tx * o.tileSize + x, ty * o.tileSize + y));
            writer.writeTile(tx, ty, pixels);
        }
    writer.finish();
}

std::vector<char> readAll(const std::string& path) {
    std::ifstream is(path, std::ios::binary);
    if (!is) throw std::runtime_error("cannot open '" + path + "'");
    std::vector<char> bytes{std::istreambuf_iterator<char>(is), std::istreambuf_iterator<char>()};
    if (is.bad()) throw std::runtime_error("cannot read '" + path + "'");
    return bytes;
}

void writeAll(const std::string& path, const std::vector<char>& bytes) {
    std::ofstream os(path, std::ios::binary | std::ios::trunc);
    os.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    os.close();
    if (!os) throw std::runtime_error("cannot write '" + path + "'");
}

void writeCorruptCopy(const std::string& in, const std::string& out) {
    std::uint64_t offset = 0;
    bool found = false;
    {
        const auto map = dsm::DeepShadowMap::open(in);
        const dsm::LevelInfo& level0 = map->info().levels.at(0);
        for (std::uint32_t ty = 0; ty < level0.tilesY && !found; ++ty)
            for (std::uint32_t tx = 0; tx < level0.tilesX && !found; ++tx) {
                const dsm::TileSummary t = map->tile(0, tx, ty);
                if (!t.empty()) {
                    offset = t.offset + t.storedBytes / 2;
                    found = true;
                }
            }
    }
    if (!found) throw std::runtime_error("'" + in + "' has no non-empty level-0 tile to corrupt");

    std::vector<char> bytes = readAll(in);
    if (offset >= bytes.size()) throw std::runtime_error("tile offset beyond the end of '" + in + "'");
    bytes[offset] = static_cast<char>(bytes[offset] ^ 0x5a);
    writeAll(out, bytes);
}

void writeTruncatedCopy(const std::string& in, const std::string& out, const std::string& size) {
    std::vector<char> bytes = readAll(in);
    const unsigned long long keep = std::stoull(size);
    if (keep < bytes.size()) bytes.resize(static_cast<std::size_t>(keep));
    writeAll(out, bytes);
}

}  // namespace

int main(int argc, char** argv) {
    try {
        const std::vector<std::string> args(argv + 1, argv + argc);
        if ((args.size() == 1 || args.size() == 2) && args[0].rfind("--", 0) != 0) {
            writeSample(args[0], args.size() == 2 ? &args[1] : nullptr);
        } else if (args.size() == 3 && args[0] == "--corrupt") {
            writeCorruptCopy(args[1], args[2]);
        } else if (args.size() == 4 && args[0] == "--truncate") {
            writeTruncatedCopy(args[1], args[2], args[3]);
        } else {
            std::cerr << "usage: make_sample_map OUT [METADATA] | --corrupt IN OUT | --truncate IN OUT BYTES\n";
            return 2;
        }
    } catch (const std::exception& e) {
        std::cerr << "make_sample_map: " << e.what() << '\n';
        return 1;
    }
    return 0;
}
