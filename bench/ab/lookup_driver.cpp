// A/B driver for warm random lookups: the same 4096 random points over the
// non-empty pixels of a map, `passes` warm passes on one thread, through
//   direct  four in-memory VisibilityFunction::evaluate (bilinear weights)
//   ctx     LookupContext::raster
//   sys     ShadowSystem::lookup, one point per call (threadTiles from the 4th argument)
//   batch   ShadowSystem::lookup, all 4096 points per call
// Built outside CMake against two library trees, so that the previous
// implementation (without ShadowSystem: -DDSM_AB_PREVIOUS) and this one run
// side by side; and under valgrind --tool=callgrind with 15 and 0 passes for
// instructions per lookup (bench/COMPONENTS.md, "Shadow system"):
//   g++ -std=c++20 -O2 -DDSM_STATIC_DEFINE -I<tree>/libdsm/*/include lookup_driver.cpp
//       <build>/libdsm/libdsm_core.a -lz -lpthread -o driver
//   driver MAP.dsm MODE [passes] [threadTiles]
#include <dsm/lookup.h>
#include <dsm/reader.h>
#ifndef DSM_AB_PREVIOUS
#include <dsm/shadow_system.h>
#endif
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <vector>
using namespace dsm;
int main(int argc, char** argv) {
    const char* mode = argc > 2 ? argv[2] : "ctx";
    const int reps = argc > 3 ? atoi(argv[3]) : 50;
    auto map = DeepShadowMap::open(argv[1]);
    const MapInfo& info = map->info();
    std::mt19937_64 rng(1);
    std::vector<std::array<double,3>> pts;
    std::uniform_int_distribution<uint32_t> ux(0, info.width - 1), uy(0, info.height - 1);
    std::uniform_real_distribution<double> u(0, 1);
    while (pts.size() < 4096) {
        uint32_t x = ux(rng), y = uy(rng);
        auto f = map->pixel(0, x, y);
        if (f->empty()) continue;
        pts.push_back({x + u(rng), y + u(rng), f->z(0) + (f->z(f->size()-1) - f->z(0)) * u(rng)});
    }
    LookupOptions o;
    o.bias = 0.0;  // as the direct evaluation
    double sum = 0;
    auto t0 = std::chrono::steady_clock::now();
    if (!strcmp(mode, "direct")) {
        std::vector<VisibilityFunction> px;
        for (uint32_t y = 0; y < info.height; ++y) for (uint32_t x = 0; x < info.width; ++x) px.push_back(map->pixel(0, x, y).view().toFunction(false));
        auto run = [&](const std::array<double,3>& p) {
            const double cx = p[0] - 0.5, cy = p[1] - 0.5; const double fx = std::floor(cx), fy = std::floor(cy);
            const long x0 = long(fx), y0 = long(fy); const double wx[2] = {1.0 - (cx - fx), cx - fx}, wy[2] = {1.0 - (cy - fy), cy - fy};
            double s = 0, t = 0;
            for (int j = 0; j < 2; ++j) for (int i = 0; i < 2; ++i) { long x = x0 + i, y = y0 + j;
                if (x < 0 || y < 0 || x >= long(info.width) || y >= long(info.height)) continue;
                double w = wx[i] * wy[j]; s += w * px[size_t(y) * info.width + size_t(x)].evaluate(p[2]); t += w; }
            return t > 0 ? s / t : 1.0; };
        for (auto& p : pts) sum += run(p);
        t0 = std::chrono::steady_clock::now();
        for (int r = 0; r < reps; ++r) for (auto& p : pts) sum += run(p);
    } else if (!strcmp(mode, "ctx")) {
        LookupContext ctx(map);
        for (auto& p : pts) sum += ctx.raster(p[0], p[1], p[2], o).v[0];
        t0 = std::chrono::steady_clock::now();
        for (int r = 0; r < reps; ++r) for (auto& p : pts) sum += ctx.raster(p[0], p[1], p[2], o).v[0];
    }
#ifndef DSM_AB_PREVIOUS
    else {
        ShadowSystemOptions so; so.threadTiles = argc > 4 ? atoi(argv[4]) : 64;
        auto sys = ShadowSystem::create(so);
        auto h = sys->open(argv[1]);
        auto th = sys->createThread();
        std::vector<LookupResult> res(pts.size());
        LookupResult r;
        for (auto& p : pts) { sys->lookup(*th, h, LookupSpace::raster, p, o, r); sum += r.v[0]; }
        t0 = std::chrono::steady_clock::now();
        if (!strcmp(mode, "batch")) {
            for (int k = 0; k < reps; ++k) { sys->lookup(*th, h, LookupSpace::raster, pts, o, res); sum += res[7].v[0]; }
        } else {
            for (int k = 0; k < reps; ++k) for (auto& p : pts) { sys->lookup(*th, h, LookupSpace::raster, p, o, r); sum += r.v[0]; }
        }
    }
#endif
    double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("%s: %.2f M/s (sum %g)\n", mode, reps * pts.size() / dt / 1e6, sum);
}
