// Writes the seed corpus of fuzz_exr_import: the seed maps of seed_maps.h
// exported as deep EXRs (scanline and tiled; monochrome and RGB, perspective
// and orthographic, with dsm:* attributes), and one deep scanline EXR written
// directly with OpenEXR's API the way a renderer would: standard camera
// attributes only, no ZBack, samples out of order and overlapping. Every seed
// is checked to import.
//
//   fuzz_make_exr_corpus DIR     creates DIR if needed and writes DIR/seed-*.exr
#include <dsm/error.h>
#include <dsm/exr_deep.h>

#include <array>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfHeader.h>
#include <ImfPartType.h>
#include <ImfStandardAttributes.h>
#include <half.h>

#include "seed_maps.h"

namespace {

void checkImports(const std::filesystem::path& exr, const std::filesystem::path& scratch) {
    const std::filesystem::path map = scratch / "imported.dsm";
    dsm::ExrImportOptions options;
    options.tileSize = 16;
    dsm::importDeepExr(exr.string(), map.string(), options);
    std::filesystem::remove(map);
    std::printf("fuzz_make_exr_corpus: %s (%ju bytes)\n", exr.string().c_str(),
                static_cast<std::uintmax_t>(std::filesystem::file_size(exr)));
}

/// 3 x 2 pixels of point samples (Z, A), given out of depth order and
/// overlapping, under a perspective light described only by worldToCamera and
/// worldToNDC.
void writeRendererStyleExr(const std::filesystem::path& path) {
    constexpr int kWidth = 3, kHeight = 2;
    dsm::LightCamera camera;
    camera.screenWindow = {-0.5, 0.5, -1.0 / 3.0, 1.0 / 3.0};
    const dsm::StandardCameraMatrices matrices = dsm::standardCameraMatrices(camera);
    const auto m44 = [](const std::array<std::array<float, 4>, 4>& m) {
        return Imath::M44f(m[0][0], m[0][1], m[0][2], m[0][3], m[1][0], m[1][1], m[1][2], m[1][3], m[2][0], m[2][1],
                           m[2][2], m[2][3], m[3][0], m[3][1], m[3][2], m[3][3]);
    };
    Imf::Header header(kWidth, kHeight);
    header.compression() = Imf::ZIPS_COMPRESSION;
    header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
    header.channels().insert("A", Imf::Channel(Imf::HALF));
    header.setType(Imf::DEEPSCANLINE);
    Imf::addWorldToCamera(header, m44(matrices.worldToCamera));
    Imf::addWorldToNDC(header, m44(matrices.worldToNDC));

    std::vector<unsigned> counts(kWidth * kHeight);
    std::vector<std::vector<float>> z(counts.size());
    std::vector<std::vector<Imath::half>> a(counts.size());
    for (std::size_t p = 0; p < counts.size(); ++p) {
        // Deeper samples first, one depth twice.
        const float base = 1.0f + 0.25f * float(p);
        z[p] = {base + 1.0f, base, base + 0.5f, base};
        a[p] = {Imath::half(0.5f), Imath::half(0.25f), Imath::half(1.0f / float(p + 2)), Imath::half(0.125f)};
        counts[p] = p == 0 ? 0u : unsigned(z[p].size()) - unsigned(p % 2);
    }
    std::vector<float*> zPointers(counts.size());
    std::vector<Imath::half*> aPointers(counts.size());
    for (std::size_t p = 0; p < counts.size(); ++p) zPointers[p] = z[p].data(), aPointers[p] = a[p].data();

    Imf::DeepFrameBuffer frameBuffer;
    frameBuffer.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()),
                                                  sizeof(unsigned), sizeof(unsigned) * kWidth));
    frameBuffer.insert("Z", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(zPointers.data()), sizeof(float*),
                                           sizeof(float*) * kWidth, sizeof(float)));
    frameBuffer.insert("A", Imf::DeepSlice(Imf::HALF, reinterpret_cast<char*>(aPointers.data()),
                                           sizeof(Imath::half*), sizeof(Imath::half*) * kWidth, sizeof(Imath::half)));
    Imf::DeepScanLineOutputFile out(path.string().c_str(), header);
    out.setFrameBuffer(frameBuffer);
    out.writePixels(kHeight);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
        return 2;
    }
    const std::filesystem::path dir = argv[1];
    const std::filesystem::path scratch = dir / "maps.tmp";
    try {
        std::filesystem::create_directories(scratch);
        for (const std::filesystem::path& map : seed_maps::writeSeedMaps(scratch)) {
            for (const bool tiled : {false, true}) {
                dsm::ExrExportOptions options;
                options.tiled = tiled;
                options.tileSize = 4;
                const std::filesystem::path exr =
                    dir / (map.stem().string() + (tiled ? "-tiled" : "-scanline") + ".exr");
                dsm::exportDeepExr(map.string(), exr.string(), options);
                checkImports(exr, scratch);
            }
        }
        const std::filesystem::path renderer = dir / "seed-renderer-scanline.exr";
        writeRendererStyleExr(renderer);
        checkImports(renderer, scratch);
        std::filesystem::remove_all(scratch);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_make_exr_corpus: %s\n", e.what());
        return 1;
    }
    return 0;
}
