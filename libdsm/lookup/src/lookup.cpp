#include "dsm/lookup.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <new>
#include <vector>

#include "dsm/error.h"
#include "pixel_filter.h"
#include "reader_impl.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

constexpr int kMicrocacheTiles = 8;
constexpr std::size_t kHintSlots = 1024;  // direct-mapped per-pixel cursor hints

// One axis of a separable filter: the pixels [first, first + weights.size())
// of a level and their weights.
struct AxisWeights {
    long first = 0;
    std::vector<double> weights;
};

double minimumWidth(PixelFilter filter) { return filter == PixelFilter::Box ? 1.0 : 2.0; }

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
    for (long i = out.first; i <= last; ++i) {
        const double d = (static_cast<double>(i) + 0.5) - c;
        double k = 0.0;
        switch (filter) {
            case PixelFilter::Box: {
                // Overlap of the pixel [i, i+1] with the footprint [c - r, c + r].
                const double lo = std::max(static_cast<double>(i), c - r);
                const double hi = std::min(static_cast<double>(i) + 1.0, c + r);
                k = std::max(0.0, hi - lo);
                break;
            }
            case PixelFilter::Triangle:
                k = detail::triangleWeight(d, r);
                break;
            case PixelFilter::Gaussian:
                k = std::abs(d) < r ? detail::gaussianWeight(d * d, r) : 0.0;
                break;
        }
        out.weights.push_back(k);
    }
}

}  // namespace

struct LookupContext::Impl {
    std::shared_ptr<const DeepShadowMap> map;
    const ImplAccess::Impl<DeepShadowMap>* reader = nullptr;
    LookupFailure failure;

    struct CachedTile {
        unsigned level = ~0u;
        std::uint32_t index = 0;
        std::shared_ptr<const format::DecodedTile> tile;
    };
    CachedTile microcache[kMicrocacheTiles];
    int nextVictim = 0;

    struct Hint {
        std::uint64_t key = ~0ull;
        std::size_t position = 0;
    };
    std::vector<Hint> hints = std::vector<Hint>(kHintSlots);
    std::uint64_t steps = 0;
    AxisWeights wx, wy;

    const format::DecodedTile& tile(unsigned level, std::uint32_t tx, std::uint32_t ty) {
        const std::uint32_t index = ty * reader->info.levels[level].tilesX + tx;
        for (CachedTile& c : microcache)
            if (c.level == level && c.index == index && c.tile) return *c.tile;
        CachedTile& slot = microcache[nextVictim];
        nextVictim = (nextVictim + 1) % kMicrocacheTiles;
        slot.level = level;
        slot.index = index;
        slot.tile = reader->getTile(level, tx, ty);
        return *slot.tile;
    }

    // Filtered visibility of one level; returns the total weight used.
    double filterLevel(unsigned level, double rx, double ry, double z, double width, PixelFilter filter,
                       double out[3], int& pixelsUsed) {
        const LevelInfo& L = reader->info.levels[level];
        const double scale = std::ldexp(1.0, -static_cast<int>(level));
        axisWeights(filter, rx * scale, width, L.width, wx);
        axisWeights(filter, ry * scale, width, L.height, wy);
        const std::uint32_t T = reader->info.tileSize;
        double total = 0.0;
        out[0] = out[1] = out[2] = 0.0;
        for (std::size_t j = 0; j < wy.weights.size(); ++j) {
            const long y = wy.first + static_cast<long>(j);
            if (y < 0 || y >= static_cast<long>(L.height) || wy.weights[j] == 0.0) continue;
            for (std::size_t i = 0; i < wx.weights.size(); ++i) {
                const long x = wx.first + static_cast<long>(i);
                if (x < 0 || x >= static_cast<long>(L.width) || wx.weights[i] == 0.0) continue;
                const double w = wx.weights[i] * wy.weights[j];
                const auto ux = static_cast<std::uint32_t>(x), uy = static_cast<std::uint32_t>(y);
                const format::DecodedTile& t = tile(level, ux / T, uy / T);
                const VisibilityView f = t.pixel(std::size_t(uy % T) * t.width + ux % T);
                double v[3] = {1.0, 1.0, 1.0};
                if (!f.empty()) {
                    const std::uint64_t key = (std::uint64_t(level) << 56) ^ (std::uint64_t(uy) << 28) ^ ux;
                    Hint& h = hints[(key * 0x9E3779B97F4A7C15ull) >> 54];
                    // A remembered segment makes coherent lookups O(1); without one,
                    // start from a binary search rather than walking from the front.
                    std::size_t start = h.position;
                    if (h.key != key) {
                        const auto zs = f.depths().first(f.lightEnd());
                        start = static_cast<std::size_t>(
                            std::upper_bound(zs.begin(), zs.end(), z, [](double q, float zk) { return q < zk; }) -
                            zs.begin());
                    }
                    VisibilityCursor cursor(f, start);
                    cursor.evaluate(z, v);
                    if (f.channels() == 1) v[1] = v[2] = v[0];
                    h.key = key;
                    h.position = cursor.position();
                    steps += cursor.stepsTaken();
                }
                for (int c = 0; c < 3; ++c) out[c] += w * v[c];
                total += w;
                ++pixelsUsed;
            }
        }
        if (total > 0.0)
            for (int c = 0; c < 3; ++c) out[c] /= total;
        return total;
    }
};

LookupContext::LookupContext(std::shared_ptr<const DeepShadowMap> map) : impl_(std::make_unique<Impl>()) {
    if (!map) throw Error(ErrorCode::argument, "lookup: no map given");
    impl_->reader = &ImplAccess::of(*map);
    impl_->map = std::move(map);
}

LookupContext::~LookupContext() = default;

std::uint64_t LookupContext::cursorSteps() const { return impl_->steps; }

LookupResult LookupContext::raster(double rx, double ry, double z, const LookupOptions& options) {
    Impl& s = *impl_;
    const MapInfo& info = s.reader->info;
    if (!std::isfinite(rx) || !std::isfinite(ry) || !std::isfinite(z))
        throw Error(ErrorCode::argument, concat("lookup: point ", rx, ",", ry, " at depth ", z, " is not finite"));
    if (!std::isfinite(options.filterWidth) || options.filterWidth < 0.0)
        throw Error(ErrorCode::argument,
                    concat("lookup: filter width ", options.filterWidth, " is not a finite value >= 0"));
    if (!std::isfinite(options.bias))
        throw Error(ErrorCode::argument, concat("lookup: bias ", options.bias, " is not finite"));
    LookupResult result;
    result.channels = info.channels;
    // Points outside the raster [0, width] x [0, height] are lit (lookup.h),
    // even when a wide footprint would reach pixels inside.
    if (!(rx >= 0.0 && rx <= static_cast<double>(info.width) && ry >= 0.0 && ry <= static_cast<double>(info.height)))
        return result;
    const double zq = z - options.bias;
    const double minWidth = minimumWidth(options.filter);
    const double width = std::max(options.filterWidth, minWidth);
    const unsigned coarsest = static_cast<unsigned>(info.levels.size() - 1);

    unsigned level0, level1;
    double blend;
    if (options.level) {
        level0 = level1 = std::min(*options.level, coarsest);
        blend = 0.0;
    } else {
        const double lambda = std::max(0.0, std::log2(width / minWidth));
        level0 = std::min(static_cast<unsigned>(std::floor(lambda)), coarsest);
        level1 = std::min(level0 + 1, coarsest);
        blend = level1 == level0 ? 0.0 : lambda - std::floor(lambda);
    }
    double a[3], b[3];
    const double w0 = std::max(width * std::ldexp(1.0, -static_cast<int>(level0)), minWidth);
    const double total0 = s.filterLevel(level0, rx, ry, zq, w0, options.filter, a, result.pixelsUsed);
    double total1 = 0.0;
    if (blend > 0.0) {
        const double w1 = std::max(width * std::ldexp(1.0, -static_cast<int>(level1)), minWidth);
        total1 = s.filterLevel(level1, rx, ry, zq, w1, options.filter, b, result.pixelsUsed);
    }
    double bound = 0.0;
    if (total0 > 0.0) bound = info.levels[level0].errorBound;
    if (total1 > 0.0) bound = std::max(bound, info.levels[level1].errorBound);
    for (int c = 0; c < 3; ++c) {
        const double va = total0 > 0.0 ? a[c] : 1.0;
        const double vb = total1 > 0.0 ? b[c] : va;
        result.v[static_cast<std::size_t>(c)] = std::clamp(va + blend * (vb - va), 0.0, 1.0);
    }
    if (total0 <= 0.0 && total1 <= 0.0) result.v = {1.0, 1.0, 1.0};
    result.errorBound = bound;
    return result;
}

LookupResult LookupContext::light(const std::array<double, 3>& p, const LookupOptions& options) {
    const MapInfo& info = impl_->reader->info;
    double rx, ry, z;
    if (!info.camera.lightToRaster(p, static_cast<int>(info.width), static_cast<int>(info.height), rx, ry, z)) {
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            throw Error(ErrorCode::argument,
                        concat("lookup: light-space point ", p[0], ",", p[1], ",", p[2], " is not finite"));
        LookupResult lit;
        lit.channels = info.channels;
        return lit;  // behind a perspective light
    }
    return raster(rx, ry, z, options);
}

LookupResult LookupContext::world(const std::array<double, 3>& p, const LookupOptions& options) {
    return light(impl_->reader->info.camera.worldToLightSpace(p), options);
}

namespace {

// Keeps why a lookup failed; a message that cannot be stored is left empty.
void recordFailure(LookupFailure& failure, ErrorCode code, const char* message) noexcept {
    failure.code = code;
    try {
        failure.message = message;
    } catch (...) {
        failure.message.clear();
    }
}

// Runs a throwing lookup; on failure records why and gives the documented
// failure value (lookup.h) instead.
template <class Lookup>
bool lookupWithoutThrowing(LookupFailure& failure, int channels, LookupResult& result, Lookup&& lookup) noexcept {
    try {
        result = lookup();
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
    result = LookupResult{};
    result.channels = channels;
    result.errorBound = 1.0;
    return false;
}

}  // namespace

bool LookupContext::tryRaster(double rx, double ry, double z, const LookupOptions& options,
                              LookupResult& result) noexcept {
    return lookupWithoutThrowing(impl_->failure, impl_->reader->info.channels, result,
                                 [&] { return raster(rx, ry, z, options); });
}

bool LookupContext::tryLight(const std::array<double, 3>& p, const LookupOptions& options,
                             LookupResult& result) noexcept {
    return lookupWithoutThrowing(impl_->failure, impl_->reader->info.channels, result,
                                 [&] { return light(p, options); });
}

bool LookupContext::tryWorld(const std::array<double, 3>& p, const LookupOptions& options,
                             LookupResult& result) noexcept {
    return lookupWithoutThrowing(impl_->failure, impl_->reader->info.channels, result,
                                 [&] { return world(p, options); });
}

const LookupFailure& LookupContext::lastFailure() const noexcept { return impl_->failure; }

DSM_NAMESPACE_END
