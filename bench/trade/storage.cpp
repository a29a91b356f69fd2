// Study 5: storage against OpenEXR deep. One build hands its raw sample rays
// (BuildOptions::sampleRays) to an OpenEXR deep scanline file, ZIPS, as a deep
// renderer would write them: per pixel, every ray's surface hits as point
// samples (Z, A = opacity / N: each ray covers 1/N of the pixel) and every
// ray's volume segments as volumetric samples (Z, ZBack, A). The same build
// writes our .dsm at the default tolerance. Both files are then read whole.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepScanLineInputFile.h>
#include <OpenEXR/ImfDeepScanLineOutputFile.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfPartType.h>

#include "trade.h"

namespace dsm::trade {

namespace {

struct DeepSample {
    float z, zBack, alpha;
};

std::uint64_t writeDeepExr(const std::string& path, std::uint32_t width, std::uint32_t height,
                           std::vector<std::vector<DeepSample>>& pixels) {
    Imf::Header header(static_cast<int>(width), static_cast<int>(height));
    header.compression() = Imf::ZIPS_COMPRESSION;
    header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
    header.channels().insert("ZBack", Imf::Channel(Imf::FLOAT));
    header.channels().insert("A", Imf::Channel(Imf::FLOAT));
    header.setType(Imf::DEEPSCANLINE);
    std::vector<unsigned> counts(pixels.size());
    std::vector<float*> zs(pixels.size()), zbacks(pixels.size()), alphas(pixels.size());
    std::vector<std::vector<float>> storage(pixels.size());
    for (std::size_t i = 0; i < pixels.size(); ++i) {
        auto& p = pixels[i];
        std::sort(p.begin(), p.end(), [](const DeepSample& a, const DeepSample& b) { return a.z < b.z; });
        counts[i] = static_cast<unsigned>(p.size());
        storage[i].resize(3 * p.size());
        for (std::size_t k = 0; k < p.size(); ++k) {
            storage[i][k] = p[k].z;
            storage[i][p.size() + k] = p[k].zBack;
            storage[i][2 * p.size() + k] = p[k].alpha;
        }
        zs[i] = storage[i].data();
        zbacks[i] = storage[i].data() + p.size();
        alphas[i] = storage[i].data() + 2 * p.size();
    }
    Imf::DeepFrameBuffer frame;
    frame.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), sizeof(unsigned),
                                            sizeof(unsigned) * width));
    const std::size_t ps = sizeof(float*);
    frame.insert("Z", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(zs.data()), ps, ps * width, sizeof(float)));
    frame.insert("ZBack",
                 Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(zbacks.data()), ps, ps * width, sizeof(float)));
    frame.insert("A", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(alphas.data()), ps, ps * width, sizeof(float)));
    {
        Imf::DeepScanLineOutputFile file(path.c_str(), header);
        file.setFrameBuffer(frame);
        file.writePixels(static_cast<int>(height));
    }
    return std::filesystem::file_size(path);
}

/// Reads every sample of a deep scanline file; returns the sample count. The
/// frame buffer is set once: its per-pixel pointers are filled in after the
/// sample counts are read.
std::uint64_t readDeepExr(const std::string& path) {
    Imf::DeepScanLineInputFile file(path.c_str());
    const auto window = file.header().dataWindow();
    const int width = window.max.x - window.min.x + 1, height = window.max.y - window.min.y + 1;
    const std::size_t n = std::size_t(width) * height;
    std::vector<unsigned> counts(n);
    std::vector<float*> pointers(3 * n);
    Imf::DeepFrameBuffer frame;
    frame.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), sizeof(unsigned),
                                            sizeof(unsigned) * width));
    const std::size_t ps = sizeof(float*);
    const char* names[] = {"Z", "ZBack", "A"};
    for (std::size_t c = 0; c < 3; ++c)
        frame.insert(names[c], Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(pointers.data() + c * n), ps,
                                              ps * width, sizeof(float)));
    file.setFrameBuffer(frame);
    file.readPixelSampleCounts(window.min.y, window.max.y);
    std::uint64_t total = 0;
    for (unsigned c : counts) total += c;
    std::vector<float> data(3 * total);
    std::uint64_t at = 0;
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t c = 0; c < 3; ++c) pointers[c * n + i] = data.data() + c * total + at;
        at += counts[i];
    }
    file.readPixels(window.min.y, window.max.y);
    return total;
}

}  // namespace

Json studyStorage(const Config& config, const Scene& scene, const std::string& name) {
    const std::uint32_t resolution = config.smoke ? 16 : 128, spp = config.smoke ? 4 : 64;
    std::vector<std::vector<DeepSample>> pixels(std::size_t(resolution) * resolution);
    std::mutex mutex;
    BuildOptions o;
    o.width = o.height = resolution;
    o.samplesPerPixel = spp;
    if (config.threads != 0) o.threads = config.threads;  // 0: all cores
    o.sampleRays = [&](std::uint32_t x, std::uint32_t y, std::span<const SampleRay> rays) {
        std::vector<DeepSample> samples;
        const float share = 1.0f / static_cast<float>(rays.size());
        for (const SampleRay& ray : rays) {
            for (const SurfaceHit& h : ray.hits) samples.push_back({h.z, h.z, h.opacity[0] * share});
            for (std::size_t k = 0; k + 1 < ray.volume.size(); ++k) {
                const VolumeSample &a = ray.volume[k], &b = ray.volume[k + 1];
                const double tau = 0.5 * (double(b.z) - a.z) * (double(a.extinction) + b.extinction);
                if (b.z > a.z && tau > 0.0)
                    samples.push_back({a.z, b.z, static_cast<float>((1.0 - std::exp(-tau)) * share)});
            }
        }
        std::lock_guard<std::mutex> lock(mutex);
        pixels[std::size_t(y) * resolution + x] = std::move(samples);
    };
    const auto dsmPath = config.workDir / (name + "-storage.dsm");
    const auto exrPath = config.workDir / (name + "-storage-deep.exr");
    const BuildStats stats = buildMap(scene, o, dsmPath.string());
    std::uint64_t samples = 0;
    for (const auto& p : pixels) samples += p.size();
    const std::uint64_t exrBytes = writeDeepExr(exrPath.string(), resolution, resolution, pixels);

    double exrSeconds = 1e30, dsmSeconds = 1e30;
    std::uint64_t readSamples = 0, readVertices = 0;
    for (int r = 0; r < 3; ++r) {
        exrSeconds = std::min(exrSeconds, timed([&] { readSamples = readDeepExr(exrPath.string()); }));
        dsmSeconds = std::min(dsmSeconds, timed([&] {
                                  ReaderOptions reader;
                                  reader.cache = TileCache::create(std::size_t(1) << 32);
                                  const auto map = DeepShadowMap::open(dsmPath.string(), reader);
                                  readVertices = 0;
                                  for (std::uint32_t y = 0; y < resolution; ++y)
                                      for (std::uint32_t x = 0; x < resolution; ++x)
                                          readVertices += map->pixel(0, x, y)->size();
                              }));
    }
    const auto map = DeepShadowMap::open(dsmPath.string());
    const MapInfo& info = map->info();
    std::uint64_t allLevels = 0;
    for (const LevelInfo& l : info.levels) allLevels += l.storedBytes;
    Json out{{"scene", name},
             {"resolution", resolution},
             {"spp", spp},
             {"tolerance", stats.tolerance},
             {"raw_samples", samples},
             {"exr_samples_read", readSamples},
             {"exr_bytes", exrBytes},
             {"dsm_bytes", info.fileBytes},
             {"dsm_level0_bytes", info.levels[0].storedBytes},
             {"dsm_pyramid_ratio", double(allLevels) / double(std::max<std::uint64_t>(1, info.levels[0].storedBytes))},
             {"dsm_vertices", readVertices},
             {"exr_read_seconds", exrSeconds},
             {"dsm_read_seconds", dsmSeconds}};
    std::printf("  %s: %llu raw samples: deep EXR %llu bytes (read %.3f s) vs .dsm %llu bytes (read level 0 %.3f s)\n",
                name.c_str(), static_cast<unsigned long long>(samples), static_cast<unsigned long long>(exrBytes),
                exrSeconds, static_cast<unsigned long long>(info.fileBytes), dsmSeconds);
    return out;
}

}  // namespace dsm::trade
