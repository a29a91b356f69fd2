// Helper for tests/tools/check_dsm_convert.cmake: makes the inputs and checks
// the outputs of dsm-convert and of the third-party tools (oiiotool,
// exrheader, exrinfo). Files are read with OpenEXR and libdsm; every check
// prints what it measured and exits 1 when it is out of bounds.
//
//   exr_check_helper make-map OUT.dsm mono|rgb
//   exr_check_helper flat-alpha MAP.dsm FLAT.exr      A (and AR AG AB) = 1 - V(inf) within 1e-3
//   exr_check_helper compare A.dsm B.dsm FACTOR       |V_A - V_B| <= FACTOR * tolerance of A
//   exr_check_helper make-flat OUT.exr                32 x 32 flat image with A and Z
//   exr_check_helper check-deepened FLAT.exr MAP.dsm  V = 1 before Z, 1 - A from Z on
//   exr_check_helper make-messy OUT.exr               unsorted, overlapping deep samples
//   exr_check_helper check-messy MAP.dsm              against the hand-computed tidy answer
//   exr_check_helper make-no-z OUT.exr                a deep image without a Z channel
//   exr_check_helper make-render OUT.exr W H [TILE]   a sparse camera render: RGBA half + Z float, 0 to 2
//                                                     samples a pixel, name/view/owner, no camera; deep tiled
//                                                     with TILE-pixel tiles when given
//   exr_check_helper make-parts OUT.exr               a flat part 'beauty', deep parts 'left' and 'right' (views)
//   exr_check_helper make-layered OUT.exr             deep channels depth.Z, rgba.A and spec.A
//   exr_check_helper count-samples IN.exr             prints "N samples" of the first deep part, read once
#include <dsm/dsm.h>

#include <ImathBox.h>
#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfDeepScanLineInputPart.h>
#include <ImfDeepScanLineOutputPart.h>
#include <ImfDeepTiledInputPart.h>
#include <ImfDeepTiledOutputFile.h>
#include <ImfMultiPartInputFile.h>
#include <ImfMultiPartOutputFile.h>
#include <ImfOutputPart.h>
#include <ImfPartType.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <exception>
#include <random>
#include <string>
#include <vector>

namespace {

constexpr int kSize = 32;

dsm::VisibilityFunction pixelFunction(std::mt19937& rng, int channels) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    dsm::VisibilityFunction f(channels);
    double v[3] = {1.0, 1.0, 1.0};
    double z = 1.0 + 3.0 * unit(rng);
    const int n = int(rng() % 8);
    for (int i = 0; i < n; ++i) {
        const bool step = unit(rng) < 0.3;
        if (!step) z += 0.05 + unit(rng);
        float values[3];
        for (int c = 0; c < channels; ++c) values[c] = float(v[c] *= 1.0 - unit(rng) * (step ? 0.8 : 0.5));
        f.append(float(z), values);
    }
    return f;
}

int makeMap(const std::string& path, const std::string& kind) {
    dsm::WriterOptions o;
    o.width = kSize;
    o.height = kSize;
    o.tileSize = 16;
    o.channels = kind == "rgb" ? 3 : 1;
    o.tolerance = 0.01;
    o.camera.screenWindow = {-0.5, 0.5, -0.5, 0.5};
    o.camera.worldToLight[11] = 2.0;
    dsm::MapWriter writer(path, o);
    std::mt19937 rng(7);
    for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty)
        for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
            std::vector<dsm::VisibilityFunction> tile;
            for (std::uint32_t i = 0; i < writer.tileWidth(tx) * writer.tileHeight(ty); ++i)
                tile.push_back(pixelFunction(rng, o.channels));
            writer.writeTile(tx, ty, tile);
        }
    writer.finish();
    return 0;
}

/// A flat EXR's float channels by name, with its size.
struct FlatImage {
    int width = 0, height = 0;
    std::vector<std::vector<float>> channels;
    float at(std::size_t channel, int x, int y) const { return channels[channel][std::size_t(y * width + x)]; }
};

FlatImage readFlat(const std::string& path, const std::vector<std::string>& names) {
    Imf::InputFile in(path.c_str());
    const Imath::Box2i dw = in.header().dataWindow();
    FlatImage image;
    image.width = dw.max.x - dw.min.x + 1;
    image.height = dw.max.y - dw.min.y + 1;
    Imf::FrameBuffer fb;
    for (const std::string& name : names) {
        if (!in.header().channels().findChannel(name)) throw std::runtime_error(path + ": no channel " + name);
        image.channels.emplace_back(std::size_t(image.width) * std::size_t(image.height), 0.0f);
        char* base = reinterpret_cast<char*>(image.channels.back().data()) -
                     (std::ptrdiff_t(dw.min.x) + std::ptrdiff_t(dw.min.y) * image.width) * std::ptrdiff_t(sizeof(float));
        fb.insert(name, Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * std::size_t(image.width)));
    }
    in.setFrameBuffer(fb);
    in.readPixels(dw.min.y, dw.max.y);
    return image;
}

double lastValue(const dsm::VisibilityView& f, int channel) {
    if (f.empty()) return 1.0;
    return f.evaluate(std::numeric_limits<float>::max(), std::min(channel, f.channels() - 1));
}

int flatAlpha(const std::string& mapPath, const std::string& flatPath) {
    const auto map = dsm::DeepShadowMap::open(mapPath);
    const int channels = map->info().channels;
    std::vector<std::string> names{"A"};
    bool perChannel = false;
    if (channels == 3) {  // AR, AG, AB are checked when the flattening kept them
        Imf::InputFile probe(flatPath.c_str());
        perChannel = probe.header().channels().findChannel("AR") != nullptr;
        if (perChannel) names.insert(names.end(), {"AR", "AG", "AB"});
    }
    const FlatImage flat = readFlat(flatPath, names);
    if (flat.width != kSize || flat.height != kSize) throw std::runtime_error("flat image has the wrong size");
    double worst = 0.0;
    for (int y = 0; y < kSize; ++y)
        for (int x = 0; x < kSize; ++x) {
            const dsm::PixelFunction f = map->pixel(0, std::uint32_t(x), std::uint32_t(y));
            double mean = 0.0;
            for (int c = 0; c < channels; ++c) {
                const double v = lastValue(f.view(), c);
                mean += v / channels;
                if (perChannel) worst = std::max(worst, std::abs(flat.at(std::size_t(c) + 1, x, y) - (1.0 - v)));
            }
            worst = std::max(worst, std::abs(flat.at(0, x, y) - (1.0 - mean)));
        }
    std::printf("flattened alpha vs 1 - V(inf): largest difference %.3g\n", worst);
    return worst <= 1e-3 ? 0 : 1;
}

int compare(const std::string& aPath, const std::string& bPath, double factor) {
    const auto a = dsm::DeepShadowMap::open(aPath), b = dsm::DeepShadowMap::open(bPath);
    const double eps = a->info().levels[0].tolerance;
    double worst = 0.0;
    for (std::uint32_t y = 0; y < a->info().height; ++y)
        for (std::uint32_t x = 0; x < a->info().width; ++x) {
            const dsm::PixelFunction fa = a->pixel(0, x, y), fb = b->pixel(0, x, y);
            std::vector<double> knots(fa->depths().begin(), fa->depths().end());
            knots.insert(knots.end(), fb->depths().begin(), fb->depths().end());
            std::sort(knots.begin(), knots.end());
            std::vector<double> depths{0.0};
            for (std::size_t i = 0; i < knots.size(); ++i)
                for (int k = 0; k < 16; ++k)
                    depths.push_back(i + 1 < knots.size() ? knots[i] + (knots[i + 1] - knots[i]) * k / 16.0
                                                          : knots[i] + k);
            for (double z : depths)
                for (int c = 0; c < a->info().channels; ++c)
                    worst = std::max(worst, std::abs(fa->evaluate(z, std::min(c, fa->channels() - 1)) -
                                                     fb->evaluate(z, std::min(c, fb->channels() - 1))));
        }
    std::printf("largest |V_a - V_b| %.4g = %.3g x tolerance %g\n", worst, worst / eps, eps);
    return worst <= factor * eps ? 0 : 1;
}

float flatAlphaAt(int x, int y) { return (x + y) % 5 == 0 ? 0.0f : float((x * 7 + y * 3) % 32) / 31.0f; }
float flatDepthAt(int x, int y) { return 1.0f + 0.25f * float(x) + 0.125f * float(y); }

int makeFlat(const std::string& path) {
    Imf::Header header(kSize, kSize);
    header.channels().insert("A", Imf::Channel(Imf::FLOAT));
    header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
    std::vector<float> a, z;
    for (int y = 0; y < kSize; ++y)
        for (int x = 0; x < kSize; ++x) a.push_back(flatAlphaAt(x, y)), z.push_back(flatDepthAt(x, y));
    Imf::FrameBuffer fb;
    fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(a.data()), sizeof(float), sizeof(float) * kSize));
    fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(z.data()), sizeof(float), sizeof(float) * kSize));
    Imf::OutputFile out(path.c_str(), header);
    out.setFrameBuffer(fb);
    out.writePixels(kSize);
    return 0;
}

int checkDeepened(const std::string& flatPath, const std::string& mapPath) {
    const FlatImage flat = readFlat(flatPath, {"A", "Z"});
    const auto map = dsm::DeepShadowMap::open(mapPath);
    dsm::LookupContext lookup(map);
    dsm::LookupOptions nearest;
    nearest.bias = 0.0;  // the stored functions at the depths themselves
    nearest.level = 0;
    double worst = 0.0;
    for (int y = 0; y < kSize; ++y)
        for (int x = 0; x < kSize; ++x) {
            const double alpha = flat.at(0, x, y), z = flat.at(1, x, y);
            // Box width 1 at a pixel centre is that pixel alone.
            auto v = [&](double depth) { return lookup.raster(x + 0.5, y + 0.5, depth, nearest).v[0]; };
            worst = std::max({worst, std::abs(v(0.5 * z) - 1.0), std::abs(v(z * 0.999) - 1.0),
                              std::abs(v(z) - (1.0 - alpha)), std::abs(v(2.0 * z) - (1.0 - alpha))});
        }
    std::printf("deepened flat image: largest |V - expected| %.3g\n", worst);
    return worst <= 1e-3 ? 0 : 1;
}

/// The samples of tests/test_exr_deep.cpp's messy pixel, and its answer.
/// Without Z (`withZ` false) the file is a deep image that cannot be read as
/// one rendered from a light.
int makeMessy(const std::string& path, bool withZ = true) {
    float z[] = {5.0f, 2.0f, 2.5f, 1.0f, 5.0f}, zBack[] = {5.0f, 4.0f, 2.5f, 3.0f, 0.0f};
    float alpha[] = {0.5f, 0.75f, 0.2f, 0.5f, 0.5f};
    Imf::Header header(kSize, 1);
    header.compression() = Imf::ZIPS_COMPRESSION;
    header.setType(Imf::DEEPSCANLINE);
    for (const char* name : {"Z", "ZBack", "A"})
        if (withZ || std::string(name) != "Z") header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    std::vector<unsigned> counts(kSize, 5);
    std::vector<char*> zp(kSize, reinterpret_cast<char*>(z)), bp(kSize, reinterpret_cast<char*>(zBack)), ap(kSize, reinterpret_cast<char*>(alpha));
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), sizeof(unsigned), 0));
    if (withZ) fb.insert("Z", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(zp.data()), sizeof(char*), 0, sizeof(float)));
    fb.insert("ZBack", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(bp.data()), sizeof(char*), 0, sizeof(float)));
    fb.insert("A", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(ap.data()), sizeof(char*), 0, sizeof(float)));
    Imf::DeepScanLineOutputFile out(path.c_str(), header);
    out.setFrameBuffer(fb);
    out.writePixels(1);
    return 0;
}

int checkMessy(const std::string& mapPath) {
    const auto map = dsm::DeepShadowMap::open(mapPath);
    const double bound = map->info().levels[0].tolerance + 1e-3;
    double worst = 0.0;
    for (std::uint32_t x = 0; x < kSize; ++x) {
        const dsm::PixelFunction f = map->pixel(0, x, 0);
        for (int k = 0; k <= 700; ++k) {
            const double zq = 0.5 + k / 100.0;
            const double a = std::pow(0.5, std::clamp((zq - 1.0) / 2.0, 0.0, 1.0));
            const double b = std::pow(0.25, std::clamp((zq - 2.0) / 2.0, 0.0, 1.0));
            const double tidy = a * b * (zq >= 2.5 ? 0.8 : 1.0) * (zq >= 5.0 ? 0.25 : 1.0);
            worst = std::max(worst, std::abs(f->evaluate(zq) - tidy));
        }
    }
    std::printf("messy deep image: largest |V - tidy answer| %.3g (bound %.3g)\n", worst, bound);
    return worst <= bound ? 0 : 1;
}

/// A sparse deep render as a camera writes it: RGBA half and Z float, about
/// a third of the pixels empty and the rest one or two point samples.
int makeRender(const std::string& path, int width, int height, int tile) {
    Imf::Header header(width, height);
    header.compression() = Imf::ZIPS_COMPRESSION;
    for (const char* name : {"R", "G", "B", "A"}) header.channels().insert(name, Imf::Channel(Imf::HALF));
    header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
    header.insert("name", Imf::StringAttribute("beauty"));
    header.insert("view", Imf::StringAttribute("left"));
    header.insert("owner", Imf::StringAttribute("lighting"));
    struct Sample {
        half r, g, b, a;
        float z;
    };
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const std::size_t n = std::size_t(width) * std::size_t(height);
    std::vector<unsigned> counts(n);
    std::vector<std::vector<Sample>> samples(n);
    for (std::size_t i = 0; i < n; ++i) {
        const unsigned k = unsigned(rng() % 3);
        float z = 1.0f + 10.0f * unit(rng);
        for (unsigned j = 0; j < k; ++j, z += 0.5f + unit(rng)) {
            const half a(0.1f + 0.9f * unit(rng));
            samples[i].push_back({a, a, a, a, z});
        }
        counts[i] = k;
    }
    std::vector<char*> pointers[5];
    for (auto& p : pointers) p.assign(n, nullptr);
    for (std::size_t i = 0; i < n; ++i) {
        char* base = reinterpret_cast<char*>(samples[i].data());
        if (!base) continue;
        pointers[0][i] = base + offsetof(Sample, r), pointers[1][i] = base + offsetof(Sample, g);
        pointers[2][i] = base + offsetof(Sample, b), pointers[3][i] = base + offsetof(Sample, a);
        pointers[4][i] = base + offsetof(Sample, z);
    }
    Imf::DeepFrameBuffer fb;
    const std::size_t ys = sizeof(char*) * std::size_t(width);
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), sizeof(unsigned),
                                         sizeof(unsigned) * std::size_t(width)));
    const char* names[] = {"R", "G", "B", "A", "Z"};
    for (int c = 0; c < 5; ++c)
        fb.insert(names[c], Imf::DeepSlice(c == 4 ? Imf::FLOAT : Imf::HALF,
                                           reinterpret_cast<char*>(pointers[c].data()), sizeof(char*), ys,
                                           sizeof(Sample)));
    if (tile > 0) {
        header.setTileDescription(Imf::TileDescription(unsigned(tile), unsigned(tile), Imf::ONE_LEVEL));
        header.setType(Imf::DEEPTILE);
        Imf::DeepTiledOutputFile out(path.c_str(), header);
        out.setFrameBuffer(fb);
        out.writeTiles(0, out.numXTiles(0) - 1, 0, out.numYTiles(0) - 1);
    } else {
        header.setType(Imf::DEEPSCANLINE);
        Imf::DeepScanLineOutputFile out(path.c_str(), header);
        out.setFrameBuffer(fb);
        out.writePixels(height);
    }
    return 0;
}

/// One point sample of alpha 0.5 at depth 2 in every pixel of a 16 x 8
/// deep part, its channels named `z` and `alpha` (and `more`, filled alike).
void writeDeepPart(Imf::MultiPartOutputFile& file, int part) {
    const Imf::Header& h = file.header(part);
    std::vector<std::string> names;
    for (auto it = h.channels().begin(); it != h.channels().end(); ++it) names.push_back(it.name());
    const int width = 16, height = 8;
    std::vector<float> values(names.size());
    for (std::size_t c = 0; c < names.size(); ++c) values[c] = names[c].back() == 'Z' ? 2.0f : 0.5f;
    std::vector<unsigned> counts(std::size_t(width * height), 1);
    std::vector<std::vector<char*>> pointers(names.size());
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), sizeof(unsigned),
                                         sizeof(unsigned) * width));
    for (std::size_t c = 0; c < names.size(); ++c) {
        pointers[c].assign(counts.size(), reinterpret_cast<char*>(&values[c]));
        fb.insert(names[c], Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(pointers[c].data()), sizeof(char*),
                                           sizeof(char*) * width, sizeof(float)));
    }
    Imf::DeepScanLineOutputPart out(file, part);
    out.setFrameBuffer(fb);
    out.writePixels(height);
}

Imf::Header deepHeader(const std::string& name, const std::string& view, const std::vector<const char*>& channels) {
    Imf::Header h(16, 8);
    h.compression() = Imf::ZIPS_COMPRESSION;
    h.setType(Imf::DEEPSCANLINE);
    if (!name.empty()) h.setName(name);
    if (!view.empty()) h.setView(view);
    for (const char* c : channels) h.channels().insert(c, Imf::Channel(Imf::FLOAT));
    return h;
}

int makeParts(const std::string& path) {
    Imf::Header flat(16, 8);
    flat.setName("beauty");
    flat.setType(Imf::SCANLINEIMAGE);
    flat.channels().insert("R", Imf::Channel(Imf::FLOAT));
    const Imf::Header headers[] = {flat, deepHeader("left", "left", {"Z", "A"}), deepHeader("right", "right", {"Z", "A"})};
    Imf::MultiPartOutputFile file(path.c_str(), headers, 3);
    std::vector<float> r(16 * 8, 0.5f);
    Imf::FrameBuffer fb;
    fb.insert("R", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(r.data()), sizeof(float), sizeof(float) * 16));
    Imf::OutputPart beauty(file, 0);
    beauty.setFrameBuffer(fb);
    beauty.writePixels(8);
    writeDeepPart(file, 1);
    writeDeepPart(file, 2);
    return 0;
}

int makeLayered(const std::string& path) {
    const Imf::Header headers[] = {deepHeader("", "", {"depth.Z", "rgba.A", "spec.A"})};
    Imf::MultiPartOutputFile file(path.c_str(), headers, 1);
    writeDeepPart(file, 0);
    return 0;
}

int countSamples(const std::string& path) {
    Imf::MultiPartInputFile file(path.c_str());
    int part = 0;
    while (part < file.parts() && !Imf::isDeepData(file.header(part).type())) ++part;
    const Imf::Header& h = file.header(part);
    const Imath::Box2i dw = h.dataWindow();
    const int width = dw.max.x - dw.min.x + 1, height = dw.max.y - dw.min.y + 1;
    std::vector<unsigned> counts(std::size_t(width) * std::size_t(height));
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT,
                                         reinterpret_cast<char*>(counts.data() - (dw.min.x + std::ptrdiff_t(dw.min.y) * width)),
                                         sizeof(unsigned), sizeof(unsigned) * std::size_t(width)));
    if (h.type() == Imf::DEEPTILE) {
        Imf::DeepTiledInputPart in(file, part);
        in.setFrameBuffer(fb);
        in.readPixelSampleCounts(0, in.numXTiles(0) - 1, 0, in.numYTiles(0) - 1);
    } else {
        Imf::DeepScanLineInputPart in(file, part);
        in.setFrameBuffer(fb);
        in.readPixelSampleCounts(dw.min.y, dw.max.y);
    }
    unsigned long long total = 0;
    for (unsigned c : counts) total += c;
    std::printf("%llu samples\n", total);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        const std::vector<std::string> a(argv + 1, argv + argc);
        if (a.size() == 3 && a[0] == "make-map") return makeMap(a[1], a[2]);
        if (a.size() == 3 && a[0] == "flat-alpha") return flatAlpha(a[1], a[2]);
        if (a.size() == 4 && a[0] == "compare") return compare(a[1], a[2], std::stod(a[3]));
        if (a.size() == 2 && a[0] == "make-flat") return makeFlat(a[1]);
        if (a.size() == 3 && a[0] == "check-deepened") return checkDeepened(a[1], a[2]);
        if (a.size() == 2 && a[0] == "make-messy") return makeMessy(a[1]);
        if (a.size() == 2 && a[0] == "check-messy") return checkMessy(a[1]);
        if (a.size() == 2 && a[0] == "make-no-z") return makeMessy(a[1], false);
        if (a.size() == 2 && a[0] == "make-parts") return makeParts(a[1]);
        if (a.size() == 2 && a[0] == "make-layered") return makeLayered(a[1]);
        if (a.size() == 2 && a[0] == "count-samples") return countSamples(a[1]);
        if ((a.size() == 4 || a.size() == 5) && a[0] == "make-render")
            return makeRender(a[1], std::stoi(a[2]), std::stoi(a[3]), a.size() == 5 ? std::stoi(a[4]) : 0);
        std::fprintf(stderr, "exr_check_helper: bad arguments (see the head of exr_check_helper.cpp)\n");
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "exr_check_helper: %s\n", e.what());
        return 1;
    }
}
