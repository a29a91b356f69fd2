// Farm builds: one map built as parts on many machines, each part a region of
// the map (BuildOptions::region) written into a shared directory, then
// stitched (MergeMode::Stitch) into the map a single build would have written.
// The user-facing description: docs/dsm-farm.md.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "dsm/merge.h"
#include "dsm/sampler.h"
#include "dsm/scene.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// How the map is cut: columns x rows of parts.
struct FarmGrid {
    std::uint32_t columns = 1;
    std::uint32_t rows = 1;
    std::uint32_t count() const { return columns * rows; }
};

/// The grid for `count` parts (1..65536): as square as `count` allows, with
/// more columns than rows when it is not a square (16 -> 4x4, 8 -> 4x2, 7 -> 7x1).
/// Throws dsm::Error (ErrorCode::argument) outside the range.
DSM_API FarmGrid farmGridForCount(std::uint32_t count);

/// One part of a farm build: its index (row-major in the grid) and its pixels
/// [x0, x1) x [y0, y1).
struct FarmPart {
    std::uint32_t index = 0;
    std::array<std::uint32_t, 4> region{0, 0, 0, 0};
};

struct FarmPlan {
    std::uint32_t width = 0;
    std::uint32_t height = 0;
    std::uint32_t tileSize = 0;
    FarmGrid grid;
    std::vector<FarmPart> parts;  ///< by index
};

/// Cuts a width x height map with square tiles of `tileSize` pixels into the
/// grid's parts, along tile edges (a part never shares a map tile with
/// another), each column and row of parts holding as near the same number of
/// map tiles as possible. Throws dsm::Error (ErrorCode::argument) when the
/// grid has more columns or rows than the map has tiles across or down, or a
/// size is 0.
DSM_API FarmPlan planFarm(std::uint32_t width, std::uint32_t height, std::uint32_t tileSize, FarmGrid grid);
/// The plan for building `scene` with `options` (map size from the options or
/// the scene's light).
DSM_API FarmPlan planFarm(const Scene& scene, const BuildOptions& options, FarmGrid grid);

/// What every part of one farm build must agree on, as (field, value) pairs in
/// a fixed order: the scene's content hash (SHA-256 of its JSON text and of
/// every file it reads, not of their names, which differ between machines),
/// the map size, every option that changes the map's bytes, the seed, the
/// grid, and the library version (which fixes the file format and codec).
/// Options that do not change the bytes (threads, progress) are left out.
/// Records keep the fields by name (so a record's key lists them in name order).
using FarmBuildKey = std::vector<std::pair<std::string, std::string>>;
DSM_API FarmBuildKey farmBuildKey(const Scene& scene, const BuildOptions& options, FarmGrid grid);

/// SHA-256 of the scene's content: its JSON text, then each file it reads
/// (length and bytes). Hex, 64 characters. Throws dsm::Error (io) when a file
/// cannot be read.
DSM_API std::string sceneContentHash(const Scene& scene);

/// The part file `directory`/part-NNNN.dsm and its record part-NNNN.json (the
/// build key, the index, the region and the part file's SHA-256 and size),
/// written after the part; a part counts only with its record.
DSM_API std::string farmPartPath(const std::string& directory, std::uint32_t index);
DSM_API std::string farmPartRecordPath(const std::string& directory, std::uint32_t index);

enum class FarmPartState : std::uint8_t {
    Missing,    ///< no part file or no record
    Damaged,    ///< the record cannot be read, or the file is not the one it records
    Different,  ///< a sound part of another build (its key differs)
    Done,       ///< a sound part of this build
};

struct FarmPartCheck {
    FarmPartState state = FarmPartState::Missing;
    /// Why the part is not Done, one line naming the file (and, for Different,
    /// the first field that differs with both values).
    std::string reason;
    FarmBuildKey key;  ///< the recorded key (Different and Done)
    FarmPart part;     ///< the recorded index and region (Different and Done)
};

/// Checks part `index` in `directory` against `expected` (empty: any key).
/// Never throws for a missing or damaged part: the state says so.
DSM_API FarmPartCheck checkFarmPart(const std::string& directory, std::uint32_t index, const FarmBuildKey& expected);

struct FarmPartResult {
    bool skipped = false;  ///< the part was already there, sound, of this build
    BuildStats stats;      ///< of the build (zero when skipped)
};

/// Builds part `index` of the plan into `directory`: skipped when it is
/// already Done; otherwise built over options.region = the part's (the
/// options' own region must be empty) and written atomically, then its record.
/// Throws dsm::Error (argument for an index outside the plan).
DSM_API FarmPartResult buildFarmPart(const Scene& scene, const BuildOptions& options, FarmGrid grid,
                                     std::uint32_t index, const std::string& directory);

/// Checks that `directory` holds every part of one build (the grid comes from
/// the records) and stitches them into `output` (atomically). Throws
/// dsm::Error naming the missing or damaged parts by index, or two parts of
/// different builds with the first field that differs.
DSM_API MergeReport stitchFarmParts(const std::string& directory, const std::string& output);

DSM_NAMESPACE_END
