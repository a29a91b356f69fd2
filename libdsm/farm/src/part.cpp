// Farm parts: the build key, the part files and their records, building one
// part and stitching them all.
#include "dsm/error.h"
#include "dsm/farm.h"
#include "dsm/names.h"
#include "dsm/output_file.h"
#include "sha256.h"
#include "text.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

DSM_NAMESPACE_BEGIN

using detail::clip;
using detail::concat;
using detail::quotedPath;
using Json = nlohmann::json;
namespace fs = std::filesystem;

namespace {

/// Marks a part record, and its layout's version.
constexpr const char* kRecordMark = "dsm_farm_part";
constexpr int kRecordVersion = 1;

/// Shortest text that reads back as the same double.
std::string exactText(double value) {
    char buffer[32];
    const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
    return std::string(buffer, result.ptr);
}

std::string partName(std::uint32_t index, const char* extension) {
    char name[32];
    std::snprintf(name, sizeof name, "part-%04u.%s", index, extension);
    return name;
}

/// "field 'seed' is 1 in 'a' but 2 in 'b'" for the first field where the keys
/// differ (in the order of `there`, then the fields only `here` has), nothing
/// when they agree.
std::optional<std::string> keyDifference(const FarmBuildKey& here, const std::string& hereName,
                                         const FarmBuildKey& there, const std::string& thereName) {
    const auto value = [](const FarmBuildKey& key, const std::string& field) -> std::string {
        for (const auto& [name, text] : key)
            if (name == field) return text;
        return "(absent)";
    };
    std::vector<std::string> fields;
    for (const auto& [field, text] : there) fields.push_back(field);
    for (const auto& [field, text] : here) fields.push_back(field);
    for (const std::string& field : fields) {
        const std::string a = value(here, field), b = value(there, field);
        if (a != b)
            return concat("field '", field, "' is ", clip(a), " in ", hereName, " but ", clip(b), " in ", thereName);
    }
    return std::nullopt;
}

std::optional<std::string> readText(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return std::nullopt;
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad()) return std::nullopt;
    return text.str();
}

void writeRecord(const std::string& path, const FarmPart& part, const FarmBuildKey& key, const std::string& partFile) {
    Json keyJson = Json::object();
    for (const auto& [field, value] : key) keyJson[field] = value;
    const Json record = {{kRecordMark, kRecordVersion},
                         {"index", part.index},
                         {"region", part.region},
                         {"key", keyJson},
                         {"part_sha256", detail::sha256OfFile(partFile)},
                         {"part_bytes", fs::file_size(partFile)}};
    const std::string text = record.dump(2) + "\n";
    OutputFile out(path);
    out.write(text.data(), text.size());
    out.commit();
}

}  // namespace

std::string sceneContentHash(const Scene& scene) {
    detail::Sha256 hash;
    const auto addLength = [&](std::uint64_t n) {
        std::uint8_t bytes[8];
        for (int i = 0; i < 8; ++i) bytes[i] = std::uint8_t(n >> (8 * i));
        hash.update(bytes, 8);
    };
    addLength(scene.source.size());
    hash.update(scene.source);
    for (const std::string& file : scene.files) {
        const std::optional<std::string> text = readText(file);
        if (!text) throw Error(ErrorCode::io, concat("scene ", quotedPath(scene.path), ": cannot read ",
                                                     quotedPath(file), " to hash it"));
        addLength(text->size());
        hash.update(*text);
    }
    return hash.hex();
}

FarmBuildKey farmBuildKey(const Scene& scene, const BuildOptions& given, FarmGrid grid) {
    // The defaults the scene gets (its area light's, say) are those of the
    // build, except the automatic tolerance, which stays "auto" as given.
    const BuildOptions options = resolvedBuildOptions(scene, given);
    FarmBuildKey key{{"scene_sha256", sceneContentHash(scene)},
            {"width", std::to_string(*options.width)},
            {"height", std::to_string(*options.height)},
            {"spp", std::to_string(options.samplesPerPixel)},
            {"tolerance", given.tolerance ? exactText(*given.tolerance) : "auto"},
            {"filter", filterName(*options.filter)},
            {"filter_width", exactText(*options.filterWidth)},
            {"mip_levels", options.mipLevels ? std::to_string(*options.mipLevels) : "auto"},
            {"level_tolerance_factor", exactText(options.levelToleranceFactor)},
            {"tile_size", std::to_string(options.tileSize)},
            {"mtsm_layers", std::to_string(*options.mtsmLayers)},
            {"counts", options.counts ? "true" : "false"},
            {"seed", std::to_string(options.seed)},
            {"sampler", options.sampler == SamplerMethod::raytrace ? "raytrace" : "scanline"},
            {"zlib_level", std::to_string(options.zlibLevel)},
            {"codec", options.codec == TileCodec::Zstd ? "zstd" : "zlib"},
            {"zstd_level", std::to_string(options.zstdLevel)},
            {"grid", concat(grid.columns, "x", grid.rows)},
            {"library", libraryVersion()}};
    // Only when set, so that the keys of greedy builds stay as they were.
    if (options.centredCompression) key.emplace_back("compression", "centred");
    return key;
}

std::string farmPartPath(const std::string& directory, std::uint32_t index) {
    return (fs::path(directory) / partName(index, "dsm")).string();
}

std::string farmPartRecordPath(const std::string& directory, std::uint32_t index) {
    return (fs::path(directory) / partName(index, "json")).string();
}

FarmPartCheck checkFarmPart(const std::string& directory, std::uint32_t index, const FarmBuildKey& expected) {
    FarmPartCheck check;
    const std::string partFile = farmPartPath(directory, index), recordFile = farmPartRecordPath(directory, index);
    std::error_code ec;
    if (!fs::is_regular_file(partFile, ec) || !fs::is_regular_file(recordFile, ec)) {
        check.reason = concat(quotedPath(partFile), ": missing (or its record ", partName(index, "json"), ")");
        return check;
    }
    check.state = FarmPartState::Damaged;
    const std::optional<std::string> text = readText(recordFile);
    const Json record = text ? Json::parse(*text, nullptr, false) : Json();
    const auto damaged = [&](const std::string& why) {
        check.reason = concat(quotedPath(recordFile), ": ", why);
        return check;
    };
    if (!record.is_object() || !record.contains(kRecordMark)) return damaged("not a farm part record");
    if (record[kRecordMark] != kRecordVersion) return damaged("a part record of another layout version");
    const Json& key = record.value("key", Json());
    const Json& region = record.value("region", Json());
    if (!record.value("index", Json()).is_number_unsigned() || !key.is_object() || !region.is_array() ||
        region.size() != 4 || !record.value("part_sha256", Json()).is_string() ||
        !record.value("part_bytes", Json()).is_number_unsigned())
        return damaged("the record's fields are missing or of the wrong type");
    for (const auto& [field, value] : key.items()) {
        if (!value.is_string()) return damaged("the record's key field '" + clip(field) + "' is not a string");
        check.key.emplace_back(field, value.get<std::string>());
    }
    for (std::size_t i = 0; i < 4; ++i) {
        if (!region[i].is_number_unsigned()) return damaged("the record's region is not 4 integers");
        check.part.region[i] = region[i].get<std::uint32_t>();
    }
    check.part.index = record["index"].get<std::uint32_t>();
    if (check.part.index != index) return damaged(concat("records part ", check.part.index, ", not ", index));
    if (fs::file_size(partFile, ec) != record["part_bytes"].get<std::uint64_t>() || ec)
        return damaged(concat(quotedPath(partFile), " is not the size the record gives (a part rewritten since?)"));
    std::string hash;
    try {
        hash = detail::sha256OfFile(partFile);
    } catch (const Error& e) {
        return damaged(e.what());
    }
    if (hash != record["part_sha256"].get<std::string>())
        return damaged(concat(quotedPath(partFile), " does not have the SHA-256 the record gives"));
    if (!expected.empty())
        if (auto difference = keyDifference(check.key, quotedPath(partFile), expected, "this build")) {
            check.state = FarmPartState::Different;
            check.reason = concat(quotedPath(partFile), ": a part of another build: ", *difference);
            return check;
        }
    check.state = FarmPartState::Done;
    return check;
}

FarmPartResult buildFarmPart(const Scene& scene, const BuildOptions& options, FarmGrid grid, std::uint32_t index,
                             const std::string& directory) {
    const FarmPlan plan = planFarm(scene, options, grid);
    if (index >= plan.parts.size())
        throw Error(ErrorCode::argument,
                    concat("farm: part index ", index, " is outside the ", plan.parts.size(), " parts [0, ",
                           plan.parts.size() - 1, "]"));
    if (options.region != std::array<std::uint32_t, 4>{0, 0, 0, 0})
        throw Error(ErrorCode::argument, "farm: the build options may not have a region (each part sets its own)");
    const FarmBuildKey key = farmBuildKey(scene, options, grid);
    FarmPartResult result;
    if (checkFarmPart(directory, index, key).state == FarmPartState::Done) {
        result.skipped = true;
        return result;
    }
    BuildOptions partOptions = options;
    partOptions.region = plan.parts[index].region;
    const std::string partFile = farmPartPath(directory, index);
    result.stats = buildMap(scene, partOptions, partFile);
    writeRecord(farmPartRecordPath(directory, index), plan.parts[index], key, partFile);
    return result;
}

MergeReport stitchFarmParts(const std::string& directory, const std::string& output) {
    // The reference build: the first sound part found.
    std::error_code ec;
    std::vector<std::uint32_t> recorded;
    for (fs::directory_iterator it(directory, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        const std::string_view prefix = "part-", suffix = ".json";
        if (name.size() <= prefix.size() + suffix.size() || !name.starts_with(prefix) || !name.ends_with(suffix))
            continue;
        const std::string digits = name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());
        if (digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos) continue;
        recorded.push_back(static_cast<std::uint32_t>(std::stoul(digits)));
    }
    if (ec) throw Error(ErrorCode::io, concat(quotedPath(directory), ": cannot list the parts: ", ec.message()));
    std::sort(recorded.begin(), recorded.end());
    std::optional<FarmPartCheck> reference;
    for (const std::uint32_t index : recorded)
        if (FarmPartCheck check = checkFarmPart(directory, index, {}); check.state == FarmPartState::Done) {
            reference = std::move(check);
            break;
        }
    if (!reference)
        throw Error(ErrorCode::io, concat(quotedPath(directory), ": holds no sound farm part (part-NNNN.dsm with "
                                                                 "its record part-NNNN.json)"));
    std::uint32_t columns = 0, rows = 0;
    int zlibLevel = -1;
    for (const auto& [field, value] : reference->key) {
        if (field == "grid") std::sscanf(value.c_str(), "%ux%u", &columns, &rows);
        if (field == "zlib_level") zlibLevel = std::atoi(value.c_str());
    }
    if (columns == 0 || rows == 0 || zlibLevel < 0 || zlibLevel > 9)
        throw Error(ErrorCode::corrupt, concat(quotedPath(farmPartRecordPath(directory, reference->part.index)),
                                               ": the key has no valid grid or zlib_level"));
    const std::uint32_t count = columns * rows;
    std::vector<std::string> missing, damaged, parts;
    for (std::uint32_t index = 0; index < count; ++index) {
        const FarmPartCheck check = checkFarmPart(directory, index, reference->key);
        if (check.state == FarmPartState::Missing) missing.push_back(std::to_string(index));
        if (check.state == FarmPartState::Damaged) damaged.push_back(check.reason);
        if (check.state == FarmPartState::Different)
            throw Error(ErrorCode::argument,
                        concat(quotedPath(directory), ": parts of different builds: ",
                               *keyDifference(check.key, quotedPath(farmPartPath(directory, index)), reference->key,
                                              quotedPath(farmPartPath(directory, reference->part.index)))));
        parts.push_back(farmPartPath(directory, index));
    }
    for (const std::uint32_t index : recorded)
        if (index >= count)
            throw Error(ErrorCode::argument, concat(quotedPath(directory), ": ", partName(index, "json"),
                                                    " is outside this build's ", count, " parts (a part of another "
                                                    "build)"));
    if (!missing.empty() || !damaged.empty()) {
        std::string list;
        for (const std::string& index : missing) list += (list.empty() ? "" : ", ") + index;
        throw Error(damaged.empty() ? ErrorCode::io : ErrorCode::corrupt,
                    concat(quotedPath(directory), ": ", missing.size(), " of ", count, " parts missing",
                           missing.empty() ? std::string() : " (" + list + ")", damaged.empty() ? "" : "; damaged: ",
                           damaged.empty() ? std::string() : damaged.front(),
                           damaged.size() > 1 ? concat(" and ", damaged.size() - 1, " more") : std::string()));
    }
    MergeOptions options;
    options.mode = MergeMode::Stitch;
    options.zlibLevel = zlibLevel;
    return mergeMaps(parts, output, options);
}

DSM_NAMESPACE_END
