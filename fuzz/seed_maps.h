// The small valid maps fuzz_validate starts from, also the sources of
// fuzz_exr_import's seed EXRs: between them they use every feature of the
// format (monochrome and RGB pixels, counts, layers, one level and full
// pyramids, empty tiles, zlib-compressed and stored tiles, clipped edge tiles,
// both projections, metadata).
#pragma once

#include <dsm/reader.h>
#include <dsm/writer.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace seed_maps {

using PixelFn = std::function<dsm::VisibilityFunction(std::uint32_t x, std::uint32_t y)>;

inline void writeMap(std::vector<std::filesystem::path>& written, const std::filesystem::path& path, const dsm::WriterOptions& options, const PixelFn& pixel) {
    dsm::MapWriter writer(path.string(), options);
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<dsm::VisibilityFunction> pixels;
            for (std::uint32_t y = 0; y < writer.tileHeight(ty); ++y)
                for (std::uint32_t x = 0; x < writer.tileWidth(tx); ++x)
                    pixels.push_back(pixel(tx * options.tileSize + x, ty * options.tileSize + y));
            writer.writeTile(tx, ty, pixels);
        }
    writer.finish();
    dsm::validate(path.string());
    std::printf("seed map %s (%ju bytes)\n", path.string().c_str(),
                static_cast<std::uintmax_t>(std::filesystem::file_size(path)));
    written.push_back(path);
}

// A monochrome function falling from 1 in `steps` steps starting at depth z0.
inline dsm::VisibilityFunction falling(float z0, int steps, bool counts) {
    dsm::VisibilityFunction f(1, counts);
    for (int i = 1; i <= steps; ++i)
        f.append(z0 + 0.5f * static_cast<float>(i), 1.0f - static_cast<float>(i) / static_cast<float>(steps + 1),
                 counts ? static_cast<std::uint32_t>(i) : 0u);
    return f;
}

/// Writes DIR/seed-*.dsm (DIR must exist) and returns their paths.
inline std::vector<std::filesystem::path> writeSeedMaps(const std::filesystem::path& dir) {
    std::vector<std::filesystem::path> written;
    // Monochrome, one level, tiles stored without zlib, clipped edge tiles.
    {
        dsm::WriterOptions o;
        o.width = 5;
        o.height = 3;
        o.tileSize = 2;
        o.mipLevels = 1;
        o.zlibLevel = 0;
        writeMap(written, dir / "seed-mono.dsm", o, [](std::uint32_t x, std::uint32_t y) {
            return (x + y) % 3 == 0 ? dsm::VisibilityFunction() : falling(0.1f * float(x + 1), 1 + int(y), false);
        });
    }
    // RGB and monochrome pixels, counts, two layers, a full pyramid,
    // zlib, empty tiles, metadata, an orthographic camera.
    {
        dsm::WriterOptions o;
        o.width = 6;
        o.height = 5;
        o.tileSize = 2;
        o.channels = 3;
        o.counts = true;
        o.maxLayers = 2;
        o.tolerance = 0.05;
        o.levelToleranceFactor = 2.0;
        o.camera.projection = dsm::Projection::Orthographic;
        o.camera.screenWindow = {0.0, 6.0, 0.0, 5.0};
        o.metadata = R"({"software":"fuzz_make_corpus","scene":"layers"})";
        writeMap(written, dir / "seed-rgb-layers.dsm", o, [](std::uint32_t x, std::uint32_t y) {
            if (x >= 4) return dsm::VisibilityFunction(1, true);  // an empty tile column
            if ((x + y) % 2 == 0) return falling(1.0f, 2, true);
            dsm::VisibilityFunction f(3, true);
            const float a[3] = {0.8f, 0.6f, 0.7f}, b[3] = {0.0f, 0.0f, 0.0f}, c[3] = {0.5f, 0.4f, 0.3f};
            f.append(0.5f + 0.1f * float(y), a, 2);
            f.append(1.5f, b, 1);
            if (y % 2 == 1) {
                f.beginLayer();
                f.append(2.0f + 0.1f * float(x), c, 3);
            }
            return f;
        });
    }
    // One pixel, perspective camera.
    {
        dsm::WriterOptions o;
        o.width = 1;
        o.height = 1;
        o.tileSize = 2;
        writeMap(written, dir / "seed-one-pixel.dsm", o, [](std::uint32_t, std::uint32_t) { return falling(0.25f, 3, false); });
    }
    // Every tile empty, two levels.
    {
        dsm::WriterOptions o;
        o.width = 4;
        o.height = 4;
        o.tileSize = 2;
        o.mipLevels = 2;
        writeMap(written, dir / "seed-empty.dsm", o, [](std::uint32_t, std::uint32_t) { return dsm::VisibilityFunction(); });
    }
    // A wide strip with counts, odd level sizes and a larger tile.
    {
        dsm::WriterOptions o;
        o.width = 13;
        o.height = 2;
        o.tileSize = 8;
        o.counts = true;
        o.mipLevels = 3;
        o.zlibLevel = 9;
        writeMap(written, dir / "seed-strip.dsm", o, [](std::uint32_t x, std::uint32_t y) {
            return x == 6 ? dsm::VisibilityFunction(1, true) : falling(float(x) * 0.3f, 1 + int((x + y) % 4), true);
        });
    }
    return written;
}

}  // namespace seed_maps
