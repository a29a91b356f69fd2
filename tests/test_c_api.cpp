// The C API (dsm/dsm_c.h) against the C++ API it wraps: every function, the
// three ways of opening a map, batched lookups and soft shadows equal to the
// C++ ones bit for bit, a map written through it read back, and every failure
// path returning a code and a message (never an exception).
#include <dsm/dsm.h>
#include <dsm/dsm_c.h>
#include <gtest/gtest.h>

#include <bit>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "map_fixtures.h"
#include "temp_dir.h"

namespace {

using dsm::test::TempDir;
using Bytes = std::vector<std::uint8_t>;

constexpr std::size_t kHeaderSize = 296;  // tiles follow the 1.1 header (spec/dsm-format.md)

bool sameBits(double a, double b) { return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b); }

// Read callbacks over a byte vector that count their calls; reads touching
// [failFrom, failTo) fail.
struct Reads {
    const Bytes* bytes = nullptr;
    std::uint64_t failFrom = 0, failTo = 0;
    int released = 0;
};

int64_t readBytes(void* user, uint64_t offset, void* buffer, size_t count) {
    const Reads& r = *static_cast<const Reads*>(user);
    if (offset < r.failTo && offset + count > r.failFrom) return -1;
    if (offset >= r.bytes->size()) return 0;
    const std::size_t n = std::min<std::size_t>(count, r.bytes->size() - offset);
    std::memcpy(buffer, r.bytes->data() + offset, n);
    return static_cast<int64_t>(n);
}

void releaseReads(void* user) { ++static_cast<Reads*>(user)->released; }

dsm_read_callbacks callbacksFor(Reads& reads) {
    dsm_read_callbacks c = DSM_READ_CALLBACKS_INIT;
    c.user = &reads;
    c.total_bytes = reads.bytes->size();
    c.read = readBytes;
    c.release = releaseReads;
    return c;
}

// Expects `result` to be the failure `want`, with a message holding `part`.
void expectFailure(dsm_result result, dsm_result want, const std::string& part) {
    EXPECT_EQ(result, want) << dsm_result_name(result) << ": " << dsm_last_error_message();
    EXPECT_EQ(dsm_last_error(), want);
    const std::string message = dsm_last_error_message();
    EXPECT_FALSE(message.empty());
    EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
}

class CApi : public ::testing::Test {
protected:
    void SetUp() override {
        std::mt19937_64 rng(21);
        image_ = dsm::test::makeImage(40, 24, [&](std::uint32_t x, std::uint32_t y) {
            if ((x + y) % 11 == 0) return dsm::VisibilityFunction(1, true);
            return dsm::test::randomFunction(rng, 1, true, 2, 6, 1.0f);
        });
        options_.tileSize = 8;
        options_.counts = true;
        options_.maxLayers = 2;
        options_.tolerance = 0.01;
        options_.camera.worldToLight = {1, 0, 0, 0.25, 0, 1, 0, -0.5, 0, 0, 1, 0, 0, 0, 0, 1};
        options_.metadata = "{\"test\":\"c api\"}";
        dsm::test::writeMap(path_, options_, image_);
        bytes_ = dsm::test::readFile(path_);
        dsm_clear_last_error();
    }

    // Points spread over the map (and beyond it) in the given space.
    std::vector<double> points(int space, std::size_t count, std::uint64_t seed) const {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> unit(-1.2, 1.2), depth(0.5, 6.0), rx(-2.0, 42.0), ry(-2.0, 26.0);
        std::vector<double> p;
        for (std::size_t i = 0; i < count; ++i) {
            const double z = depth(rng);
            if (space == DSM_SPACE_RASTER)
                p.insert(p.end(), {rx(rng), ry(rng), z});
            else
                p.insert(p.end(), {unit(rng) * z, unit(rng) * z, z});
        }
        return p;
    }

    // The map from memory named "damaged", with a bit of tile 0,0 of level 0
    // (written first) flipped; null if it does not open.
    dsm_map* openDamaged() {
        damaged_ = bytes_;
        damaged_[kHeaderSize + 3] ^= 0x10;
        dsm_map* map = nullptr;
        return dsm_map_open_memory(damaged_.data(), damaged_.size(), "damaged", nullptr, &map) == DSM_OK ? map
                                                                                                         : nullptr;
    }

    TempDir dir_;
    std::string path_ = (dir_ / "map.dsm").string();
    dsm::WriterOptions options_;
    dsm::test::Image image_;
    Bytes bytes_;
    Bytes damaged_;  // what openDamaged() reads from
};

TEST_F(CApi, ResultNamesFollowTheErrorCodes) {
    EXPECT_STREQ(dsm_result_name(DSM_OK), "ok");
    const std::pair<dsm_result, dsm::ErrorCode> codes[] = {{DSM_ERROR_IO, dsm::ErrorCode::io},
                                                           {DSM_ERROR_FORMAT, dsm::ErrorCode::format},
                                                           {DSM_ERROR_CORRUPT, dsm::ErrorCode::corrupt},
                                                           {DSM_ERROR_LIMIT, dsm::ErrorCode::limit},
                                                           {DSM_ERROR_ARGUMENT, dsm::ErrorCode::argument},
                                                           {DSM_ERROR_SCENE, dsm::ErrorCode::scene},
                                                           {DSM_ERROR_UNSUPPORTED, dsm::ErrorCode::unsupported},
                                                           {DSM_ERROR_INTERNAL, dsm::ErrorCode::internal}};
    for (const auto& [result, code] : codes) EXPECT_STREQ(dsm_result_name(result), dsm::errorCodeName(code));
    EXPECT_STREQ(dsm_result_name(static_cast<dsm_result>(99)), "unknown");
}

TEST_F(CApi, InfoLevelsAndMetadataAreTheMapsOwn) {
    dsm_map* map = nullptr;
    ASSERT_EQ(dsm_map_open(path_.c_str(), nullptr, &map), DSM_OK) << dsm_last_error_message();
    const auto cpp = dsm::DeepShadowMap::open(path_);
    const dsm::MapInfo& want = cpp->info();
    dsm_map_info info;
    info.size = sizeof info;
    ASSERT_EQ(dsm_map_get_info(map, &info), DSM_OK);
    EXPECT_EQ(info.size, sizeof info);
    EXPECT_EQ(info.width, 40u);
    EXPECT_EQ(info.height, 24u);
    EXPECT_EQ(info.tile_size, 8u);
    EXPECT_EQ(info.channels, 1);
    EXPECT_EQ(info.has_counts, 1);
    EXPECT_EQ(info.max_layers, 2);
    EXPECT_EQ(info.level_count, want.levels.size());
    EXPECT_EQ(info.projection, DSM_PROJECTION_PERSPECTIVE);
    for (int i = 0; i < 16; ++i) EXPECT_EQ(info.world_to_light[i], want.camera.worldToLight[std::size_t(i)]);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(info.screen_window[i], want.camera.screenWindow[std::size_t(i)]);
    EXPECT_EQ(info.near_plane, want.camera.nearPlane);
    EXPECT_EQ(info.filter, static_cast<int32_t>(want.filter));
    EXPECT_EQ(info.filter_width, want.filterWidth);
    EXPECT_EQ(info.error_bound, want.levels[0].errorBound);
    EXPECT_EQ(info.file_bytes, bytes_.size());
    EXPECT_EQ(info.version_major, want.versionMajor);
    EXPECT_EQ(info.version_minor, want.versionMinor);
    for (uint32_t l = 0; l < info.level_count; ++l) {
        dsm_level_info level;
        ASSERT_EQ(dsm_map_get_level(map, l, &level), DSM_OK);
        const dsm::LevelInfo& L = want.levels[l];
        EXPECT_EQ(level.width, L.width);
        EXPECT_EQ(level.height, L.height);
        EXPECT_EQ(level.tiles_x, L.tilesX);
        EXPECT_EQ(level.tiles_y, L.tilesY);
        EXPECT_EQ(level.tolerance, L.tolerance);
        EXPECT_EQ(level.error_bound, L.errorBound);
        EXPECT_EQ(level.vertex_count, L.vertexCount);
        EXPECT_EQ(level.non_empty_pixels, L.nonEmptyPixels);
        EXPECT_EQ(level.stored_bytes, L.storedBytes);
    }
    const char* json = nullptr;
    size_t length = 0;
    ASSERT_EQ(dsm_map_get_metadata(map, &json, &length), DSM_OK);
    EXPECT_EQ(std::string(json, length), want.metadata);

    // An older caller's smaller struct is filled up to its size and no further.
    dsm_map_info older;
    std::memset(&older, 0xAB, sizeof older);
    older.size = offsetof(dsm_map_info, tile_size);
    ASSERT_EQ(dsm_map_get_info(map, &older), DSM_OK);
    EXPECT_EQ(older.size, offsetof(dsm_map_info, tile_size));
    EXPECT_EQ(older.height, 24u);
    EXPECT_EQ(older.tile_size, 0xABABABABu);
    dsm_map_close(map);
}

TEST_F(CApi, LookupsEqualTheCppLookupsBitForBit) {
    dsm_map* map = nullptr;
    ASSERT_EQ(dsm_map_open(path_.c_str(), nullptr, &map), DSM_OK) << dsm_last_error_message();
    dsm_lookup_context* context = nullptr;
    ASSERT_EQ(dsm_lookup_context_create(map, &context), DSM_OK);
    const auto cppMap = dsm::DeepShadowMap::open(path_);
    dsm::LookupContext cpp(cppMap);
    const std::size_t n = 1000;
    int shadowed = 0;
    for (int space : {DSM_SPACE_WORLD, DSM_SPACE_LIGHT, DSM_SPACE_RASTER})
        for (int filter : {DSM_FILTER_BOX, DSM_FILTER_TRIANGLE, DSM_FILTER_GAUSSIAN})
            for (int level : {DSM_LEVEL_AUTO, 0, 1}) {
                dsm_lookup_options o = DSM_LOOKUP_OPTIONS_INIT;
                o.space = space;
                o.filter = filter;
                o.filter_width = filter == DSM_FILTER_BOX ? 1.5 : 3.0;
                o.level = level;
                o.bias = 0.01;
                const std::vector<double> p = points(space, n, 100u + std::uint64_t(space * 10 + filter));
                std::vector<double> v(3 * n), bounds(n);
                ASSERT_EQ(dsm_lookup(context, &o, n, p.data(), v.data(), bounds.data()), DSM_OK)
                    << dsm_last_error_message();
                dsm::LookupOptions co;
                co.filter = static_cast<dsm::PixelFilter>(filter);
                co.filterWidth = o.filter_width;
                if (level != DSM_LEVEL_AUTO) co.level = static_cast<unsigned>(level);
                co.bias = o.bias;
                for (std::size_t i = 0; i < n; ++i) {
                    const std::array<double, 3> q{p[3 * i], p[3 * i + 1], p[3 * i + 2]};
                    const dsm::LookupResult want = space == DSM_SPACE_WORLD   ? cpp.world(q, co)
                                                   : space == DSM_SPACE_LIGHT ? cpp.light(q, co)
                                                                              : cpp.raster(q[0], q[1], q[2], co);
                    for (std::size_t c = 0; c < 3; ++c)
                        ASSERT_TRUE(sameBits(v[3 * i + c], want.v[c]))
                            << "point " << i << ": " << v[3 * i + c] << " != " << want.v[c];
                    ASSERT_TRUE(sameBits(bounds[i], want.errorBound));
                    if (want.v[0] < 1.0) ++shadowed;
                }
            }
    EXPECT_GT(shadowed, 1000);  // the points meet the map's functions, not only empty space
    // The error bounds may be left out.
    const std::vector<double> p = points(DSM_SPACE_WORLD, 4, 1);
    std::vector<double> v(12);
    EXPECT_EQ(dsm_lookup(context, nullptr, 4, p.data(), v.data(), nullptr), DSM_OK);
    dsm_lookup_context_destroy(context);
    dsm_map_close(map);
}

TEST_F(CApi, ShadowSystemLookupsEqualTheContextLookupsBitForBit) {
    dsm_map* map = nullptr;
    ASSERT_EQ(dsm_map_open(path_.c_str(), nullptr, &map), DSM_OK) << dsm_last_error_message();
    dsm_lookup_context* context = nullptr;
    ASSERT_EQ(dsm_lookup_context_create(map, &context), DSM_OK);
    dsm_shadow_system_options so = DSM_SHADOW_SYSTEM_OPTIONS_INIT;
    so.cache_bytes = 4096;  // tiles come and go
    so.max_open_files = 1;
    dsm_shadow_system* system = nullptr;
    ASSERT_EQ(dsm_shadow_system_create(&so, &system), DSM_OK) << dsm_last_error_message();
    dsm_map_handle* handle = nullptr;
    ASSERT_EQ(dsm_shadow_system_open(system, path_.c_str(), &handle), DSM_OK) << dsm_last_error_message();
    dsm_map_handle* again = nullptr;
    ASSERT_EQ(dsm_shadow_system_open(system, path_.c_str(), &again), DSM_OK);
    EXPECT_EQ(handle, again);
    dsm_shadow_thread* thread = nullptr;
    ASSERT_EQ(dsm_shadow_thread_create(system, &thread), DSM_OK);
    dsm_map_info a{}, b{};
    a.size = b.size = sizeof(dsm_map_info);
    ASSERT_EQ(dsm_map_get_info(map, &a), DSM_OK);
    ASSERT_EQ(dsm_shadow_system_get_map_info(system, handle, &b), DSM_OK);
    EXPECT_EQ(std::memcmp(&a, &b, sizeof a), 0);
    const std::size_t n = 5000;  // more than one chunk of the batch
    for (int space : {DSM_SPACE_WORLD, DSM_SPACE_RASTER})
        for (int filter : {DSM_FILTER_BOX, DSM_FILTER_GAUSSIAN}) {
            dsm_lookup_options o = DSM_LOOKUP_OPTIONS_INIT;
            o.space = space;
            o.filter = filter;
            o.filter_width = filter == DSM_FILTER_BOX ? 1.0 : 4.0;
            const std::vector<double> p = points(space, n, 300u + std::uint64_t(space * 10 + filter));
            std::vector<double> want(3 * n), wantBounds(n), got(3 * n), gotBounds(n);
            ASSERT_EQ(dsm_lookup(context, &o, n, p.data(), want.data(), wantBounds.data()), DSM_OK);
            ASSERT_EQ(dsm_shadow_lookup(thread, handle, &o, n, p.data(), got.data(), gotBounds.data()), DSM_OK)
                << dsm_last_error_message();
            for (std::size_t i = 0; i < 3 * n; ++i) ASSERT_TRUE(sameBits(got[i], want[i])) << "value " << i;
            for (std::size_t i = 0; i < n; ++i) ASSERT_TRUE(sameBits(gotBounds[i], wantBounds[i])) << "bound " << i;
        }
    dsm_shadow_system_stats stats{};
    stats.size = sizeof stats;
    ASSERT_EQ(dsm_shadow_system_get_stats(system, &stats), DSM_OK);
    EXPECT_EQ(stats.maps, 1u);
    EXPECT_LE(stats.files_open, 1u);
    EXPECT_GT(stats.tiles_read, 0u);
    EXPECT_GT(stats.evictions, 0u);
    ASSERT_EQ(dsm_shadow_system_reset_stats(system), DSM_OK);
    ASSERT_EQ(dsm_shadow_system_get_stats(system, &stats), DSM_OK);
    EXPECT_EQ(stats.tiles_read, 0u);

    // Failures: a missing map, a bad point (the others are still answered).
    dsm_map_handle* missingMap = nullptr;
    expectFailure(dsm_shadow_system_open(system, (dir_ / "missing.dsm").string().c_str(), &missingMap), DSM_ERROR_IO,
                  "missing.dsm");
    const double bad[6] = {1.0, 1.0, std::nan(""), 0.1, 0.1, 2.0};
    double v[6], bounds[2];
    dsm_lookup_options o = DSM_LOOKUP_OPTIONS_INIT;
    o.space = DSM_SPACE_LIGHT;
    expectFailure(dsm_shadow_lookup(thread, handle, &o, 2, bad, v, bounds), DSM_ERROR_ARGUMENT, "not finite");
    EXPECT_EQ(v[0], 1.0);
    EXPECT_EQ(bounds[0], 1.0);
    expectFailure(dsm_shadow_lookup(thread, nullptr, &o, 2, bad, v, bounds), DSM_ERROR_ARGUMENT, "handle");
    dsm_shadow_thread_destroy(thread);
    dsm_shadow_system_destroy(system);
    dsm_lookup_context_destroy(context);
    dsm_map_close(map);
}

TEST_F(CApi, MemoryAndCallbackInputsAnswerAsThePath) {
    dsm_cache* cache = nullptr;
    ASSERT_EQ(dsm_cache_create(1u << 20, &cache), DSM_OK);
    dsm_open_options o = DSM_OPEN_OPTIONS_INIT;
    o.cache = cache;
    Reads reads;
    reads.bytes = &bytes_;
    const dsm_read_callbacks callbacks = callbacksFor(reads);
    dsm_map* maps[3] = {};
    ASSERT_EQ(dsm_map_open(path_.c_str(), &o, &maps[0]), DSM_OK);
    ASSERT_EQ(dsm_map_open_memory(bytes_.data(), bytes_.size(), "in memory", &o, &maps[1]), DSM_OK);
    ASSERT_EQ(dsm_map_open_callbacks(&callbacks, nullptr, &o, &maps[2]), DSM_OK);
    dsm_cache_destroy(cache);  // the maps keep it alive
    const std::size_t n = 1000;
    const std::vector<double> p = points(DSM_SPACE_WORLD, n, 5);
    std::vector<std::vector<double>> v(3, std::vector<double>(3 * n)), bounds(3, std::vector<double>(n));
    for (int k = 0; k < 3; ++k) {
        dsm_lookup_context* context = nullptr;
        ASSERT_EQ(dsm_lookup_context_create(maps[k], &context), DSM_OK);
        ASSERT_EQ(dsm_lookup(context, nullptr, n, p.data(), v[k].data(), bounds[k].data()), DSM_OK)
            << dsm_last_error_message();
        dsm_lookup_context_destroy(context);
        dsm_map_info info;
        info.size = sizeof info;
        ASSERT_EQ(dsm_map_get_info(maps[k], &info), DSM_OK);
        EXPECT_EQ(info.file_bytes, bytes_.size());
    }
    for (int k = 1; k < 3; ++k) {
        for (std::size_t i = 0; i < 3 * n; ++i) ASSERT_TRUE(sameBits(v[k][i], v[0][i])) << k << " " << i;
        for (std::size_t i = 0; i < n; ++i) ASSERT_TRUE(sameBits(bounds[k][i], bounds[0][i]));
    }
    // Pixels too.
    dsm_pixel* a = nullptr;
    dsm_pixel* b = nullptr;
    ASSERT_EQ(dsm_map_get_pixel(maps[0], 0, 7, 5, &a), DSM_OK);
    ASSERT_EQ(dsm_map_get_pixel(maps[2], 0, 7, 5, &b), DSM_OK);
    dsm_pixel_function fa = DSM_PIXEL_FUNCTION_INIT, fb = DSM_PIXEL_FUNCTION_INIT;
    ASSERT_EQ(dsm_pixel_get_function(a, &fa), DSM_OK);
    ASSERT_EQ(dsm_pixel_get_function(b, &fb), DSM_OK);
    ASSERT_EQ(fa.vertex_count, fb.vertex_count);
    EXPECT_EQ(std::memcmp(fa.z, fb.z, fa.vertex_count * sizeof(float)), 0);
    EXPECT_EQ(std::memcmp(fa.v, fb.v, fa.vertex_count * sizeof(float)), 0);
    dsm_pixel_release(a);
    dsm_pixel_release(b);
    EXPECT_EQ(reads.released, 0);
    for (dsm_map* map : maps) dsm_map_close(map);
    EXPECT_EQ(reads.released, 1);  // when the map no longer needs the callbacks
}

TEST_F(CApi, PixelsAreTheStoredFunctions) {
    dsm_map* map = nullptr;
    ASSERT_EQ(dsm_map_open(path_.c_str(), nullptr, &map), DSM_OK);
    const auto cpp = dsm::DeepShadowMap::open(path_);
    for (uint32_t level : {0u, 1u})
        for (uint32_t y = 0; y < cpp->info().levels[level].height; y += 3)
            for (uint32_t x = 0; x < cpp->info().levels[level].width; x += 2) {
                dsm_pixel* pixel = nullptr;
                ASSERT_EQ(dsm_map_get_pixel(map, level, x, y, &pixel), DSM_OK);
                dsm_pixel_function f = DSM_PIXEL_FUNCTION_INIT;
                ASSERT_EQ(dsm_pixel_get_function(pixel, &f), DSM_OK);
                const dsm::PixelFunction want = cpp->pixel(level, x, y);
                ASSERT_EQ(f.vertex_count, want->size());
                ASSERT_EQ(f.channels, want->channels());
                ASSERT_EQ(f.layer_count, want->layerCount());
                for (uint32_t i = 0; i < f.vertex_count; ++i) {
                    EXPECT_EQ(f.z[i], want->z(i));
                    EXPECT_EQ(f.v[i], want->value(i, 0));
                    EXPECT_EQ(f.counts ? f.counts[i] : 0u, want->count(i));
                }
                for (uint32_t l = 1; l < f.layer_count; ++l) EXPECT_EQ(f.layer_starts[l - 1], want->layerBegin(l));
                for (double z : {0.0, 1.3, 2.7, 9.0}) {
                    double v[3];
                    ASSERT_EQ(dsm_pixel_evaluate(pixel, z, v), DSM_OK);
                    EXPECT_TRUE(sameBits(v[0], want->evaluate(z)));
                    EXPECT_EQ(v[1], v[0]);
                    EXPECT_EQ(v[2], v[0]);
                }
                dsm_pixel_release(pixel);
            }
    dsm_map_close(map);
}

TEST_F(CApi, SoftShadowsEqualTheCppOnes) {
    dsm_map* map = nullptr;
    ASSERT_EQ(dsm_map_open(path_.c_str(), nullptr, &map), DSM_OK);
    const auto cppMap = dsm::DeepShadowMap::open(path_);
    for (int shape : {DSM_AREA_LIGHT_DISK, DSM_AREA_LIGHT_RECTANGLE}) {
        dsm_area_light light = DSM_AREA_LIGHT_INIT;
        light.shape = shape;
        light.half_width = 0.05;
        light.half_height = 0.03;
        light.plane_depth = 0.2;
        dsm_soft_light* soft = nullptr;
        ASSERT_EQ(dsm_soft_light_create(map, &light, &soft), DSM_OK) << dsm_last_error_message();
        dsm_soft_context* context = nullptr;
        ASSERT_EQ(dsm_soft_context_create(soft, &context), DSM_OK);
        const dsm::AreaLight area = shape == DSM_AREA_LIGHT_DISK
                                        ? dsm::AreaLight::disk(cppMap->info().camera, 0.05, 0.2)
                                        : dsm::AreaLight::rectangle(cppMap->info().camera, 0.05, 0.03, 0.2);
        dsm::SoftShadowContext cpp(std::make_shared<dsm::SoftShadowTracer>(cppMap, area));
        for (int method : {DSM_SOFT_MTSM, DSM_SOFT_PCF}) {
            dsm_soft_shadow_options o = DSM_SOFT_SHADOW_OPTIONS_INIT;
            o.method = method;
            o.samples = 16;
            o.z_threshold = 0.01;
            const std::size_t n = 200;
            const std::vector<double> p = points(DSM_SPACE_WORLD, n, 9u + std::uint64_t(method));
            std::vector<double> v(3 * n);
            std::vector<int32_t> rays(n);
            ASSERT_EQ(dsm_soft_shadow(context, &o, n, p.data(), v.data(), rays.data()), DSM_OK)
                << dsm_last_error_message();
            dsm::SoftShadowOptions co;
            co.samples = 16;
            co.zThreshold = 0.01;
            int traced = 0;
            for (std::size_t i = 0; i < n; ++i) {
                const dsm::Vec3 q{p[3 * i], p[3 * i + 1], p[3 * i + 2]};
                const dsm::SoftShadowResult want =
                    method == DSM_SOFT_PCF ? cpp.pcfVisibility(q, co) : cpp.visibility(q, co);
                for (std::size_t c = 0; c < 3; ++c) ASSERT_TRUE(sameBits(v[3 * i + c], want.v[c])) << i;
                EXPECT_EQ(rays[i], want.rays);
                traced += rays[i];
            }
            if (method == DSM_SOFT_MTSM) {
                EXPECT_GT(traced, 0);
            }
        }
        dsm_soft_context_destroy(context);
        dsm_soft_light_destroy(soft);
    }
    dsm_map_close(map);
}

TEST_F(CApi, AMapWrittenThroughTheCApiReadsBack) {
    const std::string out = (dir_ / "written.dsm").string();
    dsm_write_options o = DSM_WRITE_OPTIONS_INIT;
    o.width = 40;
    o.height = 24;
    o.tile_size = 8;
    o.counts = 1;
    o.max_layers = 2;
    o.tolerance = 0.01;
    o.metadata = "{\"written\":\"through C\"}";
    dsm_writer* writer = nullptr;
    ASSERT_EQ(dsm_writer_open(out.c_str(), &o, &writer), DSM_OK) << dsm_last_error_message();
    // Every pixel but one column, in reverse order; the column stays empty.
    for (uint32_t y = 24; y-- > 0;)
        for (uint32_t x = 40; x-- > 0;) {
            if (x == 13) continue;
            const dsm::VisibilityFunction& f = image_.at(x, y);
            std::vector<uint32_t> starts;
            for (std::size_t l = 1; l < f.layerCount(); ++l) starts.push_back(static_cast<uint32_t>(f.layerBegin(l)));
            dsm_pixel_function p = DSM_PIXEL_FUNCTION_INIT;
            p.channels = f.channels();
            p.vertex_count = static_cast<uint32_t>(f.size());
            p.z = f.depths().data();
            p.v = f.allValues().data();
            p.counts = f.counts().data();
            p.layer_count = static_cast<uint32_t>(f.layerCount());
            p.layer_starts = starts.empty() ? nullptr : starts.data();
            ASSERT_EQ(dsm_writer_set_pixel_function(writer, x, y, &p), DSM_OK) << dsm_last_error_message();
        }
    EXPECT_FALSE(std::filesystem::exists(out));  // written beside it until finished
    ASSERT_EQ(dsm_writer_finish(writer), DSM_OK) << dsm_last_error_message();
    dsm_writer_destroy(writer);

    const auto map = dsm::DeepShadowMap::open(out);
    EXPECT_EQ(map->info().metadata, "{\"written\":\"through C\"}");
    for (uint32_t y = 0; y < 24; ++y)
        for (uint32_t x = 0; x < 40; ++x) {
            if (x == 13) {
                EXPECT_TRUE(map->pixel(0, x, y)->empty());
                continue;
            }
            EXPECT_TRUE(dsm::test::sameFunction(map->pixel(0, x, y).view(), image_.at(x, y), true)) << x << "," << y;
        }
    EXPECT_NO_THROW(dsm::validate(out));
}

TEST_F(CApi, PixelsFromSampleRaysAreBuiltAsTheCppBuildDoes) {
    for (const int32_t centred : {0, 1}) {
        SCOPED_TRACE(centred ? "centred" : "greedy");
        const std::string out = (dir_ / "samples.dsm").string();
        dsm_write_options o = DSM_WRITE_OPTIONS_INIT;
        o.centred_compression = centred;
        o.width = 6;
        o.height = 5;
        o.tile_size = 4;
        o.channels = 3;
        o.tolerance = 0.02;
        dsm_writer* writer = nullptr;
        ASSERT_EQ(dsm_writer_open(out.c_str(), &o, &writer), DSM_OK) << dsm_last_error_message();
        std::mt19937_64 rng(4);
        std::uniform_real_distribution<float> depth(1.0f, 5.0f), opacity(0.0f, 1.0f);
        std::vector<dsm::VisibilityFunction> want;
        for (uint32_t y = 0; y < 5; ++y)
            for (uint32_t x = 0; x < 6; ++x) {
                std::vector<std::vector<dsm_surface_hit>> hits(8);
                std::vector<dsm_sample_ray> rays(8);
                std::vector<std::vector<dsm::SurfaceHit>> cppHits(8);
                std::vector<dsm::SampleRay> cppRays(8);
                std::vector<double> weights(8);
                for (std::size_t k = 0; k < 8; ++k) {
                    for (std::size_t h = 0; h < (k + x) % 4; ++h) {
                        dsm_surface_hit hit{depth(rng), {opacity(rng), opacity(rng), opacity(rng)}};
                        hits[k].push_back(hit);
                        cppHits[k].push_back(dsm::SurfaceHit{hit.z, {hit.opacity[0], hit.opacity[1], hit.opacity[2]}});
                    }
                    weights[k] = 0.5 + 0.1 * double(k);
                    rays[k] = dsm_sample_ray{hits[k].data(), hits[k].size(), weights[k]};
                    cppRays[k].hits = cppHits[k];
                }
                ASSERT_EQ(dsm_writer_set_pixel_samples(writer, x, y, rays.data(), rays.size()), DSM_OK)
                    << dsm_last_error_message();
                dsm::CompressorOptions c;
                c.tolerance = 0.02;
                c.channels = 3;
                c.centred = centred != 0;
                want.push_back(dsm::buildVisibility(cppRays, weights, c));
            }
        ASSERT_EQ(dsm_writer_finish(writer), DSM_OK) << dsm_last_error_message();
        dsm_writer_destroy(writer);
        const auto map = dsm::DeepShadowMap::open(out);
        for (uint32_t y = 0; y < 5; ++y)
            for (uint32_t x = 0; x < 6; ++x)
                EXPECT_TRUE(dsm::test::sameFunction(map->pixel(0, x, y).view(), want[y * 6 + x], false));
    }
}

TEST_F(CApi, AnUnfinishedWriterLeavesNoFile) {
    const std::string out = (dir_ / "unfinished.dsm").string();
    dsm_write_options o = DSM_WRITE_OPTIONS_INIT;
    o.width = 4;
    o.height = 4;
    dsm_writer* writer = nullptr;
    ASSERT_EQ(dsm_writer_open(out.c_str(), &o, &writer), DSM_OK);
    dsm_pixel_function p = DSM_PIXEL_FUNCTION_INIT;
    ASSERT_EQ(dsm_writer_set_pixel_function(writer, 1, 1, &p), DSM_OK);
    dsm_writer_destroy(writer);
    EXPECT_EQ(dsm::test::listDirectory(dir_.path()), std::vector<std::string>{"map.dsm"});
}

TEST_F(CApi, EveryFailureReturnsACodeAndAMessage) {
    dsm_map* map = nullptr;
    ASSERT_EQ(dsm_map_open(path_.c_str(), nullptr, &map), DSM_OK);
    dsm_map* none = nullptr;
    const std::string missingPath = (dir_ / "missing.dsm").string();
    const std::string notAMap = (dir_ / "text.dsm").string();
    dsm::test::writeFile(notAMap, Bytes{'h', 'e', 'l', 'l', 'o'});
    Bytes newer = bytes_;
    newer[8] = 2;

    // Caches and opening.
    expectFailure(dsm_cache_create(1, nullptr), DSM_ERROR_ARGUMENT, "dsm_cache_create: cache is NULL");
    expectFailure(dsm_cache_bytes_in_use(nullptr, nullptr), DSM_ERROR_ARGUMENT, "cache is NULL");
    expectFailure(dsm_map_open(nullptr, nullptr, &none), DSM_ERROR_ARGUMENT, "dsm_map_open: path is NULL");
    expectFailure(dsm_map_open(path_.c_str(), nullptr, nullptr), DSM_ERROR_ARGUMENT, "map is NULL");
    expectFailure(dsm_map_open(missingPath.c_str(), nullptr, &none), DSM_ERROR_IO, "cannot open");
    expectFailure(dsm_map_open(notAMap.c_str(), nullptr, &none), DSM_ERROR_FORMAT, "bad magic");
    expectFailure(dsm_map_open_memory(newer.data(), newer.size(), "newer", nullptr, &none), DSM_ERROR_UNSUPPORTED,
                  "'newer': format version 2");
    expectFailure(dsm_map_open_memory(bytes_.data(), bytes_.size() - 1, "short", nullptr, &none), DSM_ERROR_CORRUPT,
                  "'short':");
    expectFailure(dsm_map_open_memory(nullptr, 5, nullptr, nullptr, &none), DSM_ERROR_ARGUMENT, "data is NULL");
    dsm_open_options limits = DSM_OPEN_OPTIONS_INIT;
    limits.max_width = 8;
    expectFailure(dsm_map_open(path_.c_str(), &limits, &none), DSM_ERROR_LIMIT, "exceeds the reader's limit");
    EXPECT_EQ(none, nullptr);  // outputs stay untouched on failure

    // Callbacks: a failing read is io; release runs even when the open fails.
    Reads failing;
    failing.bytes = &bytes_;
    failing.failTo = 16;
    dsm_read_callbacks callbacks = callbacksFor(failing);
    expectFailure(dsm_map_open_callbacks(&callbacks, "cb", nullptr, &none), DSM_ERROR_IO,
                  "'cb': read failed: the read callback failed");
    EXPECT_EQ(failing.released, 1);
    callbacks.read = nullptr;
    expectFailure(dsm_map_open_callbacks(&callbacks, "cb", nullptr, &none), DSM_ERROR_ARGUMENT,
                  "callbacks->read is NULL");
    EXPECT_EQ(failing.released, 2);
    expectFailure(dsm_map_open_callbacks(nullptr, "cb", nullptr, &none), DSM_ERROR_ARGUMENT, "callbacks is NULL");

    // Versioned structs: no size; or fields this version does not know.
    dsm_open_options unsized = DSM_OPEN_OPTIONS_INIT;
    unsized.size = 0;
    expectFailure(dsm_map_open(path_.c_str(), &unsized, &none), DSM_ERROR_ARGUMENT, "size field is not set");
    struct Newer {
        dsm_lookup_options known;
        double unknown;
    } newerOptions{DSM_LOOKUP_OPTIONS_INIT, 0.0};
    newerOptions.known.size = sizeof(Newer);
    dsm_lookup_context* context = nullptr;
    ASSERT_EQ(dsm_lookup_context_create(map, &context), DSM_OK);
    const double point[3] = {0.0, 0.0, 2.0};
    double v[3], bound = 0.0;
    EXPECT_EQ(dsm_lookup(context, &newerOptions.known, 1, point, v, &bound), DSM_OK);  // zero: accepted
    newerOptions.unknown = 1.0;
    expectFailure(dsm_lookup(context, &newerOptions.known, 1, point, v, &bound), DSM_ERROR_UNSUPPORTED,
                  "does not know");

    // Map information and pixels.
    dsm_map_info info;
    info.size = 0;
    expectFailure(dsm_map_get_info(map, &info), DSM_ERROR_ARGUMENT, "size field is not set");
    expectFailure(dsm_map_get_info(nullptr, &info), DSM_ERROR_ARGUMENT, "map is NULL");
    dsm_level_info level;
    expectFailure(dsm_map_get_level(map, 9, &level), DSM_ERROR_ARGUMENT, "level 9 does not exist");
    expectFailure(dsm_map_get_metadata(map, nullptr, nullptr), DSM_ERROR_ARGUMENT, "json is NULL");
    dsm_pixel* pixel = nullptr;
    expectFailure(dsm_map_get_pixel(map, 0, 40, 0, &pixel), DSM_ERROR_ARGUMENT, "pixel 40,0 is outside");
    expectFailure(dsm_map_get_pixel(map, 7, 0, 0, &pixel), DSM_ERROR_ARGUMENT, "level 7 does not exist");
    expectFailure(dsm_pixel_get_function(nullptr, nullptr), DSM_ERROR_ARGUMENT, "pixel is NULL");
    expectFailure(dsm_pixel_evaluate(nullptr, 1.0, v), DSM_ERROR_ARGUMENT, "pixel is NULL");

    // Lookups.
    expectFailure(dsm_lookup_context_create(nullptr, &context), DSM_ERROR_ARGUMENT, "map is NULL");
    expectFailure(dsm_lookup(nullptr, nullptr, 1, point, v, nullptr), DSM_ERROR_ARGUMENT, "context is NULL");
    expectFailure(dsm_lookup(context, nullptr, 1, nullptr, v, nullptr), DSM_ERROR_ARGUMENT, "points is NULL");
    expectFailure(dsm_lookup(context, nullptr, 1, point, nullptr, nullptr), DSM_ERROR_ARGUMENT, "visibility is NULL");
    dsm_lookup_options bad = DSM_LOOKUP_OPTIONS_INIT;
    bad.space = 7;
    expectFailure(dsm_lookup(context, &bad, 1, point, v, nullptr), DSM_ERROR_ARGUMENT, "space");
    bad = dsm_lookup_options DSM_LOOKUP_OPTIONS_INIT;
    bad.filter = 3;
    expectFailure(dsm_lookup(context, &bad, 1, point, v, nullptr), DSM_ERROR_ARGUMENT, "filter");
    bad = dsm_lookup_options DSM_LOOKUP_OPTIONS_INIT;
    bad.level = -2;
    expectFailure(dsm_lookup(context, &bad, 1, point, v, nullptr), DSM_ERROR_ARGUMENT, "level");
    bad = dsm_lookup_options DSM_LOOKUP_OPTIONS_INIT;
    bad.filter_width = -1.0;
    expectFailure(dsm_lookup(context, &bad, 1, point, v, &bound), DSM_ERROR_ARGUMENT, "filter width");
    // A bad point among good ones: all are answered, the bad one with the failure value.
    const double mixed[9] = {0.0, 0.0, 2.0, std::numeric_limits<double>::quiet_NaN(), 0.0, 2.0, 0.1, 0.1, 3.0};
    double mv[9], mb[3];
    expectFailure(dsm_lookup(context, nullptr, 3, mixed, mv, mb), DSM_ERROR_ARGUMENT, "is not finite");
    EXPECT_EQ(mv[3], 1.0);
    EXPECT_EQ(mb[1], 1.0);
    double one[3], oneBound = 0.0;
    ASSERT_EQ(dsm_lookup(context, nullptr, 1, mixed + 6, one, &oneBound), DSM_OK);
    EXPECT_EQ(mv[6], one[0]);
    EXPECT_EQ(mb[2], oneBound);

    // Soft shadows.
    dsm_area_light light = DSM_AREA_LIGHT_INIT;
    light.half_width = 0.05;
    dsm_soft_light* soft = nullptr;
    expectFailure(dsm_soft_light_create(map, &light, &soft), DSM_ERROR_ARGUMENT, "records no area-light radius");
    light.shape = 5;
    expectFailure(dsm_soft_light_create(map, &light, &soft), DSM_ERROR_ARGUMENT, "shape");
    light.shape = DSM_AREA_LIGHT_DISK;
    light.half_width = -1.0;
    light.plane_depth = 0.2;
    expectFailure(dsm_soft_light_create(map, &light, &soft), DSM_ERROR_ARGUMENT, "area light");
    expectFailure(dsm_soft_light_create(nullptr, &light, &soft), DSM_ERROR_ARGUMENT, "map is NULL");
    expectFailure(dsm_soft_context_create(nullptr, nullptr), DSM_ERROR_ARGUMENT, "soft is NULL");
    light.half_width = 0.05;
    ASSERT_EQ(dsm_soft_light_create(map, &light, &soft), DSM_OK) << dsm_last_error_message();
    dsm_soft_context* softContext = nullptr;
    ASSERT_EQ(dsm_soft_context_create(soft, &softContext), DSM_OK);
    dsm_soft_shadow_options so = DSM_SOFT_SHADOW_OPTIONS_INIT;
    so.samples = 0;
    int32_t rays[3];
    expectFailure(dsm_soft_shadow(softContext, &so, 3, mixed, mv, rays), DSM_ERROR_ARGUMENT, "sample count 0");
    so = dsm_soft_shadow_options DSM_SOFT_SHADOW_OPTIONS_INIT;
    so.method = 4;
    expectFailure(dsm_soft_shadow(softContext, &so, 3, mixed, mv, rays), DSM_ERROR_ARGUMENT, "method");
    so = dsm_soft_shadow_options DSM_SOFT_SHADOW_OPTIONS_INIT;
    so.attenuation = 4;
    expectFailure(dsm_soft_shadow(softContext, &so, 3, mixed, mv, rays), DSM_ERROR_ARGUMENT, "attenuation");
    expectFailure(dsm_soft_shadow(softContext, nullptr, 3, mixed, mv, rays), DSM_ERROR_ARGUMENT, "is not finite");
    EXPECT_EQ(mv[3], 1.0);
    EXPECT_EQ(rays[1], 0);
    expectFailure(dsm_soft_shadow(nullptr, nullptr, 3, mixed, mv, rays), DSM_ERROR_ARGUMENT, "context is NULL");
    dsm_soft_context_destroy(softContext);
    dsm_soft_light_destroy(soft);

    // Writing.
    const std::string out = (dir_ / "out.dsm").string();
    dsm_write_options wo = DSM_WRITE_OPTIONS_INIT;
    dsm_writer* writer = nullptr;
    expectFailure(dsm_writer_open(out.c_str(), &wo, &writer), DSM_ERROR_ARGUMENT, "image size 0x0");
    expectFailure(dsm_writer_open(out.c_str(), nullptr, &writer), DSM_ERROR_ARGUMENT, "options is NULL");
    wo.width = wo.height = 4;
    wo.projection = 3;
    expectFailure(dsm_writer_open(out.c_str(), &wo, &writer), DSM_ERROR_ARGUMENT, "projection");
    wo.projection = DSM_PROJECTION_PERSPECTIVE;
    const std::string noDirectory = (dir_ / "no" / "such" / "dir.dsm").string();
    expectFailure(dsm_writer_open(noDirectory.c_str(), &wo, &writer), DSM_ERROR_IO, "cannot write in the directory");
    ASSERT_EQ(dsm_writer_open(out.c_str(), &wo, &writer), DSM_OK);
    dsm_pixel_function f = DSM_PIXEL_FUNCTION_INIT;
    expectFailure(dsm_writer_set_pixel_function(writer, 4, 0, &f), DSM_ERROR_ARGUMENT,
                  "pixel 4,0: outside the 4x4 map");
    const float z[2] = {2.0f, 1.0f}, values[2] = {1.0f, 0.5f};
    f.vertex_count = 2;
    f.z = z;
    f.v = values;
    expectFailure(dsm_writer_set_pixel_function(writer, 0, 0, &f), DSM_ERROR_ARGUMENT, "less than the previous depth");
    f.vertex_count = 1;
    ASSERT_EQ(dsm_writer_set_pixel_function(writer, 0, 0, &f), DSM_OK);
    expectFailure(dsm_writer_set_pixel_function(writer, 0, 0, &f), DSM_ERROR_ARGUMENT, "pixel 0,0: set twice");
    f.channels = 2;
    expectFailure(dsm_writer_set_pixel_function(writer, 1, 0, &f), DSM_ERROR_ARGUMENT, "channels");
    const dsm_surface_hit badHit{1.0f, {2.0f, 0.0f, 0.0f}};
    const dsm_sample_ray badRay{&badHit, 1, 1.0};
    expectFailure(dsm_writer_set_pixel_samples(writer, 1, 0, &badRay, 1), DSM_ERROR_ARGUMENT, "opacity 2");
    expectFailure(dsm_writer_set_pixel_samples(writer, 1, 0, nullptr, 1), DSM_ERROR_ARGUMENT, "rays is NULL");
    ASSERT_EQ(dsm_writer_finish(writer), DSM_OK) << dsm_last_error_message();
    expectFailure(dsm_writer_finish(writer), DSM_ERROR_ARGUMENT, "already finished");
    expectFailure(dsm_writer_set_pixel_function(writer, 1, 1, &f), DSM_ERROR_ARGUMENT, "the writer is finished");
    dsm_writer_destroy(writer);
    expectFailure(dsm_writer_finish(nullptr), DSM_ERROR_ARGUMENT, "writer is NULL");

    // NULL handles are ignored by the release functions.
    dsm_cache_destroy(nullptr);
    dsm_map_close(nullptr);
    dsm_pixel_release(nullptr);
    dsm_lookup_context_destroy(nullptr);
    dsm_soft_light_destroy(nullptr);
    dsm_soft_context_destroy(nullptr);
    dsm_writer_destroy(nullptr);
    dsm_lookup_context_destroy(context);
    dsm_map_close(map);
}

TEST_F(CApi, ATileThatCannotBeReadFailsItsPointsOnly) {
    dsm_map* map = openDamaged();
    ASSERT_NE(map, nullptr) << dsm_last_error_message();
    dsm_lookup_context* context = nullptr;
    ASSERT_EQ(dsm_lookup_context_create(map, &context), DSM_OK);
    dsm_lookup_options o = DSM_LOOKUP_OPTIONS_INIT;
    o.space = DSM_SPACE_RASTER;
    o.level = 0;
    const double p[6] = {2.0, 2.0, 3.0, 30.0, 20.0, 3.0};
    double v[6], bounds[2];
    expectFailure(dsm_lookup(context, &o, 2, p, v, bounds), DSM_ERROR_CORRUPT, "'damaged' level 0 tile 0,0");
    EXPECT_EQ(v[0], 1.0);
    EXPECT_EQ(bounds[0], 1.0);
    EXPECT_LE(bounds[1], 0.1);  // the other point was answered
    dsm_pixel* pixel = nullptr;
    expectFailure(dsm_map_get_pixel(map, 0, 1, 1, &pixel), DSM_ERROR_CORRUPT, "CRC-32 mismatch");
    dsm_lookup_context_destroy(context);
    dsm_map_close(map);
}

TEST_F(CApi, TheLastErrorNamesTheFileItConcerns) {
    dsm_map* none = nullptr;
    const std::string missingPath = (dir_ / "missing.dsm").string();
    EXPECT_EQ(dsm_map_open(missingPath.c_str(), nullptr, &none), DSM_ERROR_IO);
    EXPECT_EQ(std::string(dsm_last_error_file()), missingPath);
    EXPECT_EQ(std::string(dsm_last_error_message()).rfind("'" + missingPath + "': cannot open", 0), 0u);
    // A failure about no file forgets the file.
    EXPECT_EQ(dsm_cache_create(1, nullptr), DSM_ERROR_ARGUMENT);
    EXPECT_STREQ(dsm_last_error_file(), "");

    // A tile that cannot be read, through lookups and pixels: the name the buffer was given.
    dsm_map* map = openDamaged();
    ASSERT_NE(map, nullptr) << dsm_last_error_message();
    dsm_lookup_context* context = nullptr;
    ASSERT_EQ(dsm_lookup_context_create(map, &context), DSM_OK);
    dsm_lookup_options o = DSM_LOOKUP_OPTIONS_INIT;
    o.space = DSM_SPACE_RASTER;
    o.level = 0;
    const double p[3] = {2.0, 2.0, 3.0};
    double v[3];
    EXPECT_EQ(dsm_lookup(context, &o, 1, p, v, nullptr), DSM_ERROR_CORRUPT);
    EXPECT_STREQ(dsm_last_error_file(), "damaged");
    dsm_clear_last_error();
    EXPECT_STREQ(dsm_last_error_file(), "");
    dsm_pixel* pixel = nullptr;
    EXPECT_EQ(dsm_map_get_pixel(map, 0, 1, 1, &pixel), DSM_ERROR_CORRUPT);
    EXPECT_STREQ(dsm_last_error_file(), "damaged");
    dsm_level_info level;
    EXPECT_EQ(dsm_map_get_level(map, 99, &level), DSM_ERROR_ARGUMENT);
    EXPECT_STREQ(dsm_last_error_file(), "damaged");
    dsm_lookup_context_destroy(context);
    dsm_map_close(map);
}

TEST_F(CApi, TheLastErrorIsPerThreadAndTheCallbackSeesEveryFailure) {
    struct Seen {
        int calls = 0;
        dsm_result result = DSM_OK;
        std::string message;
    } seen;
    dsm_set_error_callback(
        [](void* user, dsm_result result, const char* message) {
            Seen& s = *static_cast<Seen*>(user);
            ++s.calls;
            s.result = result;
            s.message = message;
        },
        &seen);
    dsm_map* none = nullptr;
    expectFailure(dsm_map_open((dir_ / "missing.dsm").string().c_str(), nullptr, &none), DSM_ERROR_IO, "cannot open");
    EXPECT_EQ(seen.calls, 1);
    EXPECT_EQ(seen.result, DSM_ERROR_IO);
    EXPECT_EQ(seen.message, dsm_last_error_message());
    std::string otherThread = "unset";
    dsm_result otherResult = DSM_ERROR_INTERNAL;
    std::thread([&] {
        otherThread = dsm_last_error_message();
        otherResult = dsm_last_error();
    }).join();
    EXPECT_EQ(otherThread, "");
    EXPECT_EQ(otherResult, DSM_OK);
    dsm_set_error_callback(nullptr, nullptr);
    expectFailure(dsm_map_open(nullptr, nullptr, &none), DSM_ERROR_ARGUMENT, "path is NULL");
    EXPECT_EQ(seen.calls, 1);
    dsm_clear_last_error();
    EXPECT_EQ(dsm_last_error(), DSM_OK);
    EXPECT_STREQ(dsm_last_error_message(), "");
}

TEST_F(CApi, TheCacheKeepsToItsBudget) {
    // The same lookups through a zero budget (at most the tile being added is
    // held) and a large one (every tile touched stays).
    uint64_t held[2] = {};
    const uint64_t budgets[2] = {0, 64u << 20};
    for (int k = 0; k < 2; ++k) {
        dsm_cache* cache = nullptr;
        ASSERT_EQ(dsm_cache_create(budgets[k], &cache), DSM_OK);
        dsm_open_options o = DSM_OPEN_OPTIONS_INIT;
        o.cache = cache;
        dsm_map* map = nullptr;
        ASSERT_EQ(dsm_map_open(path_.c_str(), &o, &map), DSM_OK);
        dsm_lookup_context* context = nullptr;
        ASSERT_EQ(dsm_lookup_context_create(map, &context), DSM_OK);
        dsm_lookup_options lo = DSM_LOOKUP_OPTIONS_INIT;
        lo.space = DSM_SPACE_RASTER;
        lo.level = 0;
        std::vector<double> p;
        for (double y = 0.5; y < 24.0; y += 1.0)
            for (double x = 0.5; x < 40.0; x += 1.0) p.insert(p.end(), {x, y, 2.0});
        std::vector<double> v(p.size());
        ASSERT_EQ(dsm_lookup(context, &lo, p.size() / 3, p.data(), v.data(), nullptr), DSM_OK);
        ASSERT_EQ(dsm_cache_bytes_in_use(cache, &held[k]), DSM_OK);
        dsm_lookup_context_destroy(context);
        dsm_map_close(map);
        dsm_cache_destroy(cache);
    }
    EXPECT_GT(held[0], 0u);
    EXPECT_GT(held[1], 4 * held[0]);  // 15 tiles of level 0 against one
}

}  // namespace
