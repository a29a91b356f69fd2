// Deep OpenEXR samples and visibility functions (spec/exr-interop.md
// sections 2 to 4).
//
// A map's pixel is a piecewise-linear visibility V(z); a deep EXR pixel is a
// list of samples whose transmittance is exponential inside each volume
// sample. Export turns vertical steps into point samples and sloped segments
// into volume samples, subdividing a segment until the chord and the
// exponential agree within a bound; import evaluates the (possibly messy)
// samples exactly in log space between their fronts and backs, and places
// chord vertices densely enough for the same kind of bound.
#include "deep_samples.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

// ---------------------------------------------------------------------------
// The chord of an exponential

/// Largest gap between the chord of r^t over t in [0, 1] and r^t itself, with
/// u = -ln r >= 0. The gap 1 - t(1 - r) - r^t peaks where r^t = (1 - r) / u.
double chordGap(double u) {
    if (!(u < std::numeric_limits<double>::infinity())) return 1.0;
    if (u < 1e-4) return u * u / 8.0 - u * u * u / 16.0;  // series; the closed form cancels here
    const double m = -std::expm1(-u);  // 1 - r, exact for small u
    const double tPeak = std::log(u / m) / u;
    return std::max(0.0, 1.0 - tPeak * m - m / u);
}

/// Largest u = -ln(vb / va) of a piece starting at visibility va whose chord
/// gap va * chordGap(u) stays within `bound`; infinity when any drop is fine.
double largestLogDrop(double va, double bound) {
    if (va <= bound) return std::numeric_limits<double>::infinity();
    const double target = bound / va;  // < 1
    // chordGap(u) ~ u^2 / 8 for small u: bracket that guess, then bisect to a
    // relative 1e-7 (finer only makes pieces shorter by nothing one can see).
    const double guess = std::sqrt(8.0 * target);
    double lo = chordGap(0.5 * guess) <= target ? 0.5 * guess : 0.0, hi = 2.0 * guess + 1e-300;
    while (chordGap(hi) <= target) lo = hi, hi *= 2.0;
    for (int i = 0; i < 80 && hi - lo > 1e-7 * hi; ++i) {
        const double mid = 0.5 * (lo + hi);
        (chordGap(mid) <= target ? lo : hi) = mid;
    }
    return lo;
}

/// The next float above z, for pieces that would otherwise not advance.
float nextFloatUp(float z) { return std::nextafter(z, std::numeric_limits<float>::infinity()); }

constexpr int kMaxTracked = 4;  // R, G, B and their mean

// ---------------------------------------------------------------------------
// Export of one function

class SampleBuilder {
public:
    SampleBuilder(int channels, double bound, std::vector<DeepSample>& out)
        : channels_(channels), tracked_(channels == 1 ? 1 : 4), bound_(bound), out_(out) {
        std::fill(std::begin(v_), std::end(v_), 1.0);
    }

    double largestDeviation() const { return largest_; }
    std::uint64_t oneStepExcess() const { return oneStepExcess_; }
    bool allBlack() const {
        for (int c = 0; c < tracked_; ++c)
            if (v_[c] > 0.0) return false;
        return true;
    }

    /// A vertical step at z to `next` (channels() values).
    void step(float z, const double* next) {
        double target[kMaxTracked];
        expand(next, target);
        if (!lower(target)) return;
        emit(z, z, v_, target);
        std::copy(target, target + kMaxTracked, v_);
    }

    /// A linear segment from (z0, current values) to (z1, next).
    void segment(float z0, float z1, const double* next) {
        double target[kMaxTracked];
        expand(next, target);
        if (!lower(target)) return;
        if (!(z1 > z0)) return step(z0, next);
        const double start[kMaxTracked] = {v_[0], v_[1], v_[2], v_[3]};
        double t = 0.0;
        float zAt = z0;
        while (t < 1.0) {
            double va[kMaxTracked], vb[kMaxTracked];
            for (int c = 0; c < tracked_; ++c) va[c] = start[c] + t * (target[c] - start[c]);
            double dt = 1.0 - t;
            for (int c = 0; c < tracked_; ++c) {
                const double slope = target[c] - start[c];
                if (!(slope < 0.0) || va[c] <= 0.0) continue;
                const double u = largestLogDrop(va[c], bound_);
                if (u == std::numeric_limits<double>::infinity()) continue;
                const double vbMin = va[c] * std::exp(-u);
                dt = std::min(dt, (vbMin - va[c]) / slope);
            }
            // The piece ends at a float depth; its values are the map's there.
            const double tWanted = t + dt;
            float zNext = tWanted >= 1.0 ? z1 : static_cast<float>(z0 + tWanted * (double(z1) - double(z0)));
            if (!(zNext > zAt)) zNext = std::min(nextFloatUp(zAt), z1);  // below float resolution: one step
            if (zNext >= z1) zNext = z1;
            auto tOf = [&](float zq) { return zq >= z1 ? 1.0 : (double(zq) - double(z0)) / (double(z1) - double(z0)); };
            auto valuesAt = [&](double tq) {
                for (int c = 0; c < tracked_; ++c) vb[c] = tq >= 1.0 ? target[c] : start[c] + tq * (target[c] - start[c]);
            };
            auto within = [&] {
                for (int c = 0; c < tracked_; ++c)
                    if (exponentialDeviation(va[c], vb[c]) > bound_) return false;
                return true;
            };
            // Rounding to floats (of depth, and of t near 1) can overshoot the
            // wanted end: shorten the piece until it is within the bound.
            valuesAt(tOf(zNext));
            while (!within() && zNext > nextFloatUp(zAt)) {
                float shorter = static_cast<float>(0.5 * (double(zAt) + double(zNext)));
                if (!(shorter > zAt) || !(shorter < zNext)) shorter = std::nextafter(zNext, zAt);
                zNext = shorter;
                valuesAt(tOf(zNext));
            }
            const double tNext = tOf(zNext);
            // A piece one float step long cannot be cut further: its excess
            // lies strictly between two adjacent float depths.
            const bool oneStep = zNext == nextFloatUp(zAt) && !within();
            emit(zAt, zNext, va, vb, oneStep);
            t = tNext;
            zAt = zNext;
        }
        std::copy(target, target + kMaxTracked, v_);
    }

private:
    void expand(const double* values, double* tracked) const {
        if (channels_ == 1) {
            std::fill(tracked, tracked + kMaxTracked, values[0]);
            return;
        }
        for (int c = 0; c < 3; ++c) tracked[c] = values[c];
        tracked[3] = (values[0] + values[1] + values[2]) / 3.0;
    }
    bool lower(const double* target) const {
        for (int c = 0; c < tracked_; ++c)
            if (target[c] < v_[c]) return true;
        return false;
    }
    static float alphaOf(double before, double after) {
        if (!(before > 0.0)) return 1.0f;
        return static_cast<float>(std::clamp(1.0 - after / before, 0.0, 1.0));
    }
    void emit(float z, float zBack, const double* before, const double* after, bool oneStep = false) {
        DeepSample s;
        s.z = z;
        s.zBack = zBack;
        for (int c = 0; c < 3; ++c) s.alphaRGB[static_cast<std::size_t>(c)] = alphaOf(before[c], after[c]);
        s.alpha = alphaOf(before[tracked_ == 1 ? 0 : 3], after[tracked_ == 1 ? 0 : 3]);
        if (zBack > z)
            for (int c = 0; c < tracked_; ++c) {
                const double deviation = exponentialDeviation(before[c], after[c]);
                if (oneStep && deviation > bound_) ++oneStepExcess_;
                else largest_ = std::max(largest_, deviation);
            }
        out_.push_back(s);
    }

    int channels_;
    int tracked_;
    double bound_;
    std::vector<DeepSample>& out_;
    double v_[kMaxTracked];
    double largest_ = 0.0;
    std::uint64_t oneStepExcess_ = 0;
};

std::vector<DeepSample> samplesOf(const VisibilityView& f, double maxDeviation, double* largest,
                                  std::uint64_t* oneStepExcess = nullptr) {
    if (!(maxDeviation > 0.0) || !std::isfinite(maxDeviation))
        throw Error(ErrorCode::argument,
                    concat("deep EXR export: the largest deviation must be a positive number, got ", maxDeviation));
    std::vector<DeepSample> out;
    SampleBuilder builder(f.channels(), maxDeviation, out);
    const std::size_t end = f.lightEnd();
    double values[kMaxChannels];
    for (std::size_t i = 0; i < end && !builder.allBlack(); ++i) {
        for (int c = 0; c < f.channels(); ++c) values[c] = f.value(i, c);
        if (i == 0 || f.z(i) == f.z(i - 1)) builder.step(f.z(i), values);
        else builder.segment(f.z(i - 1), f.z(i), values);
    }
    if (f.layerCount() > 1 && end > 0 && !builder.allBlack()) {  // layer 0 ended because the light was gone
        const double black[kMaxChannels] = {0.0, 0.0, 0.0};
        builder.step(f.z(end - 1), black);
    }
    if (largest) *largest = builder.largestDeviation();
    if (oneStepExcess) *oneStepExcess = builder.oneStepExcess();
    return out;
}

// ---------------------------------------------------------------------------
// Import of one pixel

struct Volume {
    double front, back;
    double rate[kMaxChannels];  // d(ln T)/dz inside the sample, <= 0
};

}  // namespace

std::vector<DeepSample> exr::samplesWithDeviation(const VisibilityView& function, double maxDeviation,
                                                  double& largest, std::uint64_t& oneStepExcess) {
    return samplesOf(function, maxDeviation, &largest, &oneStepExcess);
}

double exponentialDeviation(double v0, double v1) {
    if (!(v0 > 0.0)) return 0.0;
    if (!(v1 > 0.0)) return v0;
    if (v1 >= v0) return 0.0;
    return v0 * chordGap(-std::log(v1 / v0));
}

std::vector<DeepSample> deepSamplesFromVisibility(const VisibilityView& function, double maxDeviation) {
    return samplesOf(function, maxDeviation, nullptr);
}

VisibilityFunction visibilityFromDeepSamples(std::span<const DeepSample> samples, int channels,
                                             double maxLinearError) {
    if (channels != 1 && channels != 3)
        throw Error(ErrorCode::argument, concat("deep samples: channels must be 1 or 3, got ", channels));
    if (!(maxLinearError > 0.0) || !std::isfinite(maxLinearError))
        throw Error(ErrorCode::argument,
                    concat("deep samples: the linearisation error must be a positive number, got ", maxLinearError));
    auto alphaOf = [&](const DeepSample& s, int c) { return channels == 1 ? s.alpha : s.alphaRGB[std::size_t(c)]; };

    // Events: every front and back; point samples and opaque volume fronts
    // are steps, other volumes change the log-slope while they are active.
    std::vector<double> breaks;
    std::vector<std::pair<double, std::array<double, kMaxChannels>>> steps;  // depth, ln(1 - alpha)
    std::vector<Volume> volumes;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const DeepSample& s = samples[i];
        if (!std::isfinite(s.z) || s.z < 0.0f || !std::isfinite(s.zBack))
            throw Error(ErrorCode::argument,
                        concat("sample ", i, ": depth Z ", s.z, " ZBack ", s.zBack, " (must be finite, Z >= 0)"));
        for (int c = 0; c < channels; ++c) {
            const float a = alphaOf(s, c);
            if (!(a >= 0.0f && a <= 1.0f))
                throw Error(ErrorCode::argument, concat("sample ", i, ": alpha ", a, " is outside [0, 1]"));
        }
        std::array<double, kMaxChannels> logT{0.0, 0.0, 0.0};
        bool any = false;
        for (int c = 0; c < channels; ++c) {
            logT[std::size_t(c)] = std::log1p(-double(alphaOf(s, c)));
            any = any || alphaOf(s, c) > 0.0f;
        }
        if (!any) continue;
        breaks.push_back(s.z);
        if (!(s.zBack > s.z)) {
            steps.push_back({s.z, logT});
            continue;
        }
        // An opaque channel is gone just behind the front: a step there.
        Volume v{s.z, s.zBack, {0.0, 0.0, 0.0}};
        std::array<double, kMaxChannels> opaque{0.0, 0.0, 0.0};
        bool anyOpaque = false;
        for (int c = 0; c < channels; ++c) {
            const double lt = logT[std::size_t(c)];
            if (std::isinf(lt)) opaque[std::size_t(c)] = lt, anyOpaque = true;
            else v.rate[c] = lt / (double(s.zBack) - double(s.z));
        }
        if (anyOpaque) steps.push_back({s.z, opaque});
        volumes.push_back(v);
        breaks.push_back(s.zBack);
    }
    std::sort(breaks.begin(), breaks.end());
    breaks.erase(std::unique(breaks.begin(), breaks.end()), breaks.end());
    std::sort(steps.begin(), steps.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

    // Volumes enter and leave the running log-slope at their fronts and backs
    // (both are breakpoints); with none active the slope is exactly 0.
    std::vector<const Volume*> byFront, byBack;
    for (const Volume& v : volumes) byFront.push_back(&v), byBack.push_back(&v);
    std::sort(byFront.begin(), byFront.end(), [](auto* a, auto* b) { return a->front < b->front; });
    std::sort(byBack.begin(), byBack.end(), [](auto* a, auto* b) { return a->back < b->back; });
    std::size_t nextFront = 0, nextBack = 0, active = 0;
    double rate[kMaxChannels] = {0.0, 0.0, 0.0};

    VisibilityFunction out(channels);
    double logT[kMaxChannels] = {0.0, 0.0, 0.0};
    std::size_t nextStep = 0;
    auto push = [&](double z) {
        float v[kMaxChannels];
        for (int c = 0; c < channels; ++c) v[c] = static_cast<float>(std::exp(logT[c]));
        out.append(static_cast<float>(z), v);
    };
    for (std::size_t b = 0; b < breaks.size(); ++b) {
        const double z = breaks[b];
        if (b == 0) {
            push(z);  // V = 1 up to the first event
        } else if (active == 0) {
            push(z);  // flat since the previous breakpoint
        } else {
            // Exponential stretch from the previous breakpoint to z, in chords.
            const double z0 = breaks[b - 1];
            const double start[kMaxChannels] = {logT[0], logT[1], logT[2]};
            double at = z0;
            float zAt = static_cast<float>(z0);
            while (at < z) {
                double dz = z - at;
                for (int c = 0; c < channels; ++c) {
                    if (!(rate[c] < 0.0)) continue;
                    const double u = largestLogDrop(std::exp(logT[c]), maxLinearError);
                    if (u != std::numeric_limits<double>::infinity()) dz = std::min(dz, u / -rate[c]);
                }
                // Chord ends sit on float depths (breakpoints are floats), not
                // past the wanted end; at least one float step.
                float zNext = static_cast<float>(at + dz);
                if (double(zNext) > at + dz) zNext = std::nextafter(zNext, zAt);
                if (!(zNext > zAt)) zNext = nextFloatUp(zAt);
                double next = std::min(double(zNext), z);
                for (int c = 0; c < channels; ++c) logT[c] = start[c] + rate[c] * (next - z0);
                push(next);
                at = next;
                zAt = zNext;
            }
        }
        for (; nextBack < byBack.size() && byBack[nextBack]->back <= z; ++nextBack, --active)
            for (int c = 0; c < channels; ++c) rate[c] -= byBack[nextBack]->rate[c];
        for (; nextFront < byFront.size() && byFront[nextFront]->front <= z; ++nextFront, ++active)
            for (int c = 0; c < channels; ++c) rate[c] += byFront[nextFront]->rate[c];
        for (int c = 0; c < channels; ++c) rate[c] = active == 0 ? 0.0 : std::min(rate[c], 0.0);
        bool stepped = false;
        for (; nextStep < steps.size() && steps[nextStep].first == z; ++nextStep) {
            for (int c = 0; c < channels; ++c) logT[c] += steps[nextStep].second[std::size_t(c)];
            stepped = true;
        }
        if (stepped) push(z);
    }
    return out;
}


DSM_NAMESPACE_END
