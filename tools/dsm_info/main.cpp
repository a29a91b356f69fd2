// dsm-info: describes deep shadow map files (size, tiling, light camera, mip
// levels, metadata), as text or JSON; lists tiles, one pixel's function and
// the statistics of vertices per pixel; verifies files; writes pictures of a
// level (visibility slice, opacity, vertices per pixel).
// Documentation, including the JSON schema: docs/dsm-info.md.
//
// Uses only libdsm's public API; the logic lives there (map_json.h,
// map_images.h, image_io.h). This file parses arguments and prints.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "dsm/error.h"
#include "colour_ramp.h"
#include "image_io.h"
#include "dsm/map_images.h"
#include "dsm/map_info.h"
#include "map_json.h"
#include "dsm/output_file.h"
#include "dsm/reader.h"
#include "option_checks.h"
#include "tool_support.h"

namespace {

namespace tools = dsm::tools;

constexpr const char* kToolName = "dsm-info";

using Json = nlohmann::ordered_json;

struct PixelCoordinates {
    std::uint32_t x = 0;
    std::uint32_t y = 0;
};

/// Which picture to write with -o.
enum class Picture { None, Slice, Opacity, VertexHeatmap };

struct Options {
    std::vector<std::string> files;
    bool json = false;
    bool verify = false;
    bool tiles = false;
    bool stats = false;
    std::optional<PixelCoordinates> pixel;
    std::optional<unsigned> level;
    Picture picture = Picture::None;
    double sliceDepth = 0.0;
    std::string output;
};

/// Runs `action`; any exception becomes one error line (tools::reportException):
/// about the file a dsm::Error names, else about `file`. The action adds the
/// temporary copy of standard input to `displayNames`, so that it is printed
/// as "<stdin>". Returns false when it failed.
template <class Action>
bool guarded(const std::string& file, Action&& action, const tools::DisplayNames& displayNames = {}) {
    try {
        action();
        return true;
    } catch (const std::exception& e) {
        tools::reportException(kToolName, e, file, displayNames);
    } catch (...) {
        tools::reportError(kToolName, file, "unknown error");
    }
    return false;
}

// ---------------------------------------------------------------------------
// Argument values

/// "X,Y" with two non-negative decimal integers.
std::optional<PixelCoordinates> parsePixel(std::string_view text) {
    const auto comma = text.find(',');
    if (comma == std::string_view::npos) return std::nullopt;
    auto parse = [](std::string_view part, std::uint32_t& value) {
        const auto [end, error] = std::from_chars(part.data(), part.data() + part.size(), value);
        return !part.empty() && error == std::errc() && end == part.data() + part.size();
    };
    PixelCoordinates p;
    if (!parse(text.substr(0, comma), p.x) || !parse(text.substr(comma + 1), p.y)) return std::nullopt;
    return p;
}

/// A depth: a decimal number, infinity allowed, NaN not.
std::optional<double> parseDepth(const std::string& text) {
    try {
        std::size_t used = 0;
        const double z = std::stod(text, &used);
        if (used != text.size() || std::isnan(z)) return std::nullopt;
        return z;
    } catch (const std::exception&) {
        return std::nullopt;
    }
}

// ---------------------------------------------------------------------------
// Numbers as text

std::string channelsText(int channels) {
    if (channels == 1) return "1 (mono)";
    if (channels == 3) return "3 (RGB)";
    return std::to_string(channels);
}

/// A double in %g style with `digits` significant digits.
std::string num(double v, int digits = 6) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*g", digits, v);
    return buf;
}

std::string fixed(double v, int decimals) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
    return buf;
}

std::string hex32(std::uint32_t v) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "%08x", static_cast<unsigned>(v));
    return buf;
}

/// "123456 bytes (120.6 KiB)".
std::string bytesText(std::uint64_t bytes) {
    std::string s = std::to_string(bytes) + (bytes == 1 ? " byte" : " bytes");
    if (bytes >= 1024) {
        static const char* const units[] = {"KiB", "MiB", "GiB", "TiB", "PiB"};
        double v = static_cast<double>(bytes) / 1024.0;
        int u = 0;
        while (v >= 1024.0 && u < 4) {
            v /= 1024.0;
            ++u;
        }
        s += " (" + fixed(v, 1) + " " + units[u] + ")";
    }
    return s;
}

/// "3 vertices", "1 layer".
std::string plural(std::uint64_t n, const std::string& one, const std::string& many) {
    return std::to_string(n) + " " + (n == 1 ? one : many);
}

// ---------------------------------------------------------------------------
// Metadata


/// The metadata as JSON, or nothing when it is not JSON (or nested too deep
/// to print safely): it is then shown as text.
std::optional<Json> parseMetadata(const std::string& text) {
    if (dsm::jsonNestingDepth(text) > dsm::kMaxMetadataDepth) return std::nullopt;
    Json parsed = Json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (parsed.is_discarded()) return std::nullopt;
    return parsed;
}

// ---------------------------------------------------------------------------
// Human-readable output

/// A table of right-aligned columns under a header row.
class Table {
public:
    explicit Table(std::vector<std::string> header) : rows_{std::move(header)} {}
    void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
    void print(std::ostream& out, const std::string& indent) const {
        std::vector<std::size_t> widths;
        for (const auto& row : rows_)
            for (std::size_t c = 0; c < row.size(); ++c) {
                if (widths.size() <= c) widths.push_back(0);
                widths[c] = std::max(widths[c], row[c].size());
            }
        for (const auto& row : rows_) {
            std::string line = indent;
            for (std::size_t c = 0; c < row.size(); ++c)
                line += (c ? "  " : "") + std::string(widths[c] - row[c].size(), ' ') + row[c];
            while (!line.empty() && line.back() == ' ') line.pop_back();
            out << line << '\n';
        }
    }

private:
    std::vector<std::vector<std::string>> rows_;
};

constexpr int kLabelWidth = 20;

/// "  label     value": values start in column kLabelWidth.
void field(std::ostream& out, const std::string& label, const std::string& value, int indent = 2) {
    out << std::string(static_cast<std::size_t>(indent), ' ') << label;
    if (!value.empty()) {
        const int pad = std::max(1, kLabelWidth - indent - static_cast<int>(label.size()));
        out << std::string(static_cast<std::size_t>(pad), ' ') << value;
    }
    out << '\n';
}

/// Lines of `text` with `indent` put in front of each.
void indented(std::ostream& out, const std::string& text, const std::string& indent) {
    std::istringstream lines(text);
    std::string line;
    while (std::getline(lines, line)) out << indent << line << '\n';
}

void printCamera(std::ostream& out, const dsm::LightCamera& cam) {
    field(out, "light camera", dsm::projectionName(cam.projection));
    const auto& w = cam.screenWindow;
    field(out, "screen window", "[" + num(w[0]) + ", " + num(w[1]) + "] x [" + num(w[2]) + ", " + num(w[3]) + "]", 4);
    field(out, "near plane", num(cam.nearPlane), 4);
    std::vector<std::string> m;
    std::size_t width = 0;
    for (double v : cam.worldToLight) {
        m.push_back(num(v));
        width = std::max(width, m.back().size());
    }
    for (int r = 0; r < 4; ++r) {
        std::string row = "[";
        for (int c = 0; c < 4; ++c) {
            const std::string& e = m[static_cast<std::size_t>(4 * r + c)];
            row += " " + std::string(width - e.size(), ' ') + e;
        }
        row += " ]";
        if (r == 0) field(out, "world to light", row, 4);
        else out << std::string(kLabelWidth, ' ') << row << '\n';
    }
}

void printLevels(std::ostream& out, const dsm::MapInfo& info) {
    field(out, "levels", std::to_string(info.levels.size()));
    Table table({"level", "size", "tiles", "tolerance", "value step", "error bound", "vertices", "non-empty",
                 "vertices/pixel", "stored bytes"});
    for (std::size_t l = 0; l < info.levels.size(); ++l) {
        const dsm::LevelInfo& L = info.levels[l];
        const std::string perPixel =
            L.nonEmptyPixels ? fixed(static_cast<double>(L.vertexCount) / static_cast<double>(L.nonEmptyPixels), 2)
                             : "-";
        table.add({std::to_string(l), std::to_string(L.width) + " x " + std::to_string(L.height),
                   std::to_string(L.tilesX) + " x " + std::to_string(L.tilesY), num(L.tolerance),
                   L.valueStep > 0.0 ? num(L.valueStep) : "exact", num(L.errorBound),
                   std::to_string(L.vertexCount), std::to_string(L.nonEmptyPixels), perPixel,
                   std::to_string(L.storedBytes)});
    }
    table.print(out, "    ");
}

/// Sum of all levels' stored bytes over level 0's:
/// "1.63 x level 0 (13523 bytes in 2 levels)".
std::string pyramidText(const dsm::MapInfo& info) {
    if (info.levels.empty()) return "-";
    std::uint64_t total = 0;
    for (const auto& L : info.levels) total += L.storedBytes;
    const std::uint64_t base = info.levels[0].storedBytes;
    const std::string all = std::to_string(total) + " bytes in " + plural(info.levels.size(), "level", "levels");
    if (base == 0) return "- (level 0 stores nothing; " + all + ")";
    return fixed(static_cast<double>(total) / static_cast<double>(base), 2) + " x level 0 (" + all + ")";
}

void printMetadata(std::ostream& out, const std::string& metadata) {
    if (metadata.empty()) {
        field(out, "metadata", "(none)");
        return;
    }
    const std::optional<Json> parsed = parseMetadata(metadata);
    if (!parsed) {
        field(out, "metadata",
              dsm::jsonNestingDepth(metadata) > dsm::kMaxMetadataDepth ? "(nested too deep to format)" : "(not JSON)");
        indented(out, metadata, "    ");
    } else if (!parsed->is_structured() || parsed->empty()) {
        field(out, "metadata", parsed->dump(-1, ' ', false, Json::error_handler_t::replace));
    } else {
        field(out, "metadata", "");
        indented(out, parsed->dump(2, ' ', false, Json::error_handler_t::replace), "    ");
    }
}

/// "coded (1.1), zlib level 6" or "arrays (1.0), zlib, level not recorded".
std::string codingText(const dsm::MapInfo& info) {
    const std::string codec = info.codec == dsm::TileCodec::Zstd ? "zstd" : "zlib";
    return std::string(info.codedTiles ? "coded (1.1)" : "arrays (1.0)") + ", " + codec +
           (info.codecLevel >= 0 ? " level " + std::to_string(info.codecLevel) : ", level not recorded");
}

void printSummary(std::ostream& out, const dsm::MapInfo& info) {
    field(out, "format version", std::to_string(info.versionMajor) + "." + std::to_string(info.versionMinor));
    field(out, "tile coding", codingText(info));
    const std::vector<std::string> flags = dsm::requiredFlagNames(info);
    std::string flagText;
    for (const std::string& flag : flags) flagText += (flagText.empty() ? "" : ", ") + flag;
    field(out, "required flags", flags.empty() ? "none" : flagText);
    field(out, "size", std::to_string(info.width) + " x " + std::to_string(info.height));
    field(out, "tile size", std::to_string(info.tileSize));
    field(out, "channels", channelsText(info.channels));
    field(out, "sample counts", info.hasCounts ? "yes" : "no");
    field(out, "MTSM layers", std::to_string(info.maxLayers));
    printCamera(out, info.camera);
    field(out, "area light", info.areaLightRadius > 0.0 ? "disk of radius " + num(info.areaLightRadius) +
                                                              " in the plane z = " + num(info.areaLightPlaneDepth)
                                                        : "none recorded (a point light)");
    field(out, "build filter", std::string(dsm::filterName(info.filter)) + ", width " + num(info.filterWidth));
    printLevels(out, info);
    field(out, "file size", bytesText(info.fileBytes));
    field(out, "mip pyramid", pyramidText(info));
    printMetadata(out, info.metadata);
}

// ---------------------------------------------------------------------------
// Tiles, one pixel, statistics: gathered once, printed as text or JSON

/// The levels an option applies to: the one given with --level, or all.
std::vector<unsigned> selectedLevels(const dsm::DeepShadowMap& map, const std::optional<unsigned>& level) {
    const auto count = static_cast<unsigned>(map.info().levels.size());
    if (level) {
        if (*level >= count)
            throw dsm::Error(dsm::ErrorCode::argument, "level " + std::to_string(*level) + " does not exist (" +
                                                           plural(count, "level", "levels") + ")");
        return {*level};
    }
    std::vector<unsigned> all(count);
    for (unsigned l = 0; l < count; ++l) all[l] = l;
    return all;
}

using dsm::TileRow;

std::vector<TileRow> gatherTiles(const dsm::DeepShadowMap& map, const std::optional<unsigned>& level) {
    std::vector<TileRow> rows;
    for (const unsigned l : selectedLevels(map, level)) {
        std::vector<TileRow> tiles = dsm::levelTiles(map, l);
        rows.insert(rows.end(), tiles.begin(), tiles.end());
    }
    return rows;
}

void printTiles(std::ostream& out, const std::vector<TileRow>& rows) {
    field(out, "tiles", std::to_string(rows.size()));
    Table table({"level", "tx", "ty", "x", "y", "stored bytes", "raw bytes", "vertices", "non-empty", "min z", "max z",
                 "crc-32"});
    for (const TileRow& t : rows) {
        const auto range = [](std::uint32_t from, std::uint32_t n) {
            return std::to_string(from) + "-" + std::to_string(from + n - 1);
        };
        const bool empty = t.summary.empty();
        table.add({std::to_string(t.level), std::to_string(t.tx), std::to_string(t.ty), range(t.x, t.width),
                   range(t.y, t.height), std::to_string(t.summary.storedBytes), std::to_string(t.summary.rawBytes),
                   std::to_string(t.summary.vertexCount), std::to_string(t.summary.nonEmptyPixels),
                   empty ? "-" : num(t.summary.minZ), empty ? "-" : num(t.summary.maxZ),
                   empty ? "-" : hex32(t.summary.crc32)});
    }
    table.print(out, "    ");
}

/// Checks the pixel against the level first, so the message names both.
dsm::PixelFunction readPixel(const dsm::DeepShadowMap& map, unsigned level, const PixelCoordinates& p) {
    const auto& levels = map.info().levels;
    if (level >= levels.size())
        throw dsm::Error(dsm::ErrorCode::argument, "level " + std::to_string(level) + " does not exist (" +
                                                       plural(levels.size(), "level", "levels") + ")");
    const dsm::LevelInfo& L = levels[level];
    if (p.x >= L.width || p.y >= L.height)
        throw dsm::Error(dsm::ErrorCode::argument, "pixel " + std::to_string(p.x) + "," + std::to_string(p.y) +
                                                       " is outside level " + std::to_string(level) + " (" +
                                                       std::to_string(L.width) + " x " + std::to_string(L.height) +
                                                       ")");
    return map.pixel(level, p.x, p.y);
}

void printPixel(std::ostream& out, unsigned level, const PixelCoordinates& p, const dsm::VisibilityView& f) {
    out << "  pixel " << p.x << "," << p.y << " of level " << level << ": ";
    if (f.empty()) {
        out << "no vertices (V = 1 at every depth)\n";
        return;
    }
    out << plural(f.size(), "vertex", "vertices") << " in " << plural(f.layerCount(), "layer", "layers") << ", "
        << plural(static_cast<std::uint64_t>(f.channels()), "channel", "channels") << '\n';
    std::vector<std::string> header{"vertex", "layer", "z"};
    if (f.channels() == 1) header.push_back("V");
    else header.insert(header.end(), {"R", "G", "B"});
    if (f.hasCounts()) header.push_back("count");
    Table table(header);
    const std::vector<std::size_t> layers = dsm::vertexLayers(f);
    for (std::size_t i = 0; i < f.size(); ++i) {
        // 7 digits: readable; --json gives the stored floats exactly.
        std::vector<std::string> row{std::to_string(i), std::to_string(layers[i]), num(f.z(i), 7)};
        for (int c = 0; c < f.channels(); ++c) row.push_back(num(f.value(i, c), 7));
        if (f.hasCounts()) row.push_back(std::to_string(f.count(i)));
        table.add(std::move(row));
    }
    table.print(out, "    ");
}

std::string bucketText(std::size_t k) {
    const std::uint64_t lo = dsm::VertexHistogram::bucketMin(k), hi = dsm::VertexHistogram::bucketMax(k);
    return lo == hi ? std::to_string(lo) : std::to_string(lo) + "-" + std::to_string(hi);
}

void printStats(std::ostream& out, const std::vector<dsm::VertexHistogram>& histograms) {
    constexpr std::size_t kBarWidth = 40;
    for (const dsm::VertexHistogram& h : histograms) {
        out << "  vertices per pixel of level " << h.level << ": " << plural(h.pixels, "pixel", "pixels") << ", "
            << h.nonEmptyPixels << " non-empty\n";
        out << "    min " << h.min << "  mean " << fixed(h.mean, 2) << "  median " << h.median << "  p99 " << h.p99
            << "  max " << h.max << '\n';
        const std::uint64_t tallest = h.buckets.empty() ? 0 : *std::max_element(h.buckets.begin(), h.buckets.end());
        Table table({"vertices", "pixels", ""});
        for (std::size_t k = 0; k < h.buckets.size(); ++k) {
            // Any pixel at all shows at least one mark.
            const std::size_t bar =
                h.buckets[k] == 0 ? 0
                                  : std::max<std::size_t>(1, static_cast<std::size_t>(
                                                                 (h.buckets[k] * kBarWidth + tallest / 2) / tallest));
            table.add({bucketText(k), std::to_string(h.buckets[k]), std::string(bar, '#') + std::string(kBarWidth - bar, ' ')});
        }
        table.print(out, "    ");
    }
}

Json statsJson(const std::vector<dsm::VertexHistogram>& histograms) {
    Json levels = Json::array();
    for (const dsm::VertexHistogram& h : histograms) {
        Json buckets = Json::array();
        for (std::size_t k = 0; k < h.buckets.size(); ++k)
            buckets.push_back({{"min", dsm::VertexHistogram::bucketMin(k)},
                               {"max", dsm::VertexHistogram::bucketMax(k)},
                               {"pixels", h.buckets[k]}});
        levels.push_back({{"level", h.level},
                          {"pixels", h.pixels},
                          {"non_empty_pixels", h.nonEmptyPixels},
                          {"vertices", h.vertices},
                          {"min", h.min},
                          {"mean", h.mean},
                          {"median", h.median},
                          {"p99", h.p99},
                          {"max", h.max},
                          {"histogram", std::move(buckets)}});
    }
    return levels;
}

// ---------------------------------------------------------------------------
// Commands

std::string dumpJson(const Json& j) { return j.dump(2, ' ', false, Json::error_handler_t::replace); }

/// Describes one map (and its tiles, pixel, statistics when asked) as text
/// into `text` or as JSON into `json`. Everything is gathered before anything
/// is printed, so a failure never leaves a file half described.
void describeOne(const Options& o, const std::string& name, const dsm::DeepShadowMap& map, std::ostream& text,
                 Json& json) {
    const dsm::MapInfo& info = map.info();
    std::optional<std::vector<TileRow>> tiles;
    if (o.tiles) tiles = gatherTiles(map, o.level);
    std::optional<dsm::PixelFunction> pixel;
    const unsigned pixelLevel = o.level.value_or(0);
    if (o.pixel) pixel = readPixel(map, pixelLevel, *o.pixel);
    std::optional<std::vector<dsm::VertexHistogram>> stats;
    if (o.stats) {
        stats.emplace();
        for (const unsigned l : selectedLevels(map, o.level)) stats->push_back(dsm::vertexHistogram(map, l));
    }

    if (o.json) {
        json = Json::parse(dsm::mapInfoJson(info, name, -1));
        if (tiles) json["tiles"] = Json::parse(dsm::tilesJson(*tiles));
        if (pixel) json["pixel"] = Json::parse(dsm::pixelFunctionJson(pixel->view(), pixelLevel, o.pixel->x, o.pixel->y));
        if (stats) json["stats"] = statsJson(*stats);
        return;
    }
    text << name << ":\n";
    printSummary(text, info);
    if (tiles) printTiles(text, *tiles);
    if (pixel) printPixel(text, pixelLevel, *o.pixel, pixel->view());
    if (stats) printStats(text, *stats);
}

int describe(const Options& o) {
    bool allOk = true;
    Json results = Json::array();
    bool first = true;
    for (const std::string& argument : o.files) {
        std::string name = argument == "-" ? "<stdin>" : argument;
        tools::DisplayNames displayNames;
        allOk &= guarded(
            name,
            [&] {
                const tools::InputFile input(argument);
                tools::addDisplayName(displayNames, input);
                std::ostringstream text;
                Json json;
                const auto map = dsm::DeepShadowMap::open(input.path());
                describeOne(o, input.name(), *map, text, json);
                if (o.json) {
                    results.push_back(std::move(json));
                } else {
                    if (!first) std::cout << '\n';
                    std::cout << text.str();
                    first = false;
                }
            },
            displayNames);
    }
    if (o.json) {
        if (o.files.size() > 1) std::cout << dumpJson(results) << '\n';
        else if (!results.empty()) std::cout << dumpJson(results[0]) << '\n';
    }
    return allOk ? tools::kExitOk : tools::kExitFailure;
}

int verify(const Options& o) {
    bool allOk = true;
    for (const std::string& argument : o.files) {
        const std::string name = argument == "-" ? "<stdin>" : argument;
        tools::DisplayNames displayNames;
        allOk &= guarded(
            name,
            [&] {
                const tools::InputFile input(argument);
                tools::addDisplayName(displayNames, input);
                dsm::validate(input.path());
                std::cout << input.name() << ": OK\n";
            },
            displayNames);
        if (argument != "-")
            for (const std::string& stale : dsm::staleTemporaries(argument))
                std::cout << name << ": note: '" << stale
                          << "' is a temporary file left by an interrupted write over a day ago; it may be deleted\n";
    }
    return allOk ? tools::kExitOk : tools::kExitFailure;
}

/// Writes the picture asked for of the one file given.
int writePicture(const Options& o) {
    const std::string& argument = o.files.front();
    const std::string name = argument == "-" ? "<stdin>" : argument;
    bool keepsFloats = false;
    const bool writable = guarded(o.output, [&] {
        tools::checkOutputs({o.output}, {argument});  // before the picture is computed
        keepsFloats = dsm::imageFormatKeepsFloats(o.output);
    });
    if (!writable) return tools::kExitFailure;

    const unsigned level = o.level.value_or(0);
    dsm::FloatImage image;
    std::string note;
    tools::DisplayNames displayNames;
    const bool computed = guarded(
        name,
        [&] {
            const tools::InputFile input(argument);
            tools::addDisplayName(displayNames, input);
            const auto map = dsm::DeepShadowMap::open(input.path());
            selectedLevels(*map, level);  // names the level when it does not exist
            switch (o.picture) {
                case Picture::Slice: image = dsm::visibilitySlice(*map, level, o.sliceDepth); break;
                case Picture::Opacity: image = dsm::opacityImage(*map, level); break;
                case Picture::VertexHeatmap: {
                    image = dsm::vertexCountImage(*map, level);
                    const float most = *std::max_element(image.values.begin(), image.values.end());
                    if (keepsFloats) {
                        note = ", vertex counts up to " + num(most);
                    } else {
                        image = dsm::colourRamp(image, most);
                        note = ", colour ramp from 0 (black) to " + num(most) + " vertices (white)";
                    }
                    break;
                }
                case Picture::None: break;
            }
        },
        displayNames);
    if (!computed) return tools::kExitFailure;
    // A monochrome opacity is an alpha: named A, as a flattened deep image names it.
    const std::vector<std::string> names =
        o.picture == Picture::Opacity && image.channels == 1 ? std::vector<std::string>{"A"} : std::vector<std::string>{};
    if (!guarded(o.output, [&] { dsm::writeImage(o.output, image, names); })) return tools::kExitFailure;
    std::cout << o.output << ": level " << level << " of " << name << ", " << image.width << " x " << image.height
              << ", " << plural(static_cast<std::uint64_t>(image.channels), "channel", "channels") << ", "
              << (keepsFloats ? "32-bit float" : "8-bit") << note << '\n';
    return tools::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    CLI::App app{"Describe deep shadow map (.dsm) files: size, tiling, channels, light camera, mip levels and "
                 "metadata; list tiles, one pixel's function and vertex statistics; verify files; write pictures "
                 "of a level.",
                 kToolName};
    app.add_option("FILE", o.files, "Deep shadow map (.dsm) files; - reads one from standard input")
        ->required()
        ->type_name("");
    auto* json = app.add_flag("--json", o.json, "Print one JSON object per file (an array for several files)");
    auto* tiles = app.add_flag("--tiles", o.tiles, "Also list every tile: pixels, bytes, vertices, depths, CRC-32");
    std::string pixelText;
    auto* pixel = app.add_option("--pixel", pixelText, "Also print the function of pixel X,Y (of --level, default 0)")
                      ->type_name("X,Y")
                      ->check([](const std::string& s) {
                          return parsePixel(s) ? std::string() : "expected X,Y (two non-negative integers)";
                      });
    auto* stats = app.add_flag("--stats", o.stats,
                               "Also print the distribution of vertices per pixel of each level (or of --level)");
    unsigned levelValue = 0;
    auto* level = app.add_option("--level", levelValue,
                                 "Mip level for --pixel and the pictures (default 0); limits --tiles and --stats "
                                 "to that level")
                      ->type_name("L")
                      ->check(tools::integerIn(0, UINT32_MAX));
    auto* verifyFlag = app.add_flag("--verify", o.verify,
                                    "Check every tile of every file (CRC-32, layout, function invariants) and print "
                                    "'FILE: OK' or the error instead of describing the files");
    std::string sliceText;
    auto* slice = app.add_option("--slice", sliceText, "Picture: visibility V(Z) at light depth Z, per channel")
                      ->type_name("Z")
                      ->check([](const std::string& s) {
                          return parseDepth(s) ? std::string() : "expected a depth (a number, not NaN)";
                      });
    bool opacityFlag = false, heatmapFlag = false;
    auto* opacity = app.add_flag("--opacity", opacityFlag, "Picture: opacity 1 - V(infinity), per channel");
    auto* heatmap = app.add_flag("--vertex-heatmap", heatmapFlag,
                                 "Picture: vertices per pixel (float counts in EXR/TIFF, a colour ramp up to the "
                                 "maximum in 8-bit formats)");
    auto* output = app.add_option("-o,--output", o.output, "Picture file to write; PNG, EXR, ... by its extension")
                       ->type_name("F");

    const std::vector<CLI::Option*> pictures{slice, opacity, heatmap};
    for (CLI::Option* picture : pictures) {
        picture->needs(output);
        for (CLI::Option* other : {json, tiles, pixel, stats, verifyFlag}) picture->excludes(other);
        for (CLI::Option* other : pictures)
            if (other != picture) picture->excludes(other);
    }
    for (CLI::Option* other : {json, tiles, pixel, stats, level}) verifyFlag->excludes(other);
    app.callback([&] {
        if (output->count() && !slice->count() && !opacity->count() && !heatmap->count())
            throw CLI::ValidationError("-o", "needs --slice, --opacity or --vertex-heatmap");
        if (level->count() && !pixel->count() && !tiles->count() && !stats->count() && !slice->count() &&
            !opacity->count() && !heatmap->count())
            throw CLI::ValidationError("--level", "needs --pixel, --tiles, --stats or a picture option");
        if (output->count() && o.files.size() != 1)
            throw CLI::ValidationError("-o", "a picture is made of exactly one FILE");
    });
    tools::configureApp(app, kToolName, "docs/dsm-info.md");
    app.footer("Exit status: 0 when every file was read (and verified, or the picture written), 1 when any file "
               "failed, 2 on a usage error.\nDocumentation: docs/dsm-info.md");

    if (const int status = tools::parseArguments(app, argc, argv); status >= 0) return status;
    if (pixel->count()) o.pixel = parsePixel(pixelText);
    if (level->count()) o.level = levelValue;
    if (slice->count()) {
        o.picture = Picture::Slice;
        o.sliceDepth = *parseDepth(sliceText);
    } else if (opacityFlag) {
        o.picture = Picture::Opacity;
    } else if (heatmapFlag) {
        o.picture = Picture::VertexHeatmap;
    }

    int status = tools::kExitFailure;
    try {
        if (o.verify) status = verify(o);
        else if (o.picture != Picture::None) status = writePicture(o);
        else status = describe(o);
    } catch (const std::exception& e) {
        std::cerr << tools::errorLine(kToolName, "", tools::exceptionMessage(e)) << '\n';
        return tools::kExitFailure;
    }
    std::cout.flush();
    if (!std::cout) {
        std::cerr << kToolName << ": ERROR: cannot write to standard output\n";
        return tools::kExitFailure;
    }
    return status;
}
