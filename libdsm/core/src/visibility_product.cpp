#include "dsm/visibility_product.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "dsm/compressor.h"
#include "dsm/error.h"
#include "mipmap.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

constexpr double kMinInterpolationError = 0x1p-20;
// A segment whose float32 depths cannot take more vertices stops subdividing
// anyway; this only caps the work on a pathological segment.
constexpr std::uint64_t kMaxSubdivisions = 4096;

// A piecewise-linear function with values in double: the exact product so
// far (its vertices are what the compressor will see).
struct DenseFunction {
    int channels = 1;
    std::vector<float> z;
    std::vector<double> v;  // vertex-major
    std::vector<std::uint64_t> counts;
    std::size_t size() const { return z.size(); }
    double value(std::size_t i, int c) const { return v[i * static_cast<std::size_t>(channels) + static_cast<std::size_t>(c)]; }
};

DenseFunction lightCentre(const VisibilityView& factor, int channels) {
    const VisibilityFunction f = lightCentreFunction(factor, channels, true);
    DenseFunction out;
    out.channels = channels;
    out.z.assign(f.depths().begin(), f.depths().end());
    out.v.assign(f.allValues().begin(), f.allValues().end());
    out.counts.assign(f.counts().begin(), f.counts().end());
    return out;
}

using Values = std::array<double, kMaxChannels>;

// Walks a function in depth order with the evaluation rule of
// VisibilityFunction::evaluate (right-continuous, 1 before the first vertex).
class Walker {
public:
    explicit Walker(const DenseFunction& f) : f_(f) {}
    bool done() const { return next_ >= f_.size(); }
    float nextDepth() const { return f_.z[next_]; }

    // The left limit at depth d, which lies beyond every vertex passed so far
    // and not beyond the next one.
    Values before(double d) const {
        Values out{1.0, 1.0, 1.0};
        const int C = f_.channels;
        if (next_ == 0) return out;
        if (next_ >= f_.size()) {
            for (int c = 0; c < C; ++c) out[c] = f_.value(f_.size() - 1, c);
            return out;
        }
        if (f_.z[next_] == d) {
            for (int c = 0; c < C; ++c) out[c] = f_.value(next_, c);
            return out;
        }
        const double z0 = f_.z[next_ - 1], z1 = f_.z[next_];
        const double t = (d - z0) / (z1 - z0);
        for (int c = 0; c < C; ++c) {
            const double a = f_.value(next_ - 1, c), b = f_.value(next_, c);
            out[c] = a + (b - a) * t;
        }
        return out;
    }

    // Passes every vertex at depth d; returns the sum of their counts and
    // sets `after` to the value at d (the last of them), or leaves it.
    std::uint64_t pass(float d, Values& after) {
        std::uint64_t counted = 0;
        bool moved = false;
        while (next_ < f_.size() && f_.z[next_] == d) {
            counted += f_.counts[next_];
            ++next_;
            moved = true;
        }
        if (moved)
            for (int c = 0; c < f_.channels; ++c) after[c] = f_.value(next_ - 1, c);
        return counted;
    }

private:
    const DenseFunction& f_;
    std::size_t next_ = 0;
};

// The product of two functions of the same channel count, and the largest
// chord error of its linear pieces against the exact (piecewise-quadratic)
// product.
class PairProduct {
public:
    PairProduct(int channels, double maxError) : maxError_(maxError) { out_.channels = channels; }

    DenseFunction run(const DenseFunction& a, const DenseFunction& b) {
        const int C = out_.channels;
        Walker wa(a), wb(b);
        Values rightA{1.0, 1.0, 1.0}, rightB{1.0, 1.0, 1.0};
        float previous = 0.0f;
        bool started = false;
        while (!wa.done() || !wb.done()) {
            float d = std::numeric_limits<float>::infinity();
            if (!wa.done()) d = std::min(d, wa.nextDepth());
            if (!wb.done()) d = std::min(d, wb.nextDepth());
            const Values leftA = wa.before(d), leftB = wb.before(d);
            if (started) subdivide(previous, d, rightA, leftA, rightB, leftB);
            emit(d, leftA, leftB, 0);
            rightA = leftA;
            rightB = leftB;
            const std::uint64_t counted = wa.pass(d, rightA) + wb.pass(d, rightB);
            bool changed = false;
            for (int c = 0; c < C; ++c) changed = changed || rightA[c] * rightB[c] != leftA[c] * leftB[c];
            if (changed) emit(d, rightA, rightB, counted);
            else out_.counts.back() += counted;
            previous = d;
            started = true;
        }
        return std::move(out_);
    }

    double worstError() const { return worst_; }

private:
    void emit(float z, const Values& a, const Values& b, std::uint64_t count) {
        const int C = out_.channels;
        for (int c = 0; c < C; ++c) {
            // Clamping and the running minimum only undo rounding in the
            // interpolation (e.g. 1 - 1e-30 rounds to 1): the product of
            // non-increasing functions in [0, 1] is one as well.
            double p = std::clamp(a[c] * b[c], 0.0, 1.0);
            p = std::min(p, running_[c]);
            running_[c] = p;
            out_.v.push_back(p);
        }
        out_.z.push_back(z);
        out_.counts.push_back(count);
    }

    // Inside (z0, z1) both factors are linear: from a0 to a1 and b0 to b1.
    void subdivide(float z0, float z1, const Values& a0, const Values& a1, const Values& b0, const Values& b1) {
        const int C = out_.channels;
        double curvature = 0.0;  // max over channels of |dA dB|
        Values da{}, db{};
        for (int c = 0; c < C; ++c) {
            da[c] = a1[c] - a0[c];
            db[c] = b1[c] - b0[c];
            curvature = std::max(curvature, std::abs(da[c] * db[c]));
        }
        if (curvature == 0.0) return;  // one factor is constant: the product is linear
        // A 1% margin keeps the pieces within the limit after their depths
        // are rounded to float32 (on all but very short segments).
        const double wanted = std::ceil(std::sqrt(curvature / (4.0 * 0.99 * maxError_)));
        const std::uint64_t pieces = wanted >= double(kMaxSubdivisions) ? kMaxSubdivisions
                                                                         : std::max<std::uint64_t>(1, std::uint64_t(wanted));
        const double width = double(z1) - double(z0);
        double tPrevious = 0.0;
        float zPrevious = z0;
        for (std::uint64_t k = 1; k < pieces; ++k) {
            const float z = static_cast<float>(double(z0) + width * double(k) / double(pieces));
            if (!(z > zPrevious && z < z1)) continue;  // float32 depths too close: a wider piece
            const double t = (double(z) - double(z0)) / width;
            Values a{}, b{};
            for (int c = 0; c < C; ++c) {
                a[c] = a0[c] + da[c] * t;
                b[c] = b0[c] + db[c] * t;
            }
            emit(z, a, b, 0);
            worst_ = std::max(worst_, curvature * (t - tPrevious) * (t - tPrevious) / 4.0);
            tPrevious = t;
            zPrevious = z;
        }
        worst_ = std::max(worst_, curvature * (1.0 - tPrevious) * (1.0 - tPrevious) / 4.0);
    }

    double maxError_;
    DenseFunction out_;
    Values running_{1.0, 1.0, 1.0};
    double worst_ = 0.0;
};

// Depth of the last vertex of layer k, where that layer became opaque within
// its map's tolerance (for a layer that another follows).
float layerEndDepth(const VisibilityView& f, std::size_t k) { return f.z(f.layerEnd(k) - 1); }

// The restart of a factor at depth d (spec/merge.md, "Layers"): the
// visibility of what lies strictly beyond d as if the light started afresh
// there, rebuilt from the factor's layers. Within the layer whose span holds d
// it is that layer divided by its value at d (1 at a layer boundary, where
// the restart is the next layer itself); where that layer ends, the next one
// continues scaled by what was left at the end, and so on. A channel that
// holds 0 at d stays 0. When the last layer lets no light reach d in any
// channel, what lies beyond is nothing (V = 1) if the factor has layers to
// spare (its build would have begun another), else unknown: returns false.
bool restartAt(const VisibilityView& f, bool spareLayers, float d, int channels, DenseFunction& out) {
    out = DenseFunction{};
    out.channels = channels;
    const int own = f.channels();
    const std::size_t layers = f.layerCount();
    std::size_t k = 0;
    while (k + 1 < layers && !(d < layerEndDepth(f, k))) ++k;

    Values scale{}, running{};
    bool passes = false;
    for (int c = 0; c < channels; ++c) {
        const double base = f.evaluateLayer(k, d, std::min(c, own - 1));
        scale[c] = base > 0.0 ? 1.0 / base : 0.0;
        running[c] = base > 0.0 ? 1.0 : 0.0;
        passes = passes || base > 0.0;
    }
    if (!passes) {
        if (!spareLayers) return false;
        out.z.push_back(d);
        out.v.assign(static_cast<std::size_t>(channels), 1.0);
        out.counts.push_back(0);
        return true;
    }
    // The running minimum undoes rounding in the ratios, which are exact
    // products of non-increasing values.
    const auto emit = [&](float z, const Values& v, std::uint64_t count) {
        for (int c = 0; c < channels; ++c) {
            running[c] = std::min(running[c], std::clamp(v[c], 0.0, 1.0));
            out.v.push_back(running[c]);
        }
        out.z.push_back(z);
        out.counts.push_back(count);
    };
    // A vertex at d itself: d may fall inside a sloped segment.
    emit(d, running, 0);
    std::size_t i = f.layerBegin(k);
    while (i < f.layerEnd(k) && !(f.z(i) > d)) ++i;  // steps at d belong to the earlier layer
    // A layer is 1 up to its first vertex: a step there, not a slope from d.
    if (i == f.layerBegin(k) && i < f.layerEnd(k)) emit(f.z(i), running, 0);
    for (;;) {
        for (; i < f.layerEnd(k); ++i) {
            Values v{};
            for (int c = 0; c < channels; ++c) v[c] = scale[c] * f.value(i, std::min(c, own - 1));
            emit(f.z(i), v, f.count(i));
        }
        if (k + 1 >= layers) break;
        bool left = false;
        for (int c = 0; c < channels; ++c) {
            scale[c] *= f.value(f.layerEnd(k) - 1, std::min(c, own - 1));
            left = left || scale[c] > 0.0;
        }
        if (!left) break;  // opaque at the layer's end: 0 from there on
        ++k;
        i = f.layerBegin(k);
        // The next layer is 1 up to its first vertex: a step there, not a slope.
        emit(f.z(i), running, 0);
    }
    return true;
}

// The product of `parts` (at least one), folded pairwise; adds the chord
// errors of the pairwise products to `interpolation`.
DenseFunction foldProduct(std::vector<DenseFunction>& parts, double maxError, double& interpolation) {
    DenseFunction product = std::move(parts.front());
    for (std::size_t i = 1; i < parts.size(); ++i) {
        PairProduct pair(product.channels, maxError);
        product = pair.run(product, parts[i]);
        interpolation += pair.worstError();
    }
    return product;
}

// The first vertex at or below the tolerance in every channel (where the
// compressor ends a layer), or size() when there is none.
std::size_t firstBlocked(const DenseFunction& f, double tolerance) {
    for (std::size_t i = 0; i < f.size(); ++i) {
        bool blocked = true;
        for (int c = 0; c < f.channels && blocked; ++c) blocked = f.value(i, c) <= tolerance;
        if (blocked) return i;
    }
    return f.size();
}

}  // namespace

VisibilityProduct multiplyVisibility(Span<const VisibilityView> factors, const VisibilityProductOptions& options) {
    if (!std::isfinite(options.tolerance) || options.tolerance < 0.0)
        throw Error(ErrorCode::argument,
                    concat("visibility product: tolerance ", options.tolerance, " is not a finite value >= 0"));
    if (options.maxInterpolationError &&
        !(std::isfinite(*options.maxInterpolationError) && *options.maxInterpolationError > 0.0))
        throw Error(ErrorCode::argument, concat("visibility product: interpolation error ",
                                                *options.maxInterpolationError, " is not a finite value > 0"));
    if (options.maxLayers < 1 || options.maxLayers > 255)
        throw Error(ErrorCode::argument,
                    concat("visibility product: layer count ", options.maxLayers, " is not in [1, 255]"));
    if (!options.factorLayers.empty() && options.factorLayers.size() != factors.size())
        throw Error(ErrorCode::argument, concat("visibility product: ", options.factorLayers.size(),
                                                " factor layer counts for ", factors.size(), " factors"));
    for (std::size_t i = 0; i < options.factorLayers.size(); ++i)
        if (options.factorLayers[i] < 1 || options.factorLayers[i] > 255)
            throw Error(ErrorCode::argument, concat("visibility product: factor ", i, " layer count ",
                                                    options.factorLayers[i], " is not in [1, 255]"));
    const double maxError =
        options.maxInterpolationError.value_or(std::max(options.tolerance / 16.0, kMinInterpolationError));
    int channels = 1;
    for (std::size_t i = 0; i < factors.size(); ++i) {
        const VisibilityView& f = factors[i];
        if (f.channels() != 1 && f.channels() != 3)
            throw Error(ErrorCode::argument,
                        concat("visibility product: factor ", i, " has ", f.channels(), " channels, not 1 or 3"));
        if (!f.empty()) channels = std::max(channels, f.channels());
    }

    VisibilityProduct result;
    result.function = VisibilityFunction(1, options.keepCounts);
    bool any = false;
    for (const VisibilityView& f : factors) any = any || !f.empty();
    if (!any) return result;

    std::vector<const VisibilityView*> present;
    std::vector<std::size_t> budgets;
    for (std::size_t i = 0; i < factors.size(); ++i) {
        if (factors[i].empty()) continue;  // V = 1: the product is unchanged
        present.push_back(&factors[i]);
        budgets.push_back(static_cast<std::size_t>(options.factorLayers.empty() ? options.maxLayers
                                                                                : options.factorLayers[i]));
    }
    std::vector<DenseFunction> parts;
    for (const VisibilityView* f : present) parts.push_back(lightCentre(*f, channels));
    double interpolation = 0.0;
    DenseFunction product = foldProduct(parts, maxError, interpolation);
    result.interpolationError = interpolation;

    CompressorOptions compression;
    compression.tolerance = options.tolerance;
    compression.channels = channels;
    compression.keepCounts = options.keepCounts;
    compression.allowMonochrome = options.allowMonochrome;
    // Layers are cut here rather than by the compressor, by the same rule:
    // layer 0 (the light-centre product) has no vertices past its end for
    // the compressor to refuse when an input's light-centre function ends
    // there, yet the inputs' deeper layers may continue.
    Compressor compressor(compression);
    for (int layer = 0;; ++layer) {
        const std::size_t blocked =
            layer + 1 < options.maxLayers ? firstBlocked(product, options.tolerance) : product.size();
        // The layer takes every vertex up to and at the blocked depth.
        std::size_t end = blocked;
        while (end < product.size() && product.z[end] == product.z[blocked]) ++end;
        for (std::size_t i = 0; i < end; ++i) {
            const std::uint64_t count = std::min<std::uint64_t>(product.counts[i], UINT32_MAX);
            compressor.push(product.z[i], product.v.data() + i * static_cast<std::size_t>(channels),
                            static_cast<std::uint32_t>(count));
        }
        result.productVertices += end;
        if (blocked == product.size()) break;
        const float cutDepth = product.z[blocked];
        // Layer `layer` ends at cutDepth: the next one is the product of the
        // factors' restarts there.
        parts.assign(present.size(), DenseFunction{});
        bool known = true;
        for (std::size_t i = 0; i < present.size() && known; ++i)
            known = restartAt(*present[i], present[i]->layerCount() < budgets[i], cutDepth, channels, parts[i]);
        if (!known) break;
        interpolation = 0.0;
        DenseFunction next = foldProduct(parts, maxError, interpolation);
        const bool beyond = std::any_of(next.z.begin(), next.z.end(), [&](float z) { return z > cutDepth; });
        if (!beyond) break;  // nothing lies behind: no further layer, as in a build
        result.interpolationError = std::max(result.interpolationError, interpolation);
        product = std::move(next);
        compressor.beginLayer();
    }
    result.function = compressor.finish();
    return result;
}

DSM_NAMESPACE_END
