// Cutting a map into farm parts along its tiles.
#include "dsm/error.h"
#include "dsm/farm.h"
#include "text.h"

#include <cmath>

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

constexpr std::uint32_t kMaxParts = 65536;

/// Start (in tiles) of each of `pieces` near-equal runs of `tiles` tiles, and
/// `tiles` at the end.
std::vector<std::uint32_t> splitTiles(std::uint32_t tiles, std::uint32_t pieces) {
    std::vector<std::uint32_t> starts(pieces + 1);
    for (std::uint32_t k = 0; k <= pieces; ++k)
        starts[k] = static_cast<std::uint32_t>(std::uint64_t(k) * tiles / pieces);
    return starts;
}

}  // namespace

FarmGrid farmGridForCount(std::uint32_t count) {
    if (count < 1 || count > kMaxParts)
        throw Error(ErrorCode::argument, concat("farm: ", count, " parts is outside [1, ", kMaxParts, "]"));
    std::uint32_t rows = static_cast<std::uint32_t>(std::sqrt(double(count)));
    while (rows > 1 && count % rows != 0) --rows;
    return {count / rows, rows};
}

FarmPlan planFarm(std::uint32_t width, std::uint32_t height, std::uint32_t tileSize, FarmGrid grid) {
    if (width == 0 || height == 0 || tileSize == 0 || grid.columns == 0 || grid.rows == 0)
        throw Error(ErrorCode::argument, concat("farm: cannot plan a ", width, "x", height, " map with tile size ",
                                                tileSize, " as ", grid.columns, "x", grid.rows, " parts"));
    if (std::uint64_t(grid.columns) * grid.rows > kMaxParts)
        throw Error(ErrorCode::argument, concat("farm: ", grid.columns, "x", grid.rows, " parts is more than ",
                                                kMaxParts));
    const std::uint32_t tilesX = (width - 1) / tileSize + 1, tilesY = (height - 1) / tileSize + 1;
    if (grid.columns > tilesX || grid.rows > tilesY)
        throw Error(ErrorCode::argument,
                    concat("farm: ", grid.columns, "x", grid.rows, " parts do not fit the ", tilesX, "x", tilesY,
                           " tiles of the ", width, "x", height, " map (tile size ", tileSize,
                           "): a part holds at least one tile"));
    FarmPlan plan{width, height, tileSize, grid, {}};
    const auto columns = splitTiles(tilesX, grid.columns), rows = splitTiles(tilesY, grid.rows);
    const auto pixel = [&](std::uint32_t tile, std::uint32_t size) {
        return static_cast<std::uint32_t>(std::min<std::uint64_t>(std::uint64_t(tile) * tileSize, size));
    };
    for (std::uint32_t r = 0; r < grid.rows; ++r)
        for (std::uint32_t c = 0; c < grid.columns; ++c)
            plan.parts.push_back({r * grid.columns + c,
                                  {pixel(columns[c], width), pixel(rows[r], height), pixel(columns[c + 1], width),
                                   pixel(rows[r + 1], height)}});
    return plan;
}

FarmPlan planFarm(const Scene& scene, const BuildOptions& options, FarmGrid grid) {
    const BuildEstimate size = estimateBuild(scene, options);
    return planFarm(size.width, size.height, options.tileSize, grid);
}

DSM_NAMESPACE_END
