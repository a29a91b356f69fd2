// What one thread needs to look maps up (internal): a small table of the tiles
// it touched, filter scratch space and the last failure. The inside of both
// ShadowThread (one per thread, for every map of a ShadowSystem) and
// LookupContext (one per thread and map).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "dsm/lookup.h"
#include "dsm/span.h"
#include "impl_access.h"
#include "tile_codec.h"

DSM_NAMESPACE_BEGIN

using MapImpl = ImplAccess::Impl<DeepShadowMap>;

/// One axis of a separable filter: the pixels [first, first + weights.size())
/// of a level and their weights.
struct AxisWeights {
    long first = 0;
    std::vector<double> weights;
};

/// Keeps why a lookup failed; a message that cannot be stored is left empty.
void recordFailure(LookupFailure& failure, ErrorCode code, const char* message) noexcept;
/// The documented value of a failed lookup (lookup.h): lit, error bound 1.
LookupResult failureValue(int channels) noexcept;

class LookupState {
public:
    /// `tileSlots` (rounded up to a power of two, at least 2) tiles are kept
    /// at hand, each with a reference that keeps it alive.
    explicit LookupState(unsigned tileSlots);

    /// The throwing lookups (LookupContext::raster and the others).
    LookupResult raster(const MapImpl& map, double rx, double ry, double z, const LookupOptions& options);
    LookupResult at(const MapImpl& map, LookupSpace space, const std::array<double, 3>& p,
                    const LookupOptions& options);

    /// at() that never throws: on failure records why in `failure` and gives
    /// the documented failure value (lookup.h).
    bool tryAt(const MapImpl& map, LookupSpace space, const std::array<double, 3>& p, const LookupOptions& options,
               LookupResult& result) noexcept;

    /// tryAt() for every point, in an order that visits each tile's points
    /// together; results[i] answers points[i]. Returns the number of failures
    /// (the last one is in `failure`).
    std::size_t tryBatch(const MapImpl& map, LookupSpace space, Span<const std::array<double, 3>> points,
                         const LookupOptions& options, Span<LookupResult> results) noexcept;

    LookupFailure failure;
    std::uint64_t tileTableHits = 0;
    std::uint64_t tileTableMisses = 0;

    /// Bytes this state holds itself (not counting the tiles it keeps alive).
    std::size_t memoryBytes() const;
    /// Lets go of every tile kept at hand.
    void releaseTiles();

private:
    struct TileSlot {
        std::uint64_t file = 0;  // 0: empty (file ids start at 1)
        std::uint32_t level = 0;
        std::uint32_t index = 0;
        bool recent = false;  // in the first slot of a pair: it was used last
        const format::DecodedTile* tile = nullptr;
        std::shared_ptr<const format::DecodedTile> keepAlive;
    };
    struct BatchItem {
        std::uint64_t key;                // level-0 tile under the point
        std::size_t index;                // in the caller's arrays
        std::array<double, 3> raster;     // the point in raster space
    };

    std::size_t tryBatchPart(const MapImpl& map, LookupSpace space, Span<const std::array<double, 3>> points,
                             const LookupOptions& options, Span<LookupResult> results) noexcept;
    const format::DecodedTile& tile(const MapImpl& map, unsigned level, std::uint32_t tx, std::uint32_t ty);
    double filterLevel(const MapImpl& map, unsigned level, double rx, double ry, double z, double width,
                       PixelFilter filter, double out[3], int& pixelsUsed);
    double sumFootprint(const MapImpl& map, unsigned level, double z, double out[3], int& pixelsUsed);
    double bilinearLevel(const MapImpl& map, unsigned level, double cx, double cy, double z, PixelFilter filter,
                         double width, double out[3], int& pixelsUsed);

    std::vector<TileSlot> slots_;
    std::size_t slotMask_ = 0;
    AxisWeights wx_, wy_;
    std::vector<BatchItem> batchOrder_;
    std::vector<BatchItem> batchScratch_;  // the other half of each radix pass
};

DSM_NAMESPACE_END
