#include "lookup_state.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <exception>
#include <new>
#include <utility>

#include "dsm/auto_bias.h"
#include "dsm/error.h"
#include "pixel_filter.h"
#include "reader_impl.h"
#include "segment_search.h"
#include "splitmix64.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

double minimumWidth(PixelFilter filter) { return filter == PixelFilter::Box ? 1.0 : 2.0; }

// 2^-level, exactly (levels are far below 64).
double levelScale(unsigned level) { return 1.0 / static_cast<double>(std::uint64_t(1) << level); }

// The weight of pixel i (centre i + 0.5) for a footprint of half-width r
// centred at c, along one axis.
inline double pixelWeight(PixelFilter filter, long i, double c, double r) {
    switch (filter) {
        case PixelFilter::Box: {
            // Overlap of the pixel [i, i+1] with the footprint [c - r, c + r].
            const double lo = std::max(static_cast<double>(i), c - r);
            const double hi = std::min(static_cast<double>(i) + 1.0, c + r);
            return std::max(0.0, hi - lo);
        }
        case PixelFilter::Triangle:
            return detail::triangleWeight((static_cast<double>(i) + 0.5) - c, r);
        case PixelFilter::Gaussian: {
            const double d = (static_cast<double>(i) + 0.5) - c;
            return std::abs(d) < r ? detail::gaussianWeight(d * d, r) : 0.0;
        }
    }
    return 0.0;
}

// Weights along one axis for a footprint of width w (pixels of this level)
// centred at c, over pixel centres i + 0.5.
void axisWeights(PixelFilter filter, double c, double w, std::uint32_t extent, AxisWeights& out) {
    const double r = 0.5 * w;
    // Pixels outside [0, extent) are left out by the caller anyway: clipping
    // here (in double, before converting) bounds the work and the conversion
    // for any width and position.
    out.first = static_cast<long>(std::clamp(std::floor(c - r - 0.5), -1.0, static_cast<double>(extent)));
    const long last = static_cast<long>(std::clamp(std::ceil(c + r - 0.5), -1.0, static_cast<double>(extent)));
    out.weights.clear();
    for (long i = out.first; i <= last; ++i) out.weights.push_back(pixelWeight(filter, i, c, r));
}

// floor(x) for |x| well inside the range of long (a raster coordinate):
// without the library call std::floor becomes on processors before SSE 4.1.
inline long floorToLong(double x) {
    const long i = static_cast<long>(x);  // truncates towards zero
    return static_cast<double>(i) > x ? i - 1 : i;
}

// True when a footprint of this width touches at most the two pixels on each
// side of the point along each axis (bilinear interpolation): the box of
// width 1 and the triangle of width 2.
bool isBilinear(PixelFilter filter, double width) {
    return (filter == PixelFilter::Box && width == 1.0) || (filter == PixelFilter::Triangle && width == 2.0);
}

// Visibility of pixel p of a tile at depth z in v[0..2] (a monochrome
// pixel's value three times). Returns the pixel's channel count. Same rules and arithmetic as
// VisibilityView::evaluate.
[[gnu::always_inline]] inline int evaluatePixel(const format::DecodedTile& t, std::size_t p, double z, double v[3]) {
    const format::PixelRecord& a = t.records()[p];
    const format::PixelRecord& b = t.records()[p + 1];
    const int channels = static_cast<int>(a.channels);
    std::size_t end0 = b.vertexStart - a.vertexStart;
    if (end0 == 0) {
        v[0] = v[1] = v[2] = 1.0;
        return channels;
    }
    const float* zs = t.depths() + a.vertexStart;
    if (b.layerStart != a.layerStart) {
        // Layered (multilayer transparent shadow maps): the light-centre
        // function is layer 0, and 0 from its last vertex on.
        end0 = t.layerStarts()[a.layerStart];
        if (z >= static_cast<double>(zs[end0 - 1])) {
            v[0] = v[1] = v[2] = 0.0;
            return channels;
        }
    }
    const std::size_t k = detail::firstDepthAbove(zs, end0, z);
    const float* vs = t.values() + a.valueStart;
    const auto channel = [&](int c) {
        if (k == 0) return 1.0;
        if (k == end0) return static_cast<double>(vs[(end0 - 1) * channels + c]);
        return detail::lerpSegment(zs[k - 1], vs[(k - 1) * channels + c], zs[k], vs[k * channels + c], z);
    };
    v[0] = channel(0);
    if (channels == 3) {
        v[1] = channel(1);
        v[2] = channel(2);
    } else {
        v[1] = v[2] = v[0];
    }
    return channels;
}

// Visibility of pixel p of a monochrome map's tile at depth z: evaluatePixel
// for one channel, with the same rules and arithmetic.
[[gnu::always_inline]] inline double evaluateMonoPixel(const format::DecodedTile& t, std::size_t p, double z) {
    const format::PixelRecord& a = t.records()[p];
    const format::PixelRecord& b = t.records()[p + 1];
    std::size_t end0 = b.vertexStart - a.vertexStart;
    if (end0 == 0) return 1.0;
    const float* zs = t.depths() + a.vertexStart;
    if (b.layerStart != a.layerStart) [[unlikely]] {
        end0 = t.layerStarts()[a.layerStart];
        if (z >= static_cast<double>(zs[end0 - 1])) return 0.0;
    }
    const std::size_t k = detail::firstDepthAbove(zs, end0, z);
    const float* vs = t.values() + a.valueStart;
    if (k == 0) return 1.0;
    if (k == end0) return static_cast<double>(vs[end0 - 1]);
    return detail::lerpSegment(zs[k - 1], vs[k - 1], zs[k], vs[k], z);
}

// The argument error of a lookup (kept out of the lookup's own code).
[[noreturn, gnu::noinline, gnu::cold]] void throwBadArguments(double rx, double ry, double z,
                                                             const LookupOptions& options) {
    if (!std::isfinite(rx) || !std::isfinite(ry) || !std::isfinite(z))
        throw Error(ErrorCode::argument, concat("lookup: point ", rx, ",", ry, " at depth ", z, " is not finite"));
    if (!std::isfinite(options.filterWidth) || options.filterWidth < 0.0)
        throw Error(ErrorCode::argument,
                    concat("lookup: filter width ", options.filterWidth, " is not a finite value >= 0"));
    throw Error(ErrorCode::argument, concat("lookup: bias ", *options.bias, " is not finite"));
}

// Raster position and depth of a point; false when it is lit without a
// lookup: behind a perspective light, or so far out that the light camera
// carries it beyond double range (a finite point, a finite but extreme
// camera). Throws for a non-finite point.
bool toRaster(const MapInfo& info, LookupSpace space, const std::array<double, 3>& p, double& rx, double& ry,
              double& z) {
    if (space == LookupSpace::raster) {
        rx = p[0];
        ry = p[1];
        z = p[2];
        return true;
    }
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
        throw Error(ErrorCode::argument, concat("lookup: ", space == LookupSpace::world ? "world" : "light",
                                                "-space point ", p[0], ",", p[1], ",", p[2], " is not finite"));
    const std::array<double, 3> light = space == LookupSpace::world ? info.camera.worldToLightSpace(p) : p;
    return info.camera.lightToRaster(light, static_cast<int>(info.width), static_cast<int>(info.height), rx, ry, z) &&
           std::isfinite(z);
}

}  // namespace

void recordFailure(LookupFailure& failure, ErrorCode code, const char* message) noexcept {
    failure.code = code;
    try {
        failure.message = message;
    } catch (...) {
        failure.message.clear();
    }
}

LookupResult failureValue(int channels) noexcept {
    LookupResult r;
    r.channels = channels;
    r.errorBound = 1.0;
    return r;
}

LookupState::LookupState(unsigned tileSlots) {
    std::size_t n = 2;  // pairs of slots
    while (n < tileSlots) n <<= 1;
    slots_.resize(n);
    slotMask_ = n - 1;
    // Room for the footprints of the common filters (bilinear, and widths up
    // to 6 pixels at the level used), so that they never allocate.
    wx_.weights.reserve(8);
    wy_.weights.reserve(8);
}

std::size_t LookupState::memoryBytes() const {
    return sizeof(*this) + slots_.capacity() * sizeof(TileSlot) +
           (wx_.weights.capacity() + wy_.weights.capacity()) * sizeof(double) +
           (batchOrder_.capacity() + batchScratch_.capacity()) * sizeof(BatchItem);
}

void LookupState::releaseTiles() {
    for (TileSlot& s : slots_) s = TileSlot{};
}

const format::DecodedTile& LookupState::tile(const MapImpl& map, unsigned level, std::uint32_t tx,
                                             std::uint32_t ty) {
    const std::uint32_t index = ty * map.info.levels[level].tilesX + tx;
    const std::uint64_t hash = detail::mix64(map.fileId * 0x9E3779B97F4A7C15ull ^ (std::uint64_t(level) << 32 | index));
    // Two-way: the key may sit in either slot of its pair; a miss replaces
    // the one not used last.
    TileSlot* pair = &slots_[hash & slotMask_ & ~std::size_t(1)];
    for (int w = 0; w < 2; ++w) {
        TileSlot& s = pair[w];
        if (s.file == map.fileId && s.level == level && s.index == index) {
            ++tileTableHits;
            pair[0].recent = w == 0;
            return *s.tile;
        }
    }
    ++tileTableMisses;
    std::shared_ptr<const format::DecodedTile> loaded = map.getTile(level, tx, ty);  // may throw: slots unchanged
    const int victim = pair[0].recent ? 1 : 0;
    pair[0].recent = victim == 0;
    TileSlot& slot = pair[victim];
    slot.file = map.fileId;
    slot.level = level;
    slot.index = index;
    slot.tile = loaded.get();
    slot.keepAlive = std::move(loaded);
    return *slot.tile;
}

// The bilinear footprint: the pixels floor(c - 1/2) and the next along each
// axis are the only ones with non-zero weight, visited in the general path's
// order (rows, then columns) with the same weights, so the result is the same
// to the bit.
[[gnu::always_inline]] inline double LookupState::bilinearLevel(const MapImpl& map, unsigned level, double cx, double cy, double z,
                                  PixelFilter filter, double width, double out[3], int& pixelsUsed) {
    const LevelInfo& L = map.info.levels[level];
    const double r = 0.5 * width;
    const long x0 = floorToLong(cx - 0.5);
    const long y0 = floorToLong(cy - 0.5);
    const double wxs[2] = {pixelWeight(filter, x0, cx, r), pixelWeight(filter, x0 + 1, cx, r)};
    const double wys[2] = {pixelWeight(filter, y0, cy, r), pixelWeight(filter, y0 + 1, cy, r)};
    const std::uint32_t T = map.info.tileSize;
    // The common case: a monochrome map and all four pixels in one tile,
    // fetched once and summed straight-line. A pixel of weight 0 adds +0 to
    // the sums, which leaves them unchanged: the same result as skipping it.
    if (map.info.channels == 1 && x0 >= 0 && y0 >= 0 && x0 + 1 < static_cast<long>(L.width) &&
        y0 + 1 < static_cast<long>(L.height) &&
        static_cast<std::uint32_t>(x0) / T == static_cast<std::uint32_t>(x0 + 1) / T &&
        static_cast<std::uint32_t>(y0) / T == static_cast<std::uint32_t>(y0 + 1) / T) {
        const format::DecodedTile& t =
            tile(map, level, static_cast<std::uint32_t>(x0) / T, static_cast<std::uint32_t>(y0) / T);
        const std::size_t p = std::size_t(static_cast<std::uint32_t>(y0) % T) * t.width + static_cast<std::uint32_t>(x0) % T;
        const double v00 = evaluateMonoPixel(t, p, z);
        const double v01 = evaluateMonoPixel(t, p + 1, z);
        const double v10 = evaluateMonoPixel(t, p + t.width, z);
        const double v11 = evaluateMonoPixel(t, p + t.width + 1, z);
        const double w00 = wxs[0] * wys[0], w01 = wxs[1] * wys[0], w10 = wxs[0] * wys[1], w11 = wxs[1] * wys[1];
        const double total = w00 + w01 + w10 + w11;
        out[0] = w00 * v00 + w01 * v01 + w10 * v10 + w11 * v11;
        pixelsUsed += (w00 != 0.0) + (w01 != 0.0) + (w10 != 0.0) + (w11 != 0.0);
        if (total > 0.0) out[0] /= total;
        out[1] = out[2] = out[0];
        return total;
    }
    // RGB, or near the image's or a tile's edge: the general sum over the two
    // pixels of each axis.
    wx_.first = x0;
    wx_.weights.assign(wxs, wxs + 2);
    wy_.first = y0;
    wy_.weights.assign(wys, wys + 2);
    return sumFootprint(map, level, z, out, pixelsUsed);
}

// Filtered visibility of one level; returns the total weight used.
[[gnu::always_inline]] inline double LookupState::filterLevel(const MapImpl& map, unsigned level, double rx, double ry, double z, double width,
                                PixelFilter filter, double out[3], int& pixelsUsed) {
    const double scale = levelScale(level);
    if (isBilinear(filter, width))
        return bilinearLevel(map, level, rx * scale, ry * scale, z, filter, width, out, pixelsUsed);
    const LevelInfo& L = map.info.levels[level];
    axisWeights(filter, rx * scale, width, L.width, wx_);
    axisWeights(filter, ry * scale, width, L.height, wy_);
    return sumFootprint(map, level, z, out, pixelsUsed);
}

// The weighted mean of the pixels wx_ x wy_ of a level (those outside the
// image, or of weight 0, left out); returns the total weight.
double LookupState::sumFootprint(const MapImpl& map, unsigned level, double z, double out[3], int& pixelsUsed) {
    const LevelInfo& L = map.info.levels[level];
    const std::uint32_t T = map.info.tileSize;
    double total = 0.0;
    out[0] = out[1] = out[2] = 0.0;
    for (std::size_t j = 0; j < wy_.weights.size(); ++j) {
        const long y = wy_.first + static_cast<long>(j);
        if (y < 0 || y >= static_cast<long>(L.height) || wy_.weights[j] == 0.0) continue;
        for (std::size_t i = 0; i < wx_.weights.size(); ++i) {
            const long x = wx_.first + static_cast<long>(i);
            if (x < 0 || x >= static_cast<long>(L.width) || wx_.weights[i] == 0.0) continue;
            const double w = wx_.weights[i] * wy_.weights[j];
            const auto ux = static_cast<std::uint32_t>(x), uy = static_cast<std::uint32_t>(y);
            const format::DecodedTile& t = tile(map, level, ux / T, uy / T);
            double v[3];
            evaluatePixel(t, std::size_t(uy % T) * t.width + ux % T, z, v);
            for (int c = 0; c < 3; ++c) out[c] += w * v[c];
            total += w;
            ++pixelsUsed;
        }
    }
    if (total > 0.0)
        for (int c = 0; c < 3; ++c) out[c] /= total;
    return total;
}

LookupResult LookupState::raster(const MapImpl& map, double rx, double ry, double z, const LookupOptions& options) {
    const MapInfo& info = map.info;
    if (!std::isfinite(rx) || !std::isfinite(ry) || !std::isfinite(z) || !std::isfinite(options.filterWidth) ||
        options.filterWidth < 0.0 || (options.bias && !std::isfinite(*options.bias))) [[unlikely]]
        throwBadArguments(rx, ry, z, options);
    LookupResult result;
    result.channels = info.channels;
    // Points outside the raster [0, width] x [0, height] are lit (lookup.h),
    // even when a wide footprint would reach pixels inside.
    if (!(rx >= 0.0 && rx <= static_cast<double>(info.width) && ry >= 0.0 && ry <= static_cast<double>(info.height)))
        return result;
    const double zq = z - (options.bias ? *options.bias : automaticBias(info, rx, ry, z, options.normal));
    const double minWidth = minimumWidth(options.filter);
    const double width = std::max(options.filterWidth, minWidth);
    const unsigned coarsest = static_cast<unsigned>(info.levels.size() - 1);

    unsigned level0, level1;
    double blend;
    if (options.level) {
        level0 = level1 = std::min(*options.level, coarsest);
        blend = 0.0;
    } else if (width == minWidth) {
        level0 = level1 = 0;  // the log below is 0
        blend = 0.0;
    } else {
        const double lambda = std::max(0.0, std::log2(width / minWidth));
        level0 = std::min(static_cast<unsigned>(std::floor(lambda)), coarsest);
        level1 = std::min(level0 + 1, coarsest);
        blend = level1 == level0 ? 0.0 : lambda - std::floor(lambda);
    }
    double a[3], b[3];
    const double w0 = std::max(width * levelScale(level0), minWidth);
    const double total0 = filterLevel(map, level0, rx, ry, zq, w0, options.filter, a, result.pixelsUsed);
    double total1 = 0.0;
    if (blend > 0.0) {
        const double w1 = std::max(width * levelScale(level1), minWidth);
        total1 = filterLevel(map, level1, rx, ry, zq, w1, options.filter, b, result.pixelsUsed);
    }
    double bound = 0.0;
    if (total0 > 0.0) bound = info.levels[level0].errorBound;
    if (total1 > 0.0) bound = std::max(bound, info.levels[level1].errorBound);
    if (blend == 0.0) {
        // One level: va + 0 * (vb - va) is va, so the blend below reduces to this.
        for (int c = 0; c < 3; ++c)
            result.v[static_cast<std::size_t>(c)] = std::clamp(total0 > 0.0 ? a[c] : 1.0, 0.0, 1.0);
    } else {
        for (int c = 0; c < 3; ++c) {
            const double va = total0 > 0.0 ? a[c] : 1.0;
            const double vb = total1 > 0.0 ? b[c] : va;
            result.v[static_cast<std::size_t>(c)] = std::clamp(va + blend * (vb - va), 0.0, 1.0);
        }
    }
    if (total0 <= 0.0 && total1 <= 0.0) result.v = {1.0, 1.0, 1.0};
    result.errorBound = bound;
    return result;
}

LookupResult LookupState::at(const MapImpl& map, LookupSpace space, const std::array<double, 3>& p,
                             const LookupOptions& options) {
    if (space == LookupSpace::raster) return raster(map, p[0], p[1], p[2], options);
    double rx, ry, z;
    if (!toRaster(map.info, space, p, rx, ry, z)) {
        LookupResult lit;
        lit.channels = map.info.channels;
        return lit;
    }
    if (space == LookupSpace::world && options.normal && !options.bias) {
        LookupOptions light = options;  // the automatic bias takes a light-space normal
        light.normal = lightSpaceNormal(map.info.camera, *options.normal);
        return raster(map, rx, ry, z, light);
    }
    return raster(map, rx, ry, z, options);
}

bool LookupState::tryAt(const MapImpl& map, LookupSpace space, const std::array<double, 3>& p,
                        const LookupOptions& options, LookupResult& result) noexcept {
    try {
        result = at(map, space, p, options);
        return true;
    } catch (const Error& e) {
        recordFailure(failure, e.code(), e.what());
    } catch (const std::bad_alloc&) {
        recordFailure(failure, ErrorCode::limit, "lookup: out of memory");
    } catch (const std::exception& e) {
        recordFailure(failure, ErrorCode::internal, e.what());
    } catch (...) {
        recordFailure(failure, ErrorCode::internal, "lookup: unknown failure");
    }
    result = failureValue(map.info.channels);
    return false;
}

std::size_t LookupState::tryBatch(const MapImpl& map, LookupSpace space, Span<const std::array<double, 3>> points,
                                  const LookupOptions& options, Span<LookupResult> results) noexcept {
    // A huge batch is taken in parts: sorting costs n log n and the points'
    // and results' own memory stops fitting in the processor's caches. A part
    // holds about 64 points per tile of level 0 (at least 2^16, at most 2^20
    // points): measured on maps of 256 and 16,384 tiles, where larger parts
    // were slower and smaller ones lost locality.
    const std::uint64_t tiles = std::uint64_t(map.info.levels[0].tilesX) * map.info.levels[0].tilesY;
    const std::size_t kPart = static_cast<std::size_t>(std::clamp<std::uint64_t>(64 * tiles, 1u << 16, 1u << 20));
    const std::size_t n = std::min(points.size(), results.size());
    if (n <= kPart) return tryBatchPart(map, space, points.first(n), options, results.first(n));
    std::size_t failures = 0;
    for (std::size_t begin = 0; begin < n; begin += kPart) {
        const std::size_t count = std::min(kPart, n - begin);
        failures += tryBatchPart(map, space, points.subspan(begin, count), options, results.subspan(begin, count));
    }
    return failures;
}

std::size_t LookupState::tryBatchPart(const MapImpl& map, LookupSpace space, Span<const std::array<double, 3>> points,
                                      const LookupOptions& options, Span<LookupResult> results) noexcept {
    const std::size_t n = points.size();
    std::size_t failures = 0;
    // Sorting needs scratch space; without it the points are looked up in
    // the order given (same answers, less locality).
    bool sorted = n > 1;
    if (sorted) {
        try {
            batchOrder_.resize(n);
            batchScratch_.resize(n);
        } catch (...) {
            sorted = false;
        }
    }
    if (!sorted) {
        for (std::size_t i = 0; i < n; ++i)
            if (!tryAt(map, space, points[i], options, results[i])) ++failures;
        return failures;
    }
    // Order the points by the level-0 tile under them, so that each tile's
    // points are looked up together and its pixels stay in the processor's
    // caches. Points that are lit without a lookup or invalid go last.
    const MapInfo& info = map.info;
    const std::uint32_t T = info.tileSize;
    const std::uint64_t tilesX = info.levels[0].tilesX;
    // A key is the tile, then the pixel within it, in as few bits as they
    // need (a tile of at most 4096 x 4096 pixels, the reader's limit, and
    // fewer than 2^40 tiles fit 64 bits); after every tile's keys, the
    // points looked up in their own space.
    const int pixelBits = std::bit_width(std::uint64_t(T) * T - 1);
    const std::uint64_t kNoTile = (tilesX * info.levels[0].tilesY) << pixelBits;
    for (std::size_t i = 0; i < n; ++i) {
        std::uint64_t key = kNoTile;
        double rx = 0.0, ry = 0.0, z = 0.0;
        bool inside = false;
        try {
            inside = toRaster(info, space, points[i], rx, ry, z);
        } catch (...) {
            inside = false;  // looked up again below, which records the failure
        }
        if (inside && rx >= 0.0 && ry >= 0.0 && rx < static_cast<double>(info.width) &&
            ry < static_cast<double>(info.height))
        {
            // A tile's points are taken in the order its records and arrays
            // lie in memory.
            const std::uint64_t px = static_cast<std::uint64_t>(rx), py = static_cast<std::uint64_t>(ry);
            key = ((py / T) * tilesX + px / T) << pixelBits | ((py % T) * T + px % T);
        }
        batchOrder_[i] = BatchItem{key, i, {rx, ry, z}};
    }
    // A radix sort on the key's bits in use: a few linear passes instead of
    // n log n comparisons, so that ordering costs less than it saves. The
    // fewest passes of digits of at most 12 bits, the digits as even as
    // they can be (a 512² map of 32² tiles: two passes of 9 bits).
    constexpr int kMaxDigitBits = 12;
    const int keyBits = std::bit_width(kNoTile);
    const int passes = (keyBits + kMaxDigitBits - 1) / kMaxDigitBits;
    const int digitBits = passes == 0 ? 0 : (keyBits + passes - 1) / passes;
    const std::uint64_t digitMask = (std::uint64_t(1) << digitBits) - 1;
    std::uint32_t counts[1u << kMaxDigitBits];
    for (int shift = 0; shift < keyBits; shift += digitBits) {
        std::fill(counts, counts + digitMask + 1, 0u);
        for (std::size_t i = 0; i < n; ++i) ++counts[(batchOrder_[i].key >> shift) & digitMask];
        std::uint32_t start = 0;
        for (std::uint64_t d = 0; d <= digitMask; ++d) start += std::exchange(counts[d], start);
        for (std::size_t i = 0; i < n; ++i) batchScratch_[counts[(batchOrder_[i].key >> shift) & digitMask]++] = batchOrder_[i];
        batchOrder_.swap(batchScratch_);
    }
    for (std::size_t j = 0; j < n; ++j) {
        const std::size_t i = batchOrder_[j].index;
        bool ok;
        if (batchOrder_[j].key != kNoTile) {
            ok = tryAt(map, LookupSpace::raster, batchOrder_[j].raster, options, results[i]);
        } else {
            ok = tryAt(map, space, points[i], options, results[i]);
        }
        if (!ok) ++failures;
    }
    return failures;
}

DSM_NAMESPACE_END
