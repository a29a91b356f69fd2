#include "dsm/value_step.h"

#include <algorithm>
#include <cmath>

DSM_NAMESPACE_BEGIN

namespace {

// Share of the tolerance: the step is at most an eighth of it, so the
// compressor keeps at least 15/16 of the tolerance. On the default hair ball
// an eighth stores 1.1 % fewer bytes than a quarter (whose compressor keeps
// 7/8 and writes 8 % more vertices); bench/COMPONENTS.md, "Tile coding".
constexpr double kStepShare = 0.125;
constexpr int kFinestStepExponent = 24;  // multiples of 2^-24 up to 1 are exact float32

}  // namespace

double valueStep(double tolerance) {
    if (!std::isfinite(tolerance) || !(tolerance > 0.0)) return 0.0;
    const double limit = tolerance * kStepShare;
    if (limit < std::ldexp(1.0, -kFinestStepExponent)) return 0.0;
    int exponent = 0;
    std::frexp(limit, &exponent);  // limit = m * 2^exponent, m in [0.5, 1)
    const int k = std::max(1, 1 - exponent);  // 2^-k is the largest power of two <= limit
    return std::ldexp(1.0, -k);
}

double compressorTolerance(double tolerance) { return tolerance - 0.5 * valueStep(tolerance); }

VisibilityFunction roundValues(const VisibilityView& f, double step) {
    VisibilityFunction out(f.channels(), f.hasCounts());
    roundValues(f, step, out);
    return out;
}

void roundValues(const VisibilityView& f, double step, VisibilityFunction& out) {
    out.reset(f.channels(), f.hasCounts());
    if (f.empty()) return;
    const int channels = f.channels();
    float values[kMaxChannels];
    out.reserve(f.size());
    std::size_t nextLayer = 1;
    for (std::size_t i = 0; i < f.size(); ++i) {
        if (nextLayer < f.layerCount() && i == f.layerBegin(nextLayer)) {
            out.beginLayer();
            ++nextLayer;
        }
        for (int c = 0; c < channels; ++c) {
            const float v = f.value(i, c);
            values[c] =
                step > 0.0 ? static_cast<float>(std::round(static_cast<double>(v) / step) * step) : v;
        }
        out.append(f.z(i), values, f.count(i));
    }
}

DSM_NAMESPACE_END
