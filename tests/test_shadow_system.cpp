// Tests for ShadowSystem: answers equal LookupContext's to the bit (every
// filter, level and space, single and batched), threads agree with one
// thread, many maps under a small open-file cap agree with separate opens,
// the per-thread state does not grow with the number of maps, and failures
// on the shading path are values, never exceptions.
#include <gtest/gtest.h>

#include <dsm/dsm.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

using namespace dsm;
using dsm::test::Image;
using dsm::test::TempDir;

// Random functions: RGB and monochrome pixels, up to two layers, empty pixels.
Image randomImage(std::uint32_t w, std::uint32_t h, std::uint64_t seed, int channels, int layers) {
    std::mt19937_64 rng(seed);
    return dsm::test::makeImage(w, h, [&](std::uint32_t x, std::uint32_t y) {
        if ((x * 5 + y * 3) % 11 == 0) return VisibilityFunction(channels == 3 && (x + y) % 2 ? 3 : 1);
        const int c = channels == 3 && (x + 2 * y) % 3 != 0 ? 3 : 1;
        return dsm::test::randomFunction(rng, c, layers > 1, 1 + static_cast<int>((x + y) % layers), 8);
    });
}

// "m<i>.dsm", built piece by piece: GCC 12 at -O3 warns, a false -Wrestrict,
// about its own inlined "m" + std::string&&.
std::string numberedMapName(int i) {
    std::string name = "m";
    name += std::to_string(i);
    name += ".dsm";
    return name;
}

std::string writeRandomMap(const TempDir& dir, const std::string& name, std::uint64_t seed, int channels = 3,
                           int layers = 2, std::uint32_t w = 37, std::uint32_t h = 29) {
    WriterOptions o;
    o.tileSize = 8;
    o.channels = channels;
    o.maxLayers = layers;
    o.tolerance = 0.01;
    const auto path = dir / name;
    dsm::test::writeMap(path, o, randomImage(w, h, seed, channels, layers), seed);
    return path.string();
}

bool sameBits(const LookupResult& a, const LookupResult& b) {
    return std::memcmp(a.v.data(), b.v.data(), sizeof(double) * 3) == 0 && a.channels == b.channels &&
           std::memcmp(&a.errorBound, &b.errorBound, sizeof(double)) == 0 && a.pixelsUsed == b.pixelsUsed;
}

std::vector<LookupOptions> allOptions() {
    std::vector<LookupOptions> out;
    for (PixelFilter f : {PixelFilter::Box, PixelFilter::Triangle, PixelFilter::Gaussian})
        for (double w : {0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 9.0})
            for (int level : {-1, 0, 1, 3}) {
                LookupOptions o;
                o.filter = f;
                o.filterWidth = w;
                if (level >= 0) o.level = static_cast<unsigned>(level);
                o.bias = level == 1 ? 0.01 : 0.0;
                out.push_back(o);
            }
    return out;
}

// Points of a space around and inside the map, depths through its range.
std::vector<std::array<double, 3>> pointsFor(const MapInfo& info, LookupSpace space, std::uint64_t seed, int n) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> ux(-1.0, info.width + 1.0), uy(-1.0, info.height + 1.0), uz(-0.2, 1.2);
    std::vector<std::array<double, 3>> pts;
    for (int i = 0; i < n; ++i) {
        const double rx = ux(rng), ry = uy(rng), z = uz(rng);
        if (space == LookupSpace::raster) pts.push_back({rx, ry, z});
        else pts.push_back({(rx / info.width - 0.5) * 0.8, (ry / info.height - 0.5) * 0.8, 0.5 + z});
    }
    pts.push_back({info.width * 0.5, info.height * 0.5, 0.5});  // a few exact spots
    pts.push_back({0.0, 0.0, 0.3});
    pts.push_back({3.5, 2.5, 0.6});  // a pixel centre
    return pts;
}

TEST(ShadowSystem, SingleAndBatchedLookupsEqualLookupContextToTheBit) {
    TempDir dir;
    const std::string rgb = writeRandomMap(dir, "rgb.dsm", 11, 3, 2);
    const std::string mono = writeRandomMap(dir, "mono.dsm", 12, 1, 1, 64, 48);
    auto system = ShadowSystem::create();
    auto thread = system->createThread();
    for (const std::string& path : {rgb, mono}) {
        MapHandle* handle = system->open(path);
        ASSERT_EQ(handle, system->open(path)) << "one handle per path";
        auto map = DeepShadowMap::open(path);
        LookupContext context(map);
        for (LookupSpace space : {LookupSpace::raster, LookupSpace::light, LookupSpace::world}) {
            const auto pts = pointsFor(map->info(), space, 5, 60);
            std::vector<LookupResult> batch(pts.size());
            for (const LookupOptions& o : allOptions()) {
                ASSERT_EQ(system->lookup(*thread, handle, space, pts, o, batch), 0u);
                for (std::size_t i = 0; i < pts.size(); ++i) {
                    const LookupResult want = space == LookupSpace::raster ? context.raster(pts[i][0], pts[i][1], pts[i][2], o)
                                              : space == LookupSpace::light ? context.light(pts[i], o)
                                                                            : context.world(pts[i], o);
                    LookupResult one;
                    ASSERT_TRUE(system->lookup(*thread, handle, space, pts[i], o, one));
                    ASSERT_TRUE(sameBits(one, want)) << path << " point " << i;
                    ASSERT_TRUE(sameBits(batch[i], want)) << path << " batched point " << i;
                }
            }
        }
    }
}

TEST(ShadowSystem, EightThreadsAgreeWithOneUnderASmallBudget) {
    TempDir dir;
    const std::string path = writeRandomMap(dir, "map.dsm", 21, 3, 2, 96, 80);
    ShadowSystemOptions options;
    options.cacheBytes = 64 << 10;  // far below the map: tiles come and go
    options.threadTiles = 4;
    auto system = ShadowSystem::create(options);
    MapHandle* handle = system->open(path);
    const auto pts = pointsFor(system->map(handle)->info(), LookupSpace::raster, 9, 600);
    LookupOptions o;
    o.filter = PixelFilter::Gaussian;
    o.filterWidth = 3.0;
    std::vector<LookupResult> want(pts.size());
    {
        auto one = system->createThread();
        for (std::size_t i = 0; i < pts.size(); ++i)
            ASSERT_TRUE(system->lookup(*one, handle, LookupSpace::raster, pts[i], o, want[i]));
    }
    std::vector<int> mismatches(8, 0);
    std::vector<std::thread> threads;
    for (int t = 0; t < 8; ++t)
        threads.emplace_back([&, t] {
            auto state = system->createThread();
            std::vector<LookupResult> got(pts.size());
            for (int rep = 0; rep < 2; ++rep) {
                if ((t + rep) % 2) {
                    system->lookup(*state, handle, LookupSpace::raster, pts, o, got);
                } else {
                    for (std::size_t i = 0; i < pts.size(); ++i)
                        system->lookup(*state, handle, LookupSpace::raster, pts[i], o, got[i]);
                }
                for (std::size_t i = 0; i < pts.size(); ++i)
                    if (!sameBits(got[i], want[i])) ++mismatches[t];
            }
        });
    for (auto& th : threads) th.join();
    for (int t = 0; t < 8; ++t) EXPECT_EQ(mismatches[t], 0) << "thread " << t;
    const ShadowSystemStats s = system->stats();
    EXPECT_GT(s.cache.evictions, 0u) << "the budget was meant to be exceeded";
}

TEST(ShadowSystem, HundredMapsUnderEightOpenFilesAgreeWithSeparateOpens) {
    TempDir dir;
    std::vector<std::string> paths;
    for (int i = 0; i < 100; ++i)
        paths.push_back(writeRandomMap(dir, numberedMapName(i), 100 + i, i % 2 ? 3 : 1, 1, 20, 12));
    ShadowSystemOptions options;
    options.maxOpenFiles = 8;
    options.cacheBytes = 32 << 10;  // small: tiles are read again, so files reopen
    auto system = ShadowSystem::create(options);
    std::vector<MapHandle*> handles;
    for (const std::string& p : paths) handles.push_back(system->open(p));
    EXPECT_LE(system->stats().filesOpen, 8u);
    auto thread = system->createThread();
    LookupOptions o;
    for (int round = 0; round < 2; ++round)
        for (std::size_t m = 0; m < paths.size(); ++m) {
            auto map = DeepShadowMap::open(paths[m]);
            LookupContext context(map);
            for (const auto& p : pointsFor(map->info(), LookupSpace::raster, m, 20)) {
                LookupResult got;
                ASSERT_TRUE(system->lookup(*thread, handles[m], LookupSpace::raster, p, o, got))
                    << thread->lastFailure().message;
                ASSERT_TRUE(sameBits(got, context.raster(p[0], p[1], p[2], o))) << paths[m];
            }
        }
    const ShadowSystemStats s = system->stats();
    EXPECT_EQ(s.maps, 100u);
    EXPECT_LE(s.filesOpen, 8u);
    EXPECT_LE(s.peakFilesOpen, 8u);  // one thread: never more than the cap
    EXPECT_GT(s.reopens, 0u);
    EXPECT_EQ(s.fileOpens, 100u + s.reopens);
}

TEST(ShadowSystem, PerThreadStateDoesNotGrowWithTheNumberOfMaps) {
    TempDir dir;
    auto system = ShadowSystem::create();
    auto thread = system->createThread();
    LookupResult r;
    const std::size_t before = thread->memoryBytes();
    for (int i = 0; i < 100; ++i) {
        MapHandle* h = system->open(writeRandomMap(dir, numberedMapName(i), 300 + i, 1, 1, 16, 16));
        system->lookup(*thread, h, LookupSpace::raster, {8.0, 8.0, 0.5}, LookupOptions{}, r);
    }
    EXPECT_EQ(thread->memoryBytes(), before);
    EXPECT_LT(before, std::size_t(64) << 10);
}

TEST(ShadowSystem, FailuresAreValuesAndNamedOnTheThread) {
    TempDir dir;
    const std::string path = writeRandomMap(dir, "map.dsm", 31, 1, 1);
    auto system = ShadowSystem::create();
    auto other = ShadowSystem::create();
    MapHandle* handle = system->open(path);
    auto thread = system->createThread();
    auto foreign = other->createThread();
    LookupResult r;
    const LookupResult failed = [] {
        LookupResult f;
        f.errorBound = 1.0;
        return f;
    }();
    EXPECT_FALSE(system->lookup(*thread, handle, LookupSpace::raster, {1.0, std::nan(""), 0.5}, {}, r));
    EXPECT_EQ(thread->lastFailure().code, ErrorCode::argument);
    EXPECT_TRUE(sameBits(r, failed));
    EXPECT_FALSE(system->lookup(*thread, nullptr, LookupSpace::raster, {1.0, 1.0, 0.5}, {}, r));
    EXPECT_EQ(thread->lastFailure().code, ErrorCode::argument);
    EXPECT_FALSE(system->lookup(*foreign, handle, LookupSpace::raster, {1.0, 1.0, 0.5}, {}, r));
    EXPECT_NE(foreign->lastFailure().message.find("another shadow system"), std::string::npos);

    // A batch: the bad points fail, the others are answered.
    std::vector<std::array<double, 3>> pts = {{1.0, 1.0, 0.5}, {std::nan(""), 1.0, 0.5}, {2.0, 3.0, 0.2}};
    std::vector<LookupResult> out(3);
    LookupOptions negative;
    EXPECT_EQ(system->lookup(*thread, handle, LookupSpace::raster, pts, negative, out), 1u);
    EXPECT_TRUE(sameBits(out[1], failed));
    LookupContext context(DeepShadowMap::open(path));
    EXPECT_TRUE(sameBits(out[0], context.raster(1.0, 1.0, 0.5)));
    EXPECT_TRUE(sameBits(out[2], context.raster(2.0, 3.0, 0.2)));
    negative.filterWidth = -1.0;
    EXPECT_EQ(system->lookup(*thread, handle, LookupSpace::raster, pts, negative, out), 3u);

    EXPECT_THROW(system->open((dir / "missing.dsm").string()), Error);
}

TEST(ShadowSystem, AReplacedFileFailsItsReadInsteadOfMixingTwoMaps) {
    TempDir dir;
    const std::string a = writeRandomMap(dir, "a.dsm", 41, 1, 1, 24, 24);
    const std::string b = writeRandomMap(dir, "b.dsm", 42, 1, 1, 24, 24);
    ShadowSystemOptions options;
    options.maxOpenFiles = 1;
    options.cacheBytes = 0;  // every tile read again
    options.threadTiles = 2;
    auto system = ShadowSystem::create(options);
    MapHandle* ha = system->open(a);
    MapHandle* hb = system->open(b);  // closes a
    auto thread = system->createThread();
    LookupResult r;
    // a is replaced (a new inode) while closed: its next read must fail.
    const std::string c = writeRandomMap(dir, "c.dsm", 43, 1, 1, 24, 24);
    std::filesystem::rename(c, a);
    bool failed = false;
    for (double x = 0.5; x < 24.0 && !failed; x += 8.0)
        failed = !system->lookup(*thread, ha, LookupSpace::raster, {x, x, 0.5}, {}, r);
    EXPECT_TRUE(failed);
    EXPECT_EQ(thread->lastFailure().code, ErrorCode::io) << thread->lastFailure().message;
    EXPECT_TRUE(system->lookup(*thread, hb, LookupSpace::raster, {3.0, 3.0, 0.5}, {}, r));
}

}  // namespace
