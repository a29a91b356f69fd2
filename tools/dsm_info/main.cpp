// dsm-info: describes deep shadow map files (size, tiling, light camera, mip
// levels, metadata), as text or JSON, and optionally verifies them.
// Documentation, including the JSON schema: docs/dsm-info.md.
//
// Uses only libdsm's public API.
#include <algorithm>
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
#include "dsm/map_info.h"
#include "dsm/reader.h"

#ifndef DSM_TOOLS_VERSION
#define DSM_TOOLS_VERSION "unknown"
#endif

namespace {

constexpr const char* kToolName = "dsm-info";
/// Version of the --json output schema (docs/dsm-info.md). Bump the minor
/// version when fields are added, the major one when fields change meaning.
constexpr const char* kJsonSchemaVersion = "1.0";

/// Exit codes (docs/dsm-info.md).
constexpr int kExitOk = 0;
constexpr int kExitFileError = 1;
constexpr int kExitUsage = 2;

using Json = nlohmann::ordered_json;

/// Metadata nested deeper than this is shown as text: printing JSON recurses
/// (and indents) once per level, and a file may hold 16 MiB of "[[[[...".
constexpr std::size_t kMaxMetadataDepth = 100;

struct Options {
    std::vector<std::string> files;
    bool json = false;
    bool verify = false;
};

// ---------------------------------------------------------------------------
// Errors

/// Makes a message safe to print as one line.
std::string oneLine(std::string s) {
    for (char& c : s)
        if (c == '\n' || c == '\r') c = ' ';
    return s;
}

/// `dsm-info: ERROR '<file>': <message>`. libdsm's messages already start with
/// the quoted file name ("'a.dsm': ..." or "'a.dsm' level 1 tile 0,2: ..."):
/// that prefix is replaced rather than repeated.
std::string errorLine(const std::string& file, const std::string& message) {
    const std::string quoted = "'" + file + "'";
    std::string_view rest = message;
    if (rest.substr(0, quoted.size()) == quoted) {
        rest.remove_prefix(quoted.size());
        if (rest.substr(0, 2) == ": ") rest.remove_prefix(2);
        else if (rest.substr(0, 1) == " ") rest.remove_prefix(1);
    }
    return oneLine(std::string(kToolName) + ": ERROR " + quoted + ": " + std::string(rest));
}

void reportError(const std::string& file, const std::string& message) {
    std::cout.flush();  // keep stdout and stderr in order on a terminal
    std::cerr << errorLine(file, message) << '\n';
}

/// Runs `action` for one file; any exception becomes one error line.
/// Returns false when it failed.
template <class Action>
bool guarded(const std::string& file, Action&& action) {
    try {
        action();
        return true;
    } catch (const dsm::Error& e) {
        reportError(file, e.what());
    } catch (const std::exception& e) {
        reportError(file, e.what());
    } catch (...) {
        reportError(file, "unknown error");
    }
    return false;
}

// ---------------------------------------------------------------------------
// Names and numbers

std::string projectionName(dsm::Projection p) {
    switch (p) {
        case dsm::Projection::Perspective: return "perspective";
        case dsm::Projection::Orthographic: return "orthographic";
    }
    return "unknown (" + std::to_string(static_cast<int>(p)) + ")";
}

std::string filterName(dsm::PixelFilter f) {
    switch (f) {
        case dsm::PixelFilter::Box: return "box";
        case dsm::PixelFilter::Triangle: return "triangle";
        case dsm::PixelFilter::Gaussian: return "gaussian";
    }
    return "unknown (" + std::to_string(static_cast<int>(f)) + ")";
}

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

// ---------------------------------------------------------------------------
// Metadata

/// Deepest nesting of arrays and objects in JSON text (strings skipped).
std::size_t jsonDepth(std::string_view text) {
    std::size_t depth = 0, deepest = 0;
    bool inString = false, escaped = false;
    for (const char c : text) {
        if (inString) {
            if (escaped) escaped = false;
            else if (c == '\\') escaped = true;
            else if (c == '"') inString = false;
        } else if (c == '"') {
            inString = true;
        } else if (c == '[' || c == '{') {
            deepest = std::max(deepest, ++depth);
        } else if ((c == ']' || c == '}') && depth > 0) {
            --depth;
        }
    }
    return deepest;
}

/// The metadata as JSON, or nothing when it is not JSON (or nested too deep
/// to print safely): it is then shown as text.
std::optional<Json> parseMetadata(const std::string& text) {
    if (jsonDepth(text) > kMaxMetadataDepth) return std::nullopt;
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
            out << indent;
            for (std::size_t c = 0; c < row.size(); ++c)
                out << (c ? "  " : "") << std::string(widths[c] - row[c].size(), ' ') << row[c];
            out << '\n';
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
    field(out, "light camera", projectionName(cam.projection));
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
    Table table({"level", "size", "tiles", "tolerance", "error bound", "vertices", "non-empty", "vertices/pixel",
                 "stored bytes"});
    for (std::size_t l = 0; l < info.levels.size(); ++l) {
        const dsm::LevelInfo& L = info.levels[l];
        const std::string perPixel =
            L.nonEmptyPixels ? fixed(static_cast<double>(L.vertexCount) / static_cast<double>(L.nonEmptyPixels), 2)
                             : "-";
        table.add({std::to_string(l), std::to_string(L.width) + " x " + std::to_string(L.height),
                   std::to_string(L.tilesX) + " x " + std::to_string(L.tilesY), num(L.tolerance), num(L.errorBound),
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
    const std::string all = std::to_string(total) + " bytes in " + std::to_string(info.levels.size()) +
                            (info.levels.size() == 1 ? " level" : " levels");
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
        field(out, "metadata", jsonDepth(metadata) > kMaxMetadataDepth ? "(nested too deep to format)" : "(not JSON)");
        indented(out, metadata, "    ");
    } else if (!parsed->is_structured() || parsed->empty()) {
        field(out, "metadata", parsed->dump(-1, ' ', false, Json::error_handler_t::replace));
    } else {
        field(out, "metadata", "");
        indented(out, parsed->dump(2, ' ', false, Json::error_handler_t::replace), "    ");
    }
}

void printHuman(std::ostream& out, const std::string& file, const dsm::MapInfo& info) {
    out << file << ":\n";
    field(out, "format version", std::to_string(info.versionMajor) + "." + std::to_string(info.versionMinor));
    field(out, "size", std::to_string(info.width) + " x " + std::to_string(info.height));
    field(out, "tile size", std::to_string(info.tileSize));
    field(out, "channels", channelsText(info.channels));
    field(out, "sample counts", info.hasCounts ? "yes" : "no");
    field(out, "MTSM layers", std::to_string(info.maxLayers));
    printCamera(out, info.camera);
    field(out, "build filter", filterName(info.filter) + ", width " + num(info.filterWidth));
    printLevels(out, info);
    field(out, "file size", bytesText(info.fileBytes));
    field(out, "mip pyramid", pyramidText(info));
    printMetadata(out, info.metadata);
}

// ---------------------------------------------------------------------------
// JSON output (schema: docs/dsm-info.md)

Json toJson(const std::string& file, const dsm::MapInfo& info) {
    Json j;
    j["schema_version"] = kJsonSchemaVersion;
    j["file"] = file;
    j["file_bytes"] = info.fileBytes;
    j["format_version"] = std::to_string(info.versionMajor) + "." + std::to_string(info.versionMinor);
    j["width"] = info.width;
    j["height"] = info.height;
    j["tile_size"] = info.tileSize;
    j["channels"] = info.channels;
    j["has_counts"] = info.hasCounts;
    j["max_layers"] = info.maxLayers;
    j["camera"] = {{"projection", projectionName(info.camera.projection)},
                   {"world_to_light", info.camera.worldToLight},
                   {"screen_window", info.camera.screenWindow},
                   {"near_plane", info.camera.nearPlane}};
    j["filter"] = {{"type", filterName(info.filter)}, {"width", info.filterWidth}};
    Json levels = Json::array();
    for (std::size_t l = 0; l < info.levels.size(); ++l) {
        const dsm::LevelInfo& L = info.levels[l];
        levels.push_back({{"level", l},
                          {"width", L.width},
                          {"height", L.height},
                          {"tiles_x", L.tilesX},
                          {"tiles_y", L.tilesY},
                          {"tolerance", L.tolerance},
                          {"error_bound", L.errorBound},
                          {"vertices", L.vertexCount},
                          {"non_empty_pixels", L.nonEmptyPixels},
                          {"stored_bytes", L.storedBytes}});
    }
    j["levels"] = std::move(levels);
    std::optional<Json> metadata = parseMetadata(info.metadata);
    j["metadata"] = metadata ? std::move(*metadata) : Json(info.metadata);
    return j;
}

std::string dumpJson(const Json& j) { return j.dump(2, ' ', false, Json::error_handler_t::replace); }

// ---------------------------------------------------------------------------
// Commands

int describe(const Options& o) {
    bool allOk = true;
    Json results = Json::array();
    bool first = true;
    for (const std::string& file : o.files) {
        allOk &= guarded(file, [&] {
            const auto map = dsm::DeepShadowMap::open(file);
            if (o.json) {
                results.push_back(toJson(file, map->info()));
            } else {
                std::ostringstream text;  // printed whole: no half-described file
                printHuman(text, file, map->info());
                if (!first) std::cout << '\n';
                std::cout << text.str();
                first = false;
            }
        });
    }
    if (o.json) {
        if (o.files.size() > 1) std::cout << dumpJson(results) << '\n';
        else if (!results.empty()) std::cout << dumpJson(results[0]) << '\n';
    }
    return allOk ? kExitOk : kExitFileError;
}

int verify(const Options& o) {
    bool allOk = true;
    for (const std::string& file : o.files) {
        allOk &= guarded(file, [&] {
            dsm::validate(file);
            std::cout << file << ": OK\n";
        });
    }
    return allOk ? kExitOk : kExitFileError;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    CLI::App app{"Describe deep shadow map (.dsm) files: size, tiling, channels, light camera, mip levels and "
                 "metadata.",
                 kToolName};
    app.add_option("FILE", o.files, "Deep shadow map (.dsm) files")->required()->type_name("");
    auto* json = app.add_flag("--json", o.json, "Print one JSON object per file (an array for several files)");
    auto* verifyFlag = app.add_flag("--verify", o.verify,
                                    "Check every tile of every file (CRC-32, layout, function invariants) and print "
                                    "'FILE: OK' or the error instead of describing the files");
    json->excludes(verifyFlag);
    app.set_version_flag("--version", std::string(kToolName) + " " + DSM_TOOLS_VERSION);
    app.footer("Exit status: 0 when every file was read (and verified), 1 when any file failed, 2 on a usage error.\n"
               "Documentation: docs/dsm-info.md");
    app.failure_message([](const CLI::App*, const CLI::Error& e) {
        return std::string(kToolName) + ": " + e.what() + "\nRun with --help for more information.\n";
    });

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // --help and --version go to stdout with status 0; usage errors to stderr.
        return app.exit(e) == 0 ? kExitOk : kExitUsage;
    }

    int status = kExitFileError;
    try {
        status = o.verify ? verify(o) : describe(o);
    } catch (const std::exception& e) {
        std::cerr << oneLine(std::string(kToolName) + ": ERROR: " + e.what()) << '\n';
        return kExitFileError;
    }
    std::cout.flush();
    if (!std::cout) {
        std::cerr << kToolName << ": ERROR: cannot write to standard output\n";
        return kExitFileError;
    }
    return status;
}
