// Product and stitch of deep shadow maps (spec/merge.md).
//
// Stitching reproduces a single full build byte for byte, so it mirrors what
// buildMap (sampler.cpp) hands the writer: the same WriterOptions, level-0
// tiles in row order, and the metadata as nlohmann::json dump() text with
// settings.region covering the image. Everything the writer derives (mip
// levels, directories, header) then follows.
#include "dsm/merge.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include "dsm/error.h"
#include "dsm/names.h"
#include "dsm/output_file.h"
#include "dsm/reader.h"
#include "dsm/visibility_product.h"
#include "dsm/writer.h"
#include "naming_file.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;
using detail::exactNumber;

namespace {

using Json = nlohmann::json;
using Map = std::shared_ptr<DeepShadowMap>;

// The compressor's bound includes float32 rounding (compressor.h).
constexpr double kStoreRounding = 0x1p-25;
constexpr int kDefaultZlibLevel = 6;

std::string quoted(const std::string& path) { return concat("'", path, "'"); }

template <std::size_t N>
std::string numbers(const std::array<double, N>& values) {
    std::string out = "[";
    for (std::size_t i = 0; i < N; ++i) {
        if (i) out += ',';
        out += exactNumber(values[i]);
    }
    return out + "]";
}

// Throws when `field` differs between the first input and another.
void requireSame(const std::string& field, const std::string& value, const std::string& firstValue,
                 const std::string& path, const std::string& firstPath) {
    if (value != firstValue)
        throw Error(ErrorCode::argument, concat(quoted(path), ": ", field, " is ", value, " but ", firstValue, " in ",
                                                quoted(firstPath), ": the maps cannot be merged"));
}

// The fields both modes need to agree on: the pixel grid and what a pixel means.
void requireSameGeometry(const DeepShadowMap& map, const DeepShadowMap& first) {
    const MapInfo& a = map.info();
    const MapInfo& b = first.info();
    const std::string& p = map.path();
    const std::string& q = first.path();
    requireSame("the size", concat(a.width, "x", a.height), concat(b.width, "x", b.height), p, q);
    requireSame("the tile size", concat(a.tileSize), concat(b.tileSize), p, q);
    requireSame("the light projection", projectionName(a.camera.projection), projectionName(b.camera.projection), p, q);
    requireSame("the light's world-to-light matrix", numbers(a.camera.worldToLight), numbers(b.camera.worldToLight), p,
                q);
    requireSame("the light's screen window", numbers(a.camera.screenWindow), numbers(b.camera.screenWindow), p, q);
    requireSame("the light's near plane", exactNumber(a.camera.nearPlane), exactNumber(b.camera.nearPlane), p, q);
    requireSame("the pixel filter", filterName(a.filter), filterName(b.filter), p, q);
    requireSame("the filter width", exactNumber(a.filterWidth), exactNumber(b.filterWidth), p, q);
}

Json parseMetadata(const DeepShadowMap& map) {
    Json parsed = Json::parse(map.info().metadata, nullptr, false);
    return parsed.is_discarded() ? Json(map.info().metadata) : parsed;
}

void checkOutput(const std::vector<std::string>& inputs, const std::string& output) {
    if (inputs.empty()) throw Error(ErrorCode::argument, "merge: no input maps");
    checkOutputPath(output);
    refuseOutputOverInputs(output, inputs);
}

std::vector<Map> openAll(const std::vector<std::string>& inputs) {
    std::vector<Map> maps;
    for (const std::string& path : inputs) maps.push_back(DeepShadowMap::open(path));
    return maps;
}

std::uint64_t fileSize(const std::string& path) {
    std::error_code ignored;
    const auto size = std::filesystem::file_size(path, ignored);
    return ignored ? 0 : size;
}

// ---------------------------------------------------------------------------
// Product

// The bound on a map's level-0 functions against what they approximate: the
// writer's bound, plus what an earlier product recorded about its inputs.
double levelZeroErrorBound(const DeepShadowMap& map, const Json& metadata) {
    double bound = map.info().levels.at(0).errorBound;
    if (metadata.is_object() && metadata.contains("merge") && metadata["merge"].is_object()) {
        const Json& merge = metadata["merge"];
        if (merge.contains("input_error_bound") && merge["input_error_bound"].is_number())
            bound += merge["input_error_bound"].get<double>();
    }
    return bound;
}

// Calls visit(tx, ty, x, y, index-in-tile) for every level-0 pixel, tile by
// tile in row order.
template <class TileBegin, class Visit, class TileEnd>
void forEachTile(const MapInfo& info, TileBegin&& begin, Visit&& visit, TileEnd&& end) {
    const std::uint32_t T = info.tileSize;
    const std::uint32_t tilesX = (info.width + T - 1) / T, tilesY = (info.height + T - 1) / T;
    for (std::uint32_t ty = 0; ty < tilesY; ++ty)
        for (std::uint32_t tx = 0; tx < tilesX; ++tx) {
            const std::uint32_t x0 = tx * T, y0 = ty * T;
            const std::uint32_t x1 = std::min(x0 + T, info.width), y1 = std::min(y0 + T, info.height);
            begin(std::size_t(x1 - x0) * (y1 - y0));
            std::size_t index = 0;
            for (std::uint32_t y = y0; y < y1; ++y)
                for (std::uint32_t x = x0; x < x1; ++x) visit(x, y, index++);
            end(tx, ty);
        }
}

MergeReport multiplyMaps(const std::vector<Map>& maps, const std::string& output, const MergeOptions& options) {
    const DeepShadowMap& first = *maps.front();
    const MapInfo& info = first.info();
    int channels = 1;
    bool counts = true;
    std::size_t levels = 1;
    double tolerance = 0.0, inputBound = 0.0;
    // Layers only when every input has them: a map of one layer knows nothing
    // of what hides behind its opaque parts.
    bool layered = true;
    int layers = 1;
    Json inputs = Json::array();
    for (const Map& map : maps) {
        requireSameGeometry(*map, first);
        const MapInfo& m = map->info();
        layered = layered && m.maxLayers > 1;
        layers = std::max(layers, m.maxLayers);
        channels = std::max(channels, m.channels);
        counts = counts && m.hasCounts;
        levels = std::max(levels, m.levels.size());
        tolerance = std::max(tolerance, m.levels.at(0).tolerance);
        const Json metadata = parseMetadata(*map);
        const double bound = levelZeroErrorBound(*map, metadata);
        inputBound += bound;
        inputs.push_back({{"file", map->path()}, {"level0_error_bound", bound}, {"metadata", metadata}});
    }
    if (options.tolerance) tolerance = *options.tolerance;
    if (!std::isfinite(tolerance) || tolerance < 0.0)
        throw Error(ErrorCode::argument, concat("merge: tolerance ", tolerance, " is not a finite value >= 0"));

    VisibilityProductOptions product;
    product.tolerance = tolerance;
    product.maxInterpolationError = options.maxInterpolationError;
    product.keepCounts = counts;
    product.maxLayers = layered ? layers : 1;
    std::vector<int> budgets;
    for (const Map& map : maps) budgets.push_back(map->info().maxLayers);
    if (layered) product.factorLayers = budgets;

    std::vector<VisibilityView> factors(maps.size());
    std::vector<PixelFunction> held(maps.size());
    auto gather = [&](std::uint32_t x, std::uint32_t y) {
        for (std::size_t i = 0; i < maps.size(); ++i) {
            held[i] = maps[i]->pixel(0, x, y);
            factors[i] = held[i].view();
        }
    };

    // Pass 1: the interpolation error, which the metadata records and the
    // writer needs before it opens.
    double interpolation = 0.0;
    forEachTile(
        info, [](std::size_t) {},
        [&](std::uint32_t x, std::uint32_t y, std::size_t) {
            gather(x, y);
            interpolation = std::max(interpolation, multiplyVisibility(factors, product).interpolationError);
        },
        [](std::uint32_t, std::uint32_t) {});

    MergeReport report;
    report.width = info.width;
    report.height = info.height;
    report.channels = channels;
    report.maxLayers = product.maxLayers;
    report.tolerance = tolerance;
    report.zlibLevel = options.zlibLevel.value_or(kDefaultZlibLevel);
    report.interpolationError = interpolation;
    report.inputErrorBound = inputBound + interpolation;
    report.errorBound = report.inputErrorBound + std::max(tolerance, kStoreRounding);

    WriterOptions w;
    w.width = info.width;
    w.height = info.height;
    w.tileSize = info.tileSize;
    w.channels = channels;
    w.counts = counts;
    w.maxLayers = product.maxLayers;
    w.camera = info.camera;
    w.filter = info.filter;
    w.filterWidth = info.filterWidth;
    w.tolerance = tolerance;
    w.mipLevels = static_cast<unsigned>(levels);
    w.zlibLevel = report.zlibLevel;
    w.metadata = Json{{"software", "libdsm"},
                      {"merge",
                       {{"mode", "product"},
                        {"inputs", inputs},
                        {"tolerance", tolerance},
                        {"interpolation_error", interpolation},
                        {"input_error_bound", report.inputErrorBound},
                        {"error_bound", report.errorBound},
                        {"layers", product.maxLayers > 1 ? "restarted from the inputs' layers"
                                                          : "light-centre product only"}}}}
                     .dump();
    MapWriter writer(output, w);
    std::vector<VisibilityFunction> pixels;
    forEachTile(
        info, [&](std::size_t n) { pixels.assign(n, VisibilityFunction(1, counts)); },
        [&](std::uint32_t x, std::uint32_t y, std::size_t index) {
            gather(x, y);
            pixels[index] = multiplyVisibility(factors, product).function;
            report.vertices += pixels[index].size();
        },
        [&](std::uint32_t tx, std::uint32_t ty) { writer.writeTile(tx, ty, pixels); });
    writer.finish();
    report.fileBytes = fileSize(output);
    return report;
}

// ---------------------------------------------------------------------------
// Stitch

using Rect = std::array<std::uint32_t, 4>;  // x0, y0, x1, y1, half-open

std::string rectText(const Rect& r) { return concat(r[0], ",", r[1], ",", r[2], ",", r[3]); }

// Whether the part's build compressed with centred segments (metadata
// settings.compression "centred", dsm-build --centred-compression): the
// mip levels rebuilt from its pixels must be compressed alike. Absent, the
// build used the greedy rule; another value is a setting this version cannot
// reproduce. `metadata` has an object `settings` (regionOf() checked it).
bool centredCompressionOf(const DeepShadowMap& map, const Json& metadata) {
    const Json& settings = metadata.at("settings");
    const auto compression = settings.find("compression");
    if (compression == settings.end()) return false;
    if (compression->is_string() && *compression == "centred") return true;
    throw Error(ErrorCode::argument, concat(quoted(map.path()), ": settings.compression ", compression->dump(),
                                            " is not \"centred\": the mip levels cannot be rebuilt as the build's"));
}

Rect regionOf(const DeepShadowMap& map, const Json& metadata) {
    const auto missing = [&](const std::string& why) {
        return Error(ErrorCode::argument,
                     concat(quoted(map.path()), ": ", why,
                            ": stitching needs maps from dsm-build --region (metadata settings.region)"));
    };
    if (!metadata.is_object() || !metadata.contains("settings") || !metadata["settings"].is_object() ||
        !metadata["settings"].contains("region"))
        throw missing("the metadata has no settings.region");
    const Json& region = metadata["settings"]["region"];
    if (!region.is_array() || region.size() != 4) throw missing("settings.region is not 4 numbers");
    Rect r{};
    for (std::size_t i = 0; i < 4; ++i) {
        if (!region[i].is_number_unsigned()) throw missing("settings.region is not 4 non-negative integers");
        r[i] = region[i].get<std::uint32_t>();
    }
    const MapInfo& info = map.info();
    if (r[0] >= r[2] || r[1] >= r[3] || r[2] > info.width || r[3] > info.height)
        throw Error(ErrorCode::argument, concat(quoted(map.path()), ": settings.region ", rectText(r),
                                                " is empty or outside the ", info.width, "x", info.height, " image"));
    return r;
}

// The first place where two JSON values differ, as "path: a vs b".
std::optional<std::string> firstDifference(const Json& a, const Json& b, const std::string& path) {
    if (a.is_object() && b.is_object()) {
        for (auto it = a.begin(); it != a.end(); ++it) {
            const std::string key = path.empty() ? it.key() : path + "." + it.key();
            if (!b.contains(it.key())) return concat("metadata ", key, " is missing");
            if (auto d = firstDifference(it.value(), b[it.key()], key)) return d;
        }
        for (auto it = b.begin(); it != b.end(); ++it)
            if (!a.contains(it.key())) return concat("metadata ", path.empty() ? "" : path + ".", it.key(), " is extra");
        return std::nullopt;
    }
    if (a == b) return std::nullopt;
    const auto shortText = [](const Json& v) {
        std::string text = v.dump();
        return text.size() > 60 ? text.substr(0, 57) + "..." : text;
    };
    return concat("metadata ", path.empty() ? "(whole)" : path, " is ", shortText(b), " but ", shortText(a));
}

void requireSameStitchSettings(const DeepShadowMap& map, const DeepShadowMap& first, Json metadata, Json firstMetadata) {
    requireSameGeometry(map, first);
    const MapInfo& a = map.info();
    const MapInfo& b = first.info();
    const std::string& p = map.path();
    const std::string& q = first.path();
    requireSame("the channel count", concat(a.channels), concat(b.channels), p, q);
    requireSame("the sample counts flag", a.hasCounts ? "on" : "off", b.hasCounts ? "on" : "off", p, q);
    requireSame("the layer count", concat(a.maxLayers), concat(b.maxLayers), p, q);
    requireSame("the mip level count", concat(a.levels.size()), concat(b.levels.size()), p, q);
    for (std::size_t l = 0; l < a.levels.size(); ++l) {
        requireSame(concat("the level ", l, " tolerance"), exactNumber(a.levels[l].tolerance),
                    exactNumber(b.levels[l].tolerance), p, q);
        requireSame(concat("the level ", l, " value step"), exactNumber(a.levels[l].valueStep),
                    exactNumber(b.levels[l].valueStep), p, q);
    }
    requireSame("the tile codec", a.codec == TileCodec::Zstd ? "zstd" : "zlib", b.codec == TileCodec::Zstd ? "zstd" : "zlib",
                p, q);
    requireSame("the zlib level", concat(a.codecLevel), concat(b.codecLevel), p, q);
    requireSame("the area light", exactNumber(a.areaLightRadius) + " at " + exactNumber(a.areaLightPlaneDepth),
                exactNumber(b.areaLightRadius) + " at " + exactNumber(b.areaLightPlaneDepth), p, q);
    metadata["settings"].erase("region");
    firstMetadata["settings"].erase("region");
    if (auto difference = firstDifference(firstMetadata, metadata, ""))
        throw Error(ErrorCode::argument,
                    concat(quoted(p), ": ", *difference, " in ", quoted(q), ": the maps are not parts of one build"));
}

bool intersects(const Rect& a, const Rect& b) { return a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]; }

// Overlapping pairs, then uncovered pixels, as one error.
void requireTiling(const std::vector<Map>& maps, const std::vector<Rect>& regions) {
    constexpr std::size_t kListed = 5;
    std::vector<std::string> overlaps;
    std::size_t overlapCount = 0;
    for (std::size_t i = 0; i < regions.size(); ++i)
        for (std::size_t j = i + 1; j < regions.size(); ++j)
            if (intersects(regions[i], regions[j])) {
                const Rect& a = regions[i];
                const Rect& b = regions[j];
                const Rect common{std::max(a[0], b[0]), std::max(a[1], b[1]), std::min(a[2], b[2]), std::min(a[3], b[3])};
                if (++overlapCount <= kListed)
                    overlaps.push_back(concat(quoted(maps[i]->path()), " region ", rectText(a), " and ",
                                              quoted(maps[j]->path()), " region ", rectText(b), " share ",
                                              rectText(common)));
            }
    if (overlapCount > 0) {
        std::string text = concat(overlapCount, " pair", overlapCount == 1 ? "" : "s",
                                  " of regions overlap: ");
        for (std::size_t k = 0; k < overlaps.size(); ++k) text += (k ? "; " : "") + overlaps[k];
        if (overlapCount > kListed) text += concat("; and ", overlapCount - kListed, " more");
        throw Error(ErrorCode::argument, text);
    }

    // Holes: the grid of all region edges splits the image into cells that
    // are either wholly covered by one region or not at all.
    const MapInfo& info = maps.front()->info();
    std::vector<std::uint32_t> xs{0, info.width}, ys{0, info.height};
    for (const Rect& r : regions) {
        xs.insert(xs.end(), {r[0], r[2]});
        ys.insert(ys.end(), {r[1], r[3]});
    }
    for (auto* edges : {&xs, &ys}) {
        std::sort(edges->begin(), edges->end());
        edges->erase(std::unique(edges->begin(), edges->end()), edges->end());
    }
    std::uint64_t uncovered = 0;
    std::size_t holes = 0;
    std::vector<std::string> listed;
    for (std::size_t j = 0; j + 1 < ys.size(); ++j)
        for (std::size_t i = 0; i + 1 < xs.size(); ++i) {
            const Rect cell{xs[i], ys[j], xs[i + 1], ys[j + 1]};
            const bool covered = std::any_of(regions.begin(), regions.end(), [&](const Rect& r) { return intersects(r, cell); });
            if (covered) continue;
            uncovered += std::uint64_t(cell[2] - cell[0]) * (cell[3] - cell[1]);
            if (++holes <= kListed) listed.push_back(rectText(cell));
        }
    if (uncovered > 0) {
        std::string text = concat("the regions leave ", uncovered, " of ", std::uint64_t(info.width) * info.height,
                                  " pixels uncovered, in ", holes, " rectangle", holes == 1 ? "" : "s", " (x0,y0,x1,y1): ");
        for (std::size_t k = 0; k < listed.size(); ++k) text += (k ? "; " : "") + listed[k];
        if (holes > kListed) text += concat("; and ", holes - kListed, " more");
        throw Error(ErrorCode::argument, text);
    }
}

// The zlib level the inputs' tiles were written with, as their headers record
// it (format 1.1); the default for 1.0 inputs, which record none.
int recordedZlibLevel(const std::vector<Map>& maps) {
    const int level = maps.front()->info().codecLevel;
    return level >= 0 ? level : kDefaultZlibLevel;
}

MergeReport stitchMaps(const std::vector<Map>& maps, const std::string& output, const MergeOptions& options) {
    const DeepShadowMap& first = *maps.front();
    const MapInfo& info = first.info();
    std::vector<Json> metadata;
    std::vector<Rect> regions;
    for (const Map& map : maps) {
        metadata.push_back(parseMetadata(*map));
        regions.push_back(regionOf(*map, metadata.back()));
    }
    for (std::size_t i = 1; i < maps.size(); ++i)
        requireSameStitchSettings(*maps[i], first, metadata[i], metadata.front());
    requireTiling(maps, regions);

    MergeReport report;
    report.width = info.width;
    report.height = info.height;
    report.channels = info.channels;
    report.maxLayers = info.maxLayers;
    report.tolerance = info.levels.at(0).tolerance;
    report.zlibLevel = options.zlibLevel ? *options.zlibLevel : recordedZlibLevel(maps);
    report.inputErrorBound = info.levels.at(0).errorBound;
    report.errorBound = report.inputErrorBound;

    WriterOptions w;
    w.width = info.width;
    w.height = info.height;
    w.tileSize = info.tileSize;
    w.channels = info.channels;
    w.counts = info.hasCounts;
    w.maxLayers = info.maxLayers;
    w.camera = info.camera;
    w.filter = info.filter;
    w.filterWidth = info.filterWidth;
    w.tolerance = info.levels.at(0).tolerance;
    w.mipLevels = static_cast<unsigned>(info.levels.size());
    if (info.levels.size() > 1 && info.levels[0].tolerance > 0.0)
        w.levelToleranceFactor = info.levels[1].tolerance / info.levels[0].tolerance;
    w.zlibLevel = report.zlibLevel;
    if (info.codec == TileCodec::Zstd) {  // the inputs' compressor and level, as recorded
        w.codec = TileCodec::Zstd;
        w.zstdLevel = std::max(info.codecLevel, 0);
        w.zlibLevel = options.zlibLevel.value_or(kDefaultZlibLevel);
    }
    // The inputs' values are multiples of their levels' steps already: the
    // writer's rounding leaves them as they are.
    w.quantiseValues = info.levels.at(0).valueStep > 0.0;
    w.areaLightRadius = info.areaLightRadius;
    w.areaLightPlaneDepth = info.areaLightPlaneDepth;
    w.centredCompression = centredCompressionOf(first, metadata.front());  // the parts' metadata are equal
    Json merged = metadata.front();
    merged["settings"]["region"] = Rect{0, 0, info.width, info.height};
    w.metadata = merged.dump();

    MapWriter writer(output, w);
    const std::uint32_t T = info.tileSize;
    std::vector<VisibilityFunction> pixels;
    std::vector<std::size_t> parts;  // inputs whose region meets the current tile
    forEachTile(
        info, [&](std::size_t n) { pixels.assign(n, VisibilityFunction(info.channels, info.hasCounts)); },
        [&](std::uint32_t x, std::uint32_t y, std::size_t index) {
            if (index == 0) {
                const Rect tile{x, y, std::min(x + T, info.width), std::min(y + T, info.height)};
                parts.clear();
                for (std::size_t i = 0; i < regions.size(); ++i)
                    if (intersects(regions[i], tile)) parts.push_back(i);
            }
            for (std::size_t i : parts) {
                const Rect& r = regions[i];
                if (x >= r[0] && x < r[2] && y >= r[1] && y < r[3]) {
                    pixels[index] = maps[i]->pixel(0, x, y).view().toFunction();
                    report.vertices += pixels[index].size();
                    return;
                }
            }
        },
        [&](std::uint32_t tx, std::uint32_t ty) { writer.writeTile(tx, ty, pixels); });
    writer.finish();
    report.fileBytes = fileSize(output);
    return report;
}

}  // namespace

// An error about one input or the output leaves carrying that file.
MergeReport mergeMaps(const std::vector<std::string>& inputs, const std::string& output,
                      const MergeOptions& options) try {
    checkOutput(inputs, output);
    if (options.zlibLevel && (*options.zlibLevel < 0 || *options.zlibLevel > 9))
        throw Error(ErrorCode::argument, concat("merge: zlib level ", *options.zlibLevel, " is not in [0, 9]"));
    const std::vector<Map> maps = openAll(inputs);
    switch (options.mode) {
        case MergeMode::Product: return multiplyMaps(maps, output, options);
        case MergeMode::Stitch: return stitchMaps(maps, output, options);
    }
    throw Error(ErrorCode::argument, "merge: unknown mode");
} catch (const Error& e) {
    std::vector<std::string> files = inputs;
    files.push_back(output);
    throw detail::withOneOf(e, files);
}

DSM_NAMESPACE_END
