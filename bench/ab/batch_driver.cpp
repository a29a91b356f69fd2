// A/B driver for batched lookups on a map larger than the processor's caches:
// every tile of level 0 is cached first, then 2^20 uniform random raster
// points are looked up through ShadowSystem::lookup in batches of 4096,
// 65,536, 2^18 and 2^20 points (best of 3). Built outside CMake like
// lookup_driver.cpp; run on a 4096² map (dsm-build examples/hairball.json
// -r 4096 -s 1 -o hb4096.dsm):
//   g++ -std=c++20 -O2 -DDSM_STATIC_DEFINE -I<tree>/libdsm/*/include batch_driver.cpp
//       <build>/libdsm/libdsm_core.a -lz -lpthread -o batch_driver
//   batch_driver hb4096.dsm
#include <dsm/shadow_system.h>
#include <chrono>
#include <cstdio>
#include <random>
#include <vector>
using namespace dsm;
int main(int argc, char** argv) {
    ShadowSystemOptions o; o.cacheBytes = size_t(16) << 30;
    auto sys = ShadowSystem::create(o);
    auto h = sys->open(argv[1]);
    auto info = sys->map(h)->info();
    auto th = sys->createThread();
    LookupOptions lo; lo.level = 0; lo.bias = 0.0; LookupResult r;
    for (uint32_t y = 0; y < info.height; y += info.tileSize) for (uint32_t x = 0; x < info.width; x += info.tileSize)
        sys->lookup(*th, h, LookupSpace::raster, {x + 0.5, y + 0.5, 1.0}, lo, r);
    std::mt19937_64 rng(4);
    std::uniform_real_distribution<double> ux(0.0, info.width), uy(0.0, info.height), uz(0.5, 3.5);
    std::vector<std::array<double,3>> pts(1 << 20);
    for (auto& p : pts) p = {ux(rng), uy(rng), uz(rng)};
    std::vector<LookupResult> res(pts.size());
    for (size_t batch : {size_t(4096), size_t(65536), size_t(1) << 18, size_t(1) << 20}) {
        double best = 1e9;
        for (int rep = 0; rep < 3; ++rep) {
            auto t0 = std::chrono::steady_clock::now();
            for (size_t b = 0; b < pts.size(); b += batch)
                sys->lookup(*th, h, LookupSpace::raster, Span<const std::array<double,3>>(pts.data() + b, batch), lo, Span<LookupResult>(res.data() + b, batch));
            best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        }
        std::printf("batch %zu: %.2f M/s\n", batch, pts.size() / best / 1e6);
    }
}
