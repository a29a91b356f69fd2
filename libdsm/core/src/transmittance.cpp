#include "dsm/transmittance.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "dsm/error.h"
#include "insertion_sort.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

void checkHits(std::span<const SurfaceHit> hits, int channels) {
    for (std::size_t i = 0; i < hits.size(); ++i) {
        const SurfaceHit& h = hits[i];
        if (!std::isfinite(h.z) || h.z < 0.0f)
            throw Error(ErrorCode::argument,
                        detail::concat("surface hit ", i, ": depth ", h.z, " is not a finite value >= 0"));
        for (int c = 0; c < channels; ++c) {
            const float o = h.opacity[static_cast<std::size_t>(c)];
            if (!(o >= 0.0f && o <= 1.0f))
                throw Error(ErrorCode::argument,
                            detail::concat("surface hit ", i, " channel ", c, ": opacity ", o, " is outside [0, 1]"));
        }
    }
}

void checkVolume(std::span<const VolumeSample> volume) {
    for (std::size_t i = 0; i < volume.size(); ++i) {
        const VolumeSample& s = volume[i];
        if (!std::isfinite(s.z) || s.z < 0.0f)
            throw Error(ErrorCode::argument,
                        detail::concat("volume sample ", i, ": depth ", s.z, " is not a finite value >= 0"));
        if (!std::isfinite(s.extinction) || s.extinction < 0.0f)
            throw Error(ErrorCode::argument, detail::concat("volume sample ", i, ": extinction ", s.extinction,
                                                            " is not a finite value >= 0"));
    }
}

// Hits and volume samples ordered by their depths alone.
constexpr auto byDepth = [](const auto& a, const auto& b) { return a.z < b.z; };

// sortByDepth() of more items than insertion suits, out of line, so that the
// few of the common case are sorted where the caller is.
template <class T>
[[gnu::noinline]] void sortManyByDepth(T* items, std::size_t n, std::vector<std::uint32_t>& order,
                                       std::vector<T>& scratch) {
    if (std::is_sorted(items, items + n, byDepth)) return;
    order.resize(n);
    for (std::uint32_t i = 0; i < n; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
        return items[a].z < items[b].z || (items[a].z == items[b].z && a < b);
    });
    scratch.resize(n);
    for (std::size_t i = 0; i < n; ++i) scratch[i] = items[order[i]];
    std::copy(scratch.begin(), scratch.end(), items);
}

// Sorts items[0, n) by depth, equal depths in their given order (what
// std::stable_sort does, without the buffer it allocates on every call):
// through a permutation sorted by (depth, index) and a scratch copy.
// A ray's few hits (the common case) are sorted in place by insertion, which
// moves an item only past deeper ones and so keeps equal depths in order too.
template <class T>
void sortByDepth(T* items, std::size_t n, std::vector<std::uint32_t>& order, std::vector<T>& scratch) {
    constexpr std::size_t kInsertionLimit = 16;
    if (n <= kInsertionLimit) detail::insertionSort(items, n, byDepth);
    else sortManyByDepth(items, n, order, scratch);
}

// Copies the hits beyond zStart that block some light (an opacity not 0 in
// some of the NC channels) to kept[0, count) and returns count; `valid`
// becomes false when some hit fails checkHits(). One pass without a branch
// a hit: a sample's few hits from the sampler are valid, and checking them
// one test at a time cost as much as the rest of their transmittance.
template <std::size_t NC>
std::size_t keepHits(std::span<const SurfaceHit> hits, float zStart, SurfaceHit* kept, bool& valid) {
    std::size_t count = 0;
    bool allValid = true;
    for (const SurfaceHit& h : hits) {
        bool blocks = false;
        allValid &= std::isfinite(h.z) & (h.z >= 0.0f);
        for (std::size_t c = 0; c < NC; ++c) {
            const float o = h.opacity[c];
            allValid &= (o >= 0.0f) & (o <= 1.0f);
            blocks |= o != 0.0f;
        }
        kept[count] = h;
        count += std::size_t((h.z > zStart) & blocks);
    }
    valid = allValid;
    return count;
}

}  // namespace

struct TransmittanceBuilder::Impl {
    std::vector<SurfaceHit> hits, hitScratch;  // hits grown, never shrunk: sortedHits() says how many
    std::vector<VolumeSample> volume, volumeScratch;
    std::vector<std::uint32_t> order;
    std::vector<double> volumeTau;
    VisibilityFunction function;  // a ray with volume, on its way to a SweepInput

    // Checks the ray and returns those of its hits beyond zStart that block
    // some light, sorted by depth (equal depths in the ray's order), kept in
    // `hits`.
    std::span<const SurfaceHit> sortedHits(const SampleRay& ray, int channels, float zStart) {
        if (channels != 1 && channels != kMaxChannels)
            throw Error(ErrorCode::argument, detail::concat("transmittance: channel count ", channels, " is not 1 or 3"));
        if (hits.size() < ray.hits.size()) hits.resize(ray.hits.size());
        bool valid = true;
        const std::size_t count = channels == 1 ? keepHits<1>(ray.hits, zStart, hits.data(), valid)
                                                : keepHits<kMaxChannels>(ray.hits, zStart, hits.data(), valid);
        if (!valid) checkHits(ray.hits, channels);  // throws, naming the first hit at fault
        checkVolume(ray.volume);
        sortByDepth(hits.data(), count, order, hitScratch);
        return {hits.data(), count};
    }

    // What build() emits for hits alone, two vertices at each distinct depth
    // (tau before, tau after), and what SweepInput::assignWith() makes of them:
    // one step a depth, its height after - before from the float values, flat
    // after it, and its hits' count.
    template <std::size_t NC>
    static void prepareSteps(std::span<const SurfaceHit> hits, bool withCounts, SweepInput& out) {
        // Room for a depth a hit, at most what they take (counting them
        // first cost a pass over the hits).
        out.reserveDepths(hits.size(), static_cast<int>(NC));
        out.slopes_ = false;
        double surfaceTau[NC];
        float before[NC];
        bool atZero[NC];
        for (std::size_t c = 0; c < NC; ++c) {
            surfaceTau[c] = 1.0;
            before[c] = 1.0f;
            atZero[c] = false;
        }
        std::size_t h = 0, d = 0;
        for (; h < hits.size(); ++d) {
            const float z = hits[h].z;
            std::uint32_t hitCount = 0;
            for (; h < hits.size() && hits[h].z == z; ++h, ++hitCount)
                for (std::size_t c = 0; c < NC; ++c) surfaceTau[c] *= 1.0 - static_cast<double>(hits[h].opacity[c]);
            SweepInput::Step step{z, withCounts ? hitCount : 0u, 0u};
            double* valueChange = out.numberData_ + d * 2 * NC;
            for (std::size_t c = 0; c < NC; ++c) {
                const float after = std::min(static_cast<float>(surfaceTau[c]), before[c]);
                valueChange[c] = static_cast<double>(after) - static_cast<double>(before[c]);
                valueChange[NC + c] = 0.0;
                if ((after == 0.0f) != atZero[c]) {
                    atZero[c] = after == 0.0f;
                    step.flags |= (atZero[c] ? SweepInput::kReachesZero : SweepInput::kLeavesZero) << (2 * c);
                }
                before[c] = after;
            }
            out.stepData_[d] = step;
        }
        out.size_ = d;
        out.vertices_ = 2 * d;
    }
};

TransmittanceBuilder::TransmittanceBuilder() : impl_(std::make_unique<Impl>()) {}
TransmittanceBuilder::~TransmittanceBuilder() = default;
TransmittanceBuilder::TransmittanceBuilder(TransmittanceBuilder&&) noexcept = default;
TransmittanceBuilder& TransmittanceBuilder::operator=(TransmittanceBuilder&&) noexcept = default;

VisibilityFunction transmittance(const SampleRay& ray, int channels, bool withCounts, float zStart) {
    VisibilityFunction out;  // build() gives it the channels and counts asked for
    TransmittanceBuilder().build(ray, channels, withCounts, zStart, out);
    return out;
}

void TransmittanceBuilder::build(const SampleRay& ray, int channels, bool withCounts, float zStart, SweepInput& out) {
    if (!ray.volume.empty()) {
        build(ray, channels, withCounts, zStart, impl_->function);
        out.assign(impl_->function);
        return;
    }
    if (channels == 1 && ray.hits.size() <= SweepInput::kInlineDepths) {
        // A mono ray of a few hits, most of a map's: kept and sorted on the
        // stack, the same steps as below without the calls and the checks
        // of sizes that cost more than the few hits themselves.
        SurfaceHit kept[SweepInput::kInlineDepths];
        bool valid = true;
        const std::size_t count = keepHits<1>(ray.hits, zStart, kept, valid);
        if (!valid) checkHits(ray.hits, channels);  // throws, naming the first hit at fault
        sortByDepth(kept, count, impl_->order, impl_->hitScratch);
        Impl::prepareSteps<1>(std::span<const SurfaceHit>(kept, count), withCounts, out);
        return;
    }
    const std::span<const SurfaceHit> hits = impl_->sortedHits(ray, channels, zStart);
    if (channels == 1)
        Impl::prepareSteps<1>(hits, withCounts, out);
    else
        Impl::prepareSteps<kMaxChannels>(hits, withCounts, out);
}

void TransmittanceBuilder::build(const SampleRay& ray, int channels, bool withCounts, float zStart,
                                 VisibilityFunction& out) {
    const std::span<const SurfaceHit> hits = impl_->sortedHits(ray, channels, zStart);

    std::vector<VolumeSample>& volume = impl_->volume;
    volume.assign(ray.volume.begin(), ray.volume.end());
    sortByDepth(volume.data(), volume.size(), impl_->order, impl_->volumeScratch);
    // Keep only the volume beyond zStart, cutting a straddling segment at zStart.
    {
        const auto firstBeyond = std::find_if(volume.begin(), volume.end(),
                                              [&](const VolumeSample& s) { return s.z > zStart; });
        if (firstBeyond == volume.end()) {
            volume.clear();
        } else if (firstBeyond != volume.begin()) {
            const VolumeSample& a = *(firstBeyond - 1);
            const VolumeSample& b = *firstBeyond;
            const double t = (static_cast<double>(zStart) - a.z) / (static_cast<double>(b.z) - a.z);
            const VolumeSample cut{zStart, static_cast<float>(a.extinction + t * (b.extinction - a.extinction))};
            *(firstBeyond - 1) = cut;
            volume.erase(volume.begin(), firstBeyond - 1);
        }
    }

    // Volume transmittance at every volume sample, from the accumulated optical
    // depth (one exp per sample keeps the product accurate and underflow exact).
    std::vector<double>& volumeTau = impl_->volumeTau;
    volumeTau.assign(volume.size(), 1.0);
    double opticalDepth = 0.0;
    for (std::size_t i = 1; i < volume.size(); ++i) {
        const double dz = static_cast<double>(volume[i].z) - volume[i - 1].z;
        if (dz > 0.0) opticalDepth += dz * (static_cast<double>(volume[i - 1].extinction) + volume[i].extinction) * 0.5;
        volumeTau[i] = std::exp(-opticalDepth);
    }

    if (out.channels() == channels && out.hasCounts() == withCounts)
        out.clear();
    else
        out = VisibilityFunction(channels, withCounts);
    out.reserve(2 * hits.size() + volume.size());
    double surfaceTau[kMaxChannels] = {1.0, 1.0, 1.0};
    float emitted[kMaxChannels];
    std::size_t h = 0, s = 0;
    auto emit = [&](float z, double tauV, std::uint32_t count) {
        for (int c = 0; c < channels; ++c) {
            float v = static_cast<float>(surfaceTau[c] * tauV);
            // Rounding is monotone, but guard the invariant explicitly.
            if (!out.empty()) v = std::min(v, out.value(out.size() - 1, c));
            emitted[c] = v;
        }
        out.append(z, emitted, count);
    };

    while (h < hits.size() || s < volume.size()) {
        const float z = (s < volume.size() && (h >= hits.size() || volume[s].z <= hits[h].z)) ? volume[s].z
                                                                                              : hits[h].z;
        // Volume transmittance at z: exact at a sample, linear between samples.
        double tauV;
        bool atSample = false;
        std::uint32_t volumeCount = 0;
        while (s < volume.size() && volume[s].z == z) {
            // A volume step of positive length ends here (samples repeated at
            // one depth mark a jump of extinction, not a step).
            if (s > 0 && volume[s].z > volume[s - 1].z) ++volumeCount;
            atSample = true;
            ++s;
        }
        if (atSample) {
            tauV = volumeTau[s - 1];
        } else if (s == 0) {
            tauV = 1.0;
        } else if (s == volume.size()) {
            tauV = volumeTau.back();
        } else {
            const double t = (static_cast<double>(z) - volume[s - 1].z) /
                             (static_cast<double>(volume[s].z) - volume[s - 1].z);
            tauV = volumeTau[s - 1] + t * (volumeTau[s] - volumeTau[s - 1]);
        }
        // Every depth here is a volume sample or a hit. At a hit this is the
        // vertex before the step: it holds tau(z-) and keeps the function flat
        // (or on the volume's slope) up to z, instead of interpolating from the
        // previous vertex to the value after the step.
        emit(z, tauV, withCounts ? volumeCount : 0);

        std::uint32_t hitCount = 0;
        while (h < hits.size() && hits[h].z == z) {
            for (int c = 0; c < channels; ++c)
                surfaceTau[c] *= 1.0 - static_cast<double>(hits[h].opacity[static_cast<std::size_t>(c)]);
            ++hitCount;
            ++h;
        }
        if (hitCount > 0) emit(z, tauV, withCounts ? hitCount : 0);
    }
}

DSM_NAMESPACE_END
