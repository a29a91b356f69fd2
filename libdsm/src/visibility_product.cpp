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

namespace dsm {

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

}  // namespace

VisibilityProduct multiplyVisibility(std::span<const VisibilityView> factors, const VisibilityProductOptions& options) {
    if (!std::isfinite(options.tolerance) || options.tolerance < 0.0)
        throw Error(concat("visibility product: tolerance ", options.tolerance, " is not a finite value >= 0"));
    if (std::isnan(options.maxInterpolationError) || std::isinf(options.maxInterpolationError))
        throw Error(concat("visibility product: interpolation error ", options.maxInterpolationError, " is not finite"));
    const double maxError = options.maxInterpolationError > 0.0
                                ? options.maxInterpolationError
                                : std::max(options.tolerance / 16.0, kMinInterpolationError);
    int channels = 1;
    for (std::size_t i = 0; i < factors.size(); ++i) {
        const VisibilityView& f = factors[i];
        if (f.channels() != 1 && f.channels() != 3)
            throw Error(concat("visibility product: factor ", i, " has ", f.channels(), " channels, not 1 or 3"));
        if (!f.empty()) channels = std::max(channels, f.channels());
    }

    VisibilityProduct result;
    result.function = VisibilityFunction(1, options.keepCounts);
    bool any = false;
    for (const VisibilityView& f : factors) any = any || !f.empty();
    if (!any) return result;

    DenseFunction product;
    bool first = true;
    for (const VisibilityView& f : factors) {
        if (f.empty()) continue;  // V = 1: the product is unchanged
        DenseFunction factor = lightCentre(f, channels);
        if (first) {
            product = std::move(factor);
            first = false;
            continue;
        }
        PairProduct pair(channels, maxError);
        product = pair.run(product, factor);
        result.interpolationError += pair.worstError();
    }

    CompressorOptions compression;
    compression.tolerance = options.tolerance;
    compression.channels = channels;
    compression.keepCounts = options.keepCounts;
    compression.allowMonochrome = options.allowMonochrome;
    Compressor compressor(compression);
    for (std::size_t i = 0; i < product.size(); ++i) {
        const std::uint64_t count = std::min<std::uint64_t>(product.counts[i], UINT32_MAX);
        compressor.push(product.z[i], product.v.data() + i * static_cast<std::size_t>(channels),
                        static_cast<std::uint32_t>(count));
    }
    result.productVertices = product.size();
    result.function = compressor.finish();
    return result;
}

}  // namespace dsm
