// Deep OpenEXR as pipelines write it (dsm/exr_deep.h, spec/exr-interop.md):
// multi-part files and views, layered channel names, tiled inputs decoded
// once, header attributes and windows kept, samples merged or left out
// reported, recorded error bounds that hold, and vertex samples read back
// losslessly. The inputs are made here with the OpenEXR API.
#include <dsm/dsm.h>
#include <dsm/exr_deep.h>
#include <gtest/gtest.h>

#include <ImathBox.h>
#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineOutputPart.h>
#include <ImfDeepTiledOutputPart.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfMultiPartInputFile.h>
#include <ImfMultiPartOutputFile.h>
#include <ImfOutputPart.h>
#include <ImfPartType.h>
#include <ImfStringAttribute.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "temp_dir.h"

namespace dsm {
namespace {

using SampleSource = std::function<std::vector<DeepSample>(int x, int y)>;

/// One part of a test file: deep (scanline, or tiled with `tile` > 0) with
/// the given channel names for depth, back depth (may be empty) and alpha, or
/// flat (one half channel R).
struct TestPart {
    std::string name, view;
    bool deep = true;
    int tile = 0;
    Imath::Box2i display{Imath::V2i(0, 0), Imath::V2i(15, 11)};
    Imath::Box2i data{Imath::V2i(0, 0), Imath::V2i(15, 11)};
    std::string z = "Z", zBack = "ZBack", alpha = "A";
    std::vector<std::string> moreChannels;  // filled with 0.5
    std::vector<std::pair<std::string, std::string>> strings;
    SampleSource samples;
};

/// Samples that differ from pixel to pixel: 0 to 2 points and a volume.
std::vector<DeepSample> variedSamples(int x, int y) {
    std::vector<DeepSample> out;
    const int k = (x * 3 + y * 5) % 4;
    for (int i = 0; i < k; ++i) {
        const float z = 1.0f + float(x % 5) * 0.5f + float(i) * 1.25f;
        const float a = 0.1f + 0.2f * float((x + y + i) % 4);
        out.push_back({z, i == 2 ? z + 2.0f : z, a, {a, a, a}});
    }
    return out;
}

Imf::Header headerOf(const TestPart& p) {
    Imf::Header h(p.display, p.data);
    if (!p.name.empty()) h.setName(p.name);
    if (!p.view.empty()) h.setView(p.view);
    for (const auto& [k, v] : p.strings) h.insert(k, Imf::StringAttribute(v));
    if (!p.deep) {
        h.channels().insert("R", Imf::Channel(Imf::HALF));
        h.setType(Imf::SCANLINEIMAGE);
        return h;
    }
    h.compression() = Imf::ZIPS_COMPRESSION;
    for (const std::string* c : {&p.z, &p.zBack, &p.alpha})
        if (!c->empty()) h.channels().insert(*c, Imf::Channel(Imf::FLOAT));
    for (const std::string& c : p.moreChannels) h.channels().insert(c, Imf::Channel(Imf::FLOAT));
    if (p.tile > 0) {
        h.setTileDescription(Imf::TileDescription(unsigned(p.tile), unsigned(p.tile), Imf::ONE_LEVEL));
        h.setType(Imf::DEEPTILE);
    } else {
        h.setType(Imf::DEEPSCANLINE);
    }
    return h;
}

/// Writes the parts as one file (multi-part when there are several).
void writeParts(const std::filesystem::path& path, const std::vector<TestPart>& parts) {
    std::vector<Imf::Header> headers;
    for (const TestPart& p : parts) headers.push_back(headerOf(p));
    Imf::MultiPartOutputFile file(path.string().c_str(), headers.data(), int(headers.size()));
    for (std::size_t i = 0; i < parts.size(); ++i) {
        const TestPart& p = parts[i];
        const int x0 = p.data.min.x, y0 = p.data.min.y;
        const int w = p.data.max.x - x0 + 1, h = p.data.max.y - y0 + 1;
        const std::size_t n = std::size_t(w) * std::size_t(h);
        if (!p.deep) {
            std::vector<half> r(n, half(0.5f));
            Imf::FrameBuffer fb;
            fb.insert("R", Imf::Slice(Imf::HALF, reinterpret_cast<char*>(r.data() - (x0 + std::ptrdiff_t(y0) * w)),
                                      sizeof(half), sizeof(half) * std::size_t(w)));
            Imf::OutputPart out(file, int(i));
            out.setFrameBuffer(fb);
            out.writePixels(h);
            continue;
        }
        // Every channel of a sample: z, zBack, alpha, then the others.
        const std::size_t fields = 3 + p.moreChannels.size();
        std::vector<std::vector<float>> values(n);
        std::vector<unsigned> counts(n);
        std::vector<std::vector<char*>> pointers(fields, std::vector<char*>(n, nullptr));
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const std::size_t k = std::size_t(y) * std::size_t(w) + std::size_t(x);
                for (const DeepSample& s : p.samples(x0 + x, y0 + y)) {
                    values[k].insert(values[k].end(), {s.z, s.zBack, s.alpha});
                    values[k].insert(values[k].end(), p.moreChannels.size(), 0.5f);
                }
                counts[k] = unsigned(values[k].size() / fields);
                for (std::size_t f = 0; f < fields; ++f)
                    pointers[f][k] = values[k].empty() ? nullptr : reinterpret_cast<char*>(values[k].data() + f);
            }
        const std::ptrdiff_t origin = x0 + std::ptrdiff_t(y0) * w;
        Imf::DeepFrameBuffer fb;
        fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data() - origin),
                                             sizeof(unsigned), sizeof(unsigned) * std::size_t(w)));
        std::vector<std::string> names = {p.z, p.zBack, p.alpha};
        names.insert(names.end(), p.moreChannels.begin(), p.moreChannels.end());
        for (std::size_t f = 0; f < fields; ++f)
            if (!names[f].empty())
                fb.insert(names[f], Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(pointers[f].data() - origin),
                                                   sizeof(char*), sizeof(char*) * std::size_t(w),
                                                   sizeof(float) * fields));
        if (p.tile > 0) {
            Imf::DeepTiledOutputPart out(file, int(i));
            out.setFrameBuffer(fb);
            out.writeTiles(0, out.numXTiles(0) - 1, 0, out.numYTiles(0) - 1);
        } else {
            Imf::DeepScanLineOutputPart out(file, int(i));
            out.setFrameBuffer(fb);
            out.writePixels(h);
        }
    }
}

TestPart deepPart(const std::string& name, const std::string& view, SampleSource samples = variedSamples) {
    TestPart p;
    p.name = name;
    p.view = view;
    p.samples = std::move(samples);
    return p;
}

ExrImportOptions withFov(ExrImportOptions o = {}) {
    o.fieldOfView = 60.0;
    o.mipLevels = 1;
    return o;
}

/// Samples of one pixel as a function: what the import must reproduce.
double exrTransmittance(const std::vector<DeepSample>& samples, double z) {
    double t = 1.0;
    for (const DeepSample& s : samples) {
        if (!(s.zBack > s.z)) {
            if (z >= s.z) t *= 1.0 - s.alpha;
        } else if (z > s.z) {
            t *= std::pow(1.0 - s.alpha, std::min(1.0, (z - s.z) / (double(s.zBack) - s.z)));
        }
    }
    return t;
}

/// Largest |V_map(z) - T(z)| over every pixel of `display` (file
/// coordinates) at 400 depths in [0, 10).
double largestDifference(const DeepShadowMap& map, const Imath::Box2i& display, const SampleSource& samples) {
    double worst = 0.0;
    for (int y = display.min.y; y <= display.max.y; ++y)
        for (int x = display.min.x; x <= display.max.x; ++x) {
            const PixelFunction f = map.pixel(0, std::uint32_t(x - display.min.x), std::uint32_t(y - display.min.y));
            const std::vector<DeepSample> s = samples(x, y);
            for (int k = 0; k < 400; ++k) {
                const double z = k / 40.0;
                worst = std::max(worst, std::abs(f->evaluate(z) - exrTransmittance(s, z)));
            }
        }
    return worst;
}

// ---------------------------------------------------------------------------
// Parts and views

TEST(ExrParts, FlatPartZeroThenTwoDeepViews) {
    test::TempDir dir;
    const auto exr = dir / "stereo.exr", out = dir / "out.dsm";
    TestPart flat;
    flat.name = "beauty";
    flat.deep = false;
    const SampleSource right = [](int, int) { return std::vector<DeepSample>{{2.0f, 2.0f, 0.75f, {}}}; };
    writeParts(exr, {flat, deepPart("deepLeft", "left"), deepPart("deepRight", "right", right)});

    // Default: the first deep part, with a note naming the other.
    ExrImportReport r = importDeepExr(exr.string(), out.string(), withFov());
    EXPECT_EQ(r.part, "part 1 'deepLeft' (view 'left')");
    ASSERT_EQ(r.notes.size(), 1u);
    EXPECT_NE(r.notes[0].find("part 2 'deepRight' (view 'right')"), std::string::npos) << r.notes[0];
    EXPECT_NEAR(DeepShadowMap::open(out.string())->pixel(0, 0, 0)->evaluate(9.0),
                exrTransmittance(variedSamples(0, 0), 9.0), 0.01);

    // By view, by name and by index: the right eye. (Index 2 is assigned as
    // one character: GCC 12 at -O3 warns, a false -Wrestrict, about = "2".)
    for (auto select : std::vector<std::function<void(ExrImportOptions&)>>{
             [](ExrImportOptions& o) { o.view = "right"; }, [](ExrImportOptions& o) { o.part = "deepRight"; },
             [](ExrImportOptions& o) { o.part.assign(1, '2'); }}) {
        ExrImportOptions o = withFov();
        select(o);
        r = importDeepExr(exr.string(), out.string(), o);
        EXPECT_EQ(r.part, "part 2 'deepRight' (view 'right')");
        EXPECT_TRUE(r.notes.empty());
        EXPECT_NEAR(DeepShadowMap::open(out.string())->pixel(0, 3, 4)->evaluate(3.0), 0.25, 1e-6);
    }

    auto message = [&](const std::string& part, const std::string& view) {
        ExrImportOptions o = withFov();
        o.part = part;
        o.view = view;
        try {
            importDeepExr(exr.string(), (dir / "x.dsm").string(), o);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    EXPECT_NE(message("0", "").find("part 0 'beauty' is not a deep image"), std::string::npos) << message("0", "");
    EXPECT_NE(message("7", "").find("no part 7: the file has 3 parts"), std::string::npos) << message("7", "");
    EXPECT_NE(message("nope", "").find("no part named 'nope' (part 0 'beauty' flat, part 1"), std::string::npos)
        << message("nope", "");
    EXPECT_NE(message("", "centre").find("no deep part of view 'centre'"), std::string::npos);
    EXPECT_NE(message("deepLeft", "right").find("is not of view 'right'"), std::string::npos);
    EXPECT_FALSE(std::filesystem::exists(dir / "x.dsm"));
}

// ---------------------------------------------------------------------------
// Channels

TEST(ExrChannels, LayeredNamesFoundOrMapped) {
    test::TempDir dir;
    TestPart p = deepPart("", "");
    p.z = "depth.Z", p.zBack = "depth.ZBack", p.alpha = "rgba.A";
    p.moreChannels = {"rgba.R", "spec.B"};
    writeParts(dir / "layered.exr", {p});
    ExrImportReport r = importDeepExr((dir / "layered.exr").string(), (dir / "a.dsm").string(), withFov());
    EXPECT_EQ(r.channelNames, "Z=depth.Z, ZBack=depth.ZBack, A=rgba.A");
    EXPECT_LE(largestDifference(*DeepShadowMap::open((dir / "a.dsm").string()), p.display, p.samples),
              r.errorBound);

    // Two layers with an alpha: ambiguous until mapped.
    p.moreChannels = {"spec.A"};
    writeParts(dir / "two.exr", {p});
    try {
        importDeepExr((dir / "two.exr").string(), (dir / "b.dsm").string(), withFov());
        ADD_FAILURE() << "an ambiguous alpha was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("channel A is ambiguous: rgba.A, spec.A (choose one with --channels A="),
                  std::string::npos)
            << e.what();
    }
    ExrImportOptions o = withFov();
    o.channels = parseExrChannelMapping("A=rgba.A");
    r = importDeepExr((dir / "two.exr").string(), (dir / "b.dsm").string(), o);
    EXPECT_EQ(r.channelNames, "Z=depth.Z, ZBack=depth.ZBack, A=rgba.A");
    // A mapping to the other layer reads its alphas (all 0.5 here): a different map.
    o.channels = parseExrChannelMapping("A=spec.A,Z=depth.Z");
    r = importDeepExr((dir / "two.exr").string(), (dir / "c.dsm").string(), o);
    EXPECT_EQ(r.channelNames, "Z=depth.Z, ZBack=depth.ZBack, A=spec.A");
    const auto c = DeepShadowMap::open((dir / "c.dsm").string());
    EXPECT_NEAR(c->pixel(0, 3, 0)->evaluate(9.0), 0.5, 0.01);  // one point sample of alpha 0.5

    o.channels = {{"A", "missing.A"}};
    EXPECT_THROW(importDeepExr((dir / "two.exr").string(), (dir / "d.dsm").string(), o), Error);
    for (const char* bad : {"A", "=x", "A=", "Q=x", "A=x,A=y"})
        EXPECT_THROW(parseExrChannelMapping(bad), Error) << bad;
}

// ---------------------------------------------------------------------------
// Tiled inputs: each tile decoded once, true sample counts

TEST(ExrTiled, EachTileDecodedOnceAndSamplesCountedOnce) {
    test::TempDir dir;
    for (int tile : {16, 50, 64, 128}) {
        TestPart p = deepPart("", "");
        p.tile = tile;
        p.display = p.data = Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(99, 149));
        writeParts(dir / "tiled.exr", {p});
        std::uint64_t truth = 0;
        for (int y = 0; y < 150; ++y)
            for (int x = 0; x < 100; ++x) truth += variedSamples(x, y).size();
        ExrImportOptions o = withFov();
        o.tileSize = 32;  // map tile rows that EXR tiles of 50, 64 and 128 straddle
        const ExrImportReport r = importDeepExr((dir / "tiled.exr").string(), (dir / "t.dsm").string(), o);
        const std::uint64_t tiles = std::uint64_t((100 + tile - 1) / tile) * std::uint64_t((150 + tile - 1) / tile);
        EXPECT_TRUE(r.tiled);
        EXPECT_EQ(r.exrChunks, tiles) << tile;
        EXPECT_EQ(r.exrDecodes, tiles) << tile;
        EXPECT_EQ(r.samples, truth) << tile;
        EXPECT_EQ(r.droppedSamples, 0u);
        EXPECT_LE(largestDifference(*DeepShadowMap::open((dir / "t.dsm").string()), p.display, p.samples),
                  r.errorBound);
    }
}

// ---------------------------------------------------------------------------
// Attributes and windows kept; samples merged or left out reported

TEST(ExrKept, AttributesAndDataWindowKeptAndGivenBack) {
    test::TempDir dir;
    TestPart p = deepPart("beauty", "left");
    p.strings = {{"owner", "lighting"}, {"comments", "caf\xc3\xa9 \xff"}};
    p.display = Imath::Box2i(Imath::V2i(-2, 3), Imath::V2i(17, 18));
    p.data = Imath::Box2i(Imath::V2i(1, 5), Imath::V2i(12, 14));
    writeParts(dir / "in.exr", {p});
    importDeepExr((dir / "in.exr").string(), (dir / "map.dsm").string(), withFov());
    const auto map = DeepShadowMap::open((dir / "map.dsm").string());
    EXPECT_EQ(map->info().width, 20u);
    const auto meta = nlohmann::json::parse(map->info().metadata);
    EXPECT_EQ(meta["exr"]["owner"], "lighting");
    EXPECT_EQ(meta["exr"]["name"], "beauty");
    EXPECT_EQ(meta["exr"]["view"], "left");
    EXPECT_EQ(meta["exr"]["comments"], "caf\xc3\xa9 \xef\xbf\xbd");  // the invalid byte as U+FFFD
    EXPECT_EQ(meta["exr"]["dataWindow"], nlohmann::json::array({1, 5, 12, 14}));
    EXPECT_EQ(meta["exr"]["displayWindow"], nlohmann::json::array({-2, 3, 17, 18}));
    EXPECT_LE(largestDifference(*map, p.display,
                                [&](int x, int y) {
                                    return p.data.intersects(Imath::V2i(x, y)) ? variedSamples(x, y)
                                                                               : std::vector<DeepSample>{};
                                }),
              map->info().levels[0].errorBound);

    exportDeepExr((dir / "map.dsm").string(), (dir / "out.exr").string());
    Imf::MultiPartInputFile back((dir / "out.exr").string().c_str());
    const Imf::Header& h = back.header(0);
    EXPECT_EQ(h.dataWindow(), p.data);
    EXPECT_EQ(h.displayWindow(), p.display);
    for (const char* name : {"owner", "name", "view"}) {
        const auto* a = h.findTypedAttribute<Imf::StringAttribute>(name);
        ASSERT_NE(a, nullptr) << name;
        EXPECT_EQ(a->value(), meta["exr"][name].get<std::string>());
    }
    // And in again: the same map.
    const ExrImportReport again = importDeepExr((dir / "out.exr").string(), (dir / "again.dsm").string());
    EXPECT_EQ(again.width, 20u);
    EXPECT_EQ(again.droppedSamples, 0u);
}

TEST(ExrKept, MergedAndOutOfWindowSamplesReported) {
    test::TempDir dir;
    TestPart p = deepPart("", "", [](int x, int y) {
        // Two coincident points in every pixel, and a third one in odd columns.
        std::vector<DeepSample> s = {{2.0f, 2.0f, 0.5f, {}}, {2.0f, 2.0f, 0.5f, {}}};
        if (x % 2) s.push_back({2.0f, 2.0f, 0.5f, {}});
        (void)y;
        return s;
    });
    p.display = Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(9, 9));
    p.data = Imath::Box2i(Imath::V2i(-3, -2), Imath::V2i(11, 12));  // 15 x 15, 100 pixels inside
    writeParts(dir / "wide.exr", {p});
    const ExrImportReport r = importDeepExr((dir / "wide.exr").string(), (dir / "m.dsm").string(), withFov());
    std::uint64_t inside = 0, outside = 0;
    for (int y = -2; y <= 12; ++y)
        for (int x = -3; x <= 11; ++x) (p.display.intersects(Imath::V2i(x, y)) ? inside : outside) += 2 + (x & 1);
    EXPECT_EQ(r.samples, inside);
    EXPECT_EQ(r.droppedSamples, outside);
    EXPECT_EQ(r.mergedSamples, 100u + 50u);  // one per pixel, two in odd columns
    const auto map = DeepShadowMap::open((dir / "m.dsm").string());
    EXPECT_NEAR(map->pixel(0, 0, 0)->evaluate(3.0), 0.25, 1e-6);
    EXPECT_NEAR(map->pixel(0, 1, 0)->evaluate(3.0), 0.125, 1e-6);
}

// ---------------------------------------------------------------------------
// Error bounds that hold

TEST(ExrBounds, VolumetricImportRecordsItsTrueBound) {
    test::TempDir dir;
    // Dense volumes: long exponentials whose chords and compression both count.
    const SampleSource fog = [](int x, int y) {
        std::vector<DeepSample> s;
        for (int i = 0; i < 3; ++i) {
            const float z = 1.0f + float(i) * 2.5f + float(x % 3) * 0.25f, a = 0.6f + 0.1f * float((y + i) % 4);
            s.push_back({z, z + 2.0f, a, {a, a, a}});
        }
        return s;
    };
    TestPart p = deepPart("", "", fog);
    writeParts(dir / "fog.exr", {p});
    ExrImportOptions o = withFov();
    o.tolerance = 0.01;
    o.maxLinearError = 0.01;
    const ExrImportReport r = importDeepExr((dir / "fog.exr").string(), (dir / "fog.dsm").string(), o);
    EXPECT_EQ(r.errorBound, 0.02);
    const auto map = DeepShadowMap::open((dir / "fog.dsm").string());
    EXPECT_EQ(map->info().levels[0].errorBound, 0.02);
    const double worst = largestDifference(*map, p.display, fog);
    std::printf("[ measured ] volumetric import: largest |V - T| %.4g = %.3g eps (recorded bound %.3g)\n", worst,
                worst / 0.01, r.errorBound);
    EXPECT_GT(worst, 0.01);  // the tolerance alone would understate it
    EXPECT_LE(worst, r.errorBound);
}

/// A 24 x 24 map of random functions; with `layered` every pixel has counts
/// and a second layer.
void writeMap(const std::filesystem::path& path, bool layered, int channels = 1,
              const std::string& metadata = R"({"test":"pipeline"})") {
    WriterOptions o;
    o.width = o.height = 24;
    o.tileSize = 8;
    o.channels = channels;
    o.tolerance = 0.01;
    o.counts = layered;
    o.maxLayers = layered ? 3 : 1;
    o.camera.screenWindow = {-1.0, 1.0, -1.0, 1.0};
    o.metadata = metadata;
    MapWriter writer(path.string(), o);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<VisibilityFunction> tile;
            for (std::uint32_t i = 0; i < writer.tileWidth(tx) * writer.tileHeight(ty); ++i) {
                // An RGB map holds monochrome pixels (every fourth) and grey RGB ones (the next) too.
                const bool grey = channels == 3 && i % 4 < 2;
                VisibilityFunction f(channels == 3 && i % 4 == 0 ? 1 : channels, layered);
                const int layers = layered ? 1 + int(rng() % 3) : 1;
                float z = float(1.0 + unit(rng));
                for (int l = 0; l < layers; ++l) {
                    if (l > 0) f.beginLayer();
                    double v = 1.0;
                    for (int k = 0; k < 1 + int(rng() % 4); ++k) {
                        z += float(0.1 + unit(rng));
                        v *= 0.3 + 0.6 * unit(rng);
                        const float values[3] = {float(v), float(grey ? v : v * 0.9), float(grey ? v : v * 0.8)};
                        f.append(z, values, 1 + std::uint32_t(rng() % 5));
                    }
                }
                tile.push_back(std::move(f));
            }
            writer.writeTile(tx, ty, tile);
        }
    writer.finish();
}

TEST(ExrBounds, RoundTripRecordsItsTrueBound) {
    test::TempDir dir;
    writeMap(dir / "map.dsm", false);
    const ExrExportReport er = exportDeepExr((dir / "map.dsm").string(), (dir / "map.exr").string());
    EXPECT_FALSE(er.vertexSamples);
    const ExrImportReport ir = importDeepExr((dir / "map.exr").string(), (dir / "back.dsm").string());
    const auto a = DeepShadowMap::open((dir / "map.dsm").string()), b = DeepShadowMap::open((dir / "back.dsm").string());
    const double stated = a->info().levels[0].errorBound;
    EXPECT_EQ(ir.sourceErrorBound, stated + er.maxDeviation);
    EXPECT_DOUBLE_EQ(ir.errorBound, ir.tolerance + ir.maxLinearError + stated + er.maxDeviation);
    EXPECT_EQ(b->info().levels[0].errorBound, ir.errorBound);
    // The round trip's own error, against the map it came from: within what
    // the back map states beyond the map's own bound.
    double worst = 0.0;
    for (std::uint32_t y = 0; y < 24; ++y)
        for (std::uint32_t x = 0; x < 24; ++x)
            for (int k = 0; k < 300; ++k)
                worst = std::max(worst, std::abs(a->pixel(0, x, y)->evaluate(k / 30.0) -
                                                 b->pixel(0, x, y)->evaluate(k / 30.0)));
    std::printf("[ measured ] dsm -> exr -> dsm: largest |dV| %.4g; recorded bound %.4g (was %.4g)\n", worst,
                ir.errorBound, ir.tolerance);
    EXPECT_LE(worst, ir.errorBound - stated);
    EXPECT_GT(ir.errorBound, 2.0 * ir.tolerance);
}

TEST(ExrKept, WindowsNoImageCouldHaveAreNotGivenBack) {
    test::TempDir dir;
    // Edited metadata: a data window four billion pixels wide.
    writeMap(dir / "map.dsm", false, 1,
             R"({"exr":{"owner":"x","dataWindow":[-2000000000,0,2000000000,10],"displayWindow":[5,5,28,28]}})");
    exportDeepExr((dir / "map.dsm").string(), (dir / "out.exr").string());
    Imf::MultiPartInputFile back((dir / "out.exr").string().c_str());
    const Imath::Box2i window(Imath::V2i(0, 0), Imath::V2i(23, 23));
    EXPECT_EQ(back.header(0).dataWindow(), window);
    EXPECT_EQ(back.header(0).displayWindow(), window);
    EXPECT_EQ(back.header(0).typedAttribute<Imf::StringAttribute>("owner").value(), "x");
}

// ---------------------------------------------------------------------------
// Vertex samples: layers and counts, losslessly

TEST(ExrVertexSamples, LayersAndCountsComeBackExactly) {
    test::TempDir dir;
    for (int channels : {1, 3})
        for (bool tiled : {false, true}) {
            writeMap(dir / "map.dsm", true, channels);
            ExrExportOptions eo;
            eo.tiled = tiled;
            eo.tileSize = 16;
            const ExrExportReport er = exportDeepExr((dir / "map.dsm").string(), (dir / "map.exr").string(), eo);
            EXPECT_TRUE(er.vertexSamples);
            EXPECT_GT(er.vertices, 0u);
            const ExrImportReport ir = importDeepExr((dir / "map.exr").string(), (dir / "back.dsm").string());
            EXPECT_TRUE(ir.fromVertexSamples);
            const auto a = DeepShadowMap::open((dir / "map.dsm").string());
            const auto b = DeepShadowMap::open((dir / "back.dsm").string());
            EXPECT_TRUE(b->info().hasCounts);
            EXPECT_EQ(b->info().maxLayers, a->info().maxLayers);
            EXPECT_EQ(b->info().levels[0].errorBound, a->info().levels[0].errorBound);
            EXPECT_EQ(ir.vertices, a->info().levels[0].vertexCount);
            for (std::uint32_t y = 0; y < 24; ++y)
                for (std::uint32_t x = 0; x < 24; ++x) {
                    const VisibilityFunction fa = a->pixel(0, x, y)->toFunction();
                    const VisibilityFunction fb = b->pixel(0, x, y)->toFunction();
                    ASSERT_EQ(fa.size(), fb.size()) << x << "," << y;
                    // Grey pixels come back monochrome, whichever way the map stored them.
                    EXPECT_EQ(fb.channels(), fa.isMonochrome() ? 1 : 3) << x << "," << y;
                    EXPECT_EQ(std::vector<float>(fa.depths().begin(), fa.depths().end()),
                              std::vector<float>(fb.depths().begin(), fb.depths().end()));
                    EXPECT_EQ(std::vector<std::uint32_t>(fa.counts().begin(), fa.counts().end()),
                              std::vector<std::uint32_t>(fb.counts().begin(), fb.counts().end()));
                    ASSERT_EQ(fa.layerCount(), fb.layerCount());
                    for (std::size_t l = 1; l < fa.layerCount(); ++l) EXPECT_EQ(fa.layerBegin(l), fb.layerBegin(l));
                    for (std::size_t i = 0; i < fa.size(); ++i)
                        for (int c = 0; c < channels; ++c)
                            EXPECT_EQ(fa.value(i, std::min(c, fa.channels() - 1)),
                                      fb.value(i, std::min(c, fb.channels() - 1)));
                }
        }
}

// ---------------------------------------------------------------------------
// Clean error text

TEST(ExrErrors, OpenExrMessagesNameTheFileOnce) {
    test::TempDir dir;
    writeParts(dir / "whole.exr", {deepPart("", "")});
    // Cut short: OpenEXR fails reading pixel data and names the file itself.
    std::filesystem::copy_file(dir / "whole.exr", dir / "cut.exr");
    std::filesystem::resize_file(dir / "cut.exr", std::filesystem::file_size(dir / "whole.exr") - 40);
    try {
        importDeepExr((dir / "cut.exr").string(), (dir / "cut.dsm").string(), withFov());
        ADD_FAILURE() << "a truncated file was read";
    } catch (const Error& e) {
        const std::string what = e.what(), path = (dir / "cut.exr").string();
        EXPECT_EQ(what.find(path), 1u) << what;  // "'path': ..."
        EXPECT_EQ(what.find(path, 2), std::string::npos) << what;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "cut.dsm"));
    // The camera error names the options that give one.
    try {
        importDeepExr((dir / "whole.exr").string(), (dir / "w.dsm").string());
        ADD_FAILURE() << "no camera was accepted";
    } catch (const Error& e) {
        for (const char* option : {"--fov", "--ortho-width", "--camera-from"})
            EXPECT_NE(std::string(e.what()).find(option), std::string::npos) << e.what();
    }
    EXPECT_TRUE(hasOpenExrMagic((dir / "whole.exr").string()));
    EXPECT_FALSE(hasOpenExrMagic((dir / "missing.exr").string()));
}

/// True when `text` is valid UTF-8 without control characters.
bool cleanUtf8(const std::string& text) {
    for (std::size_t i = 0; i < text.size();) {
        const unsigned char c = static_cast<unsigned char>(text[i]);
        std::size_t n = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : (c >> 3) == 30 ? 4 : 0;
        if (n == 0 || i + n > text.size() || (n == 1 && c < 0x20)) return false;
        for (std::size_t k = 1; k < n; ++k)
            if ((static_cast<unsigned char>(text[i + k]) & 0xC0) != 0x80) return false;
        i += n;
    }
    return true;
}

TEST(ExrErrors, DamagedHeaderBytesReachNoMessageRaw) {
    test::TempDir dir;
    TestPart p = deepPart("", "");
    p.strings = {{"bad\xff\xfe", "text"}};
    writeParts(dir / "damaged.exr", {p});
    // Claim a size the file cannot hold for the attribute with the non-UTF-8 name.
    std::string bytes;
    {
        std::ifstream in(dir / "damaged.exr", std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), {});
    }
    const std::string key("bad\xff\xfe\0string\0", 13);
    const std::size_t at = bytes.find(key);
    ASSERT_NE(at, std::string::npos);
    bytes.replace(at + key.size(), 4, std::string("\xff\xff\xff\x7f", 4));
    std::ofstream(dir / "damaged.exr", std::ios::binary) << bytes;
    try {
        importDeepExr((dir / "damaged.exr").string(), (dir / "d.dsm").string(), withFov());
        ADD_FAILURE() << "a damaged header was read";
    } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_TRUE(cleanUtf8(what)) << what;
        EXPECT_NE(what.find("header attribute 'bad\\xFF\\xFE' (string) claims 2147483647 bytes"), std::string::npos)
            << what;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "d.dsm"));
}

}  // namespace
}  // namespace dsm
