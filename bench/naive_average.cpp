#include "naive_average.h"

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

namespace dsm::bench {

namespace {

// Linear interpolation on the segment (za, va) -> (zb, vb), za < zb. At z = zb
// this gives vb exactly (t = 1 and vb - va is exact for float inputs).
inline double lerp(double za, double va, double zb, double vb, double z) {
    return va + (z - za) / (zb - za) * (vb - va);
}

// tau(z) from the vertices around index k: 1 before the first vertex, the
// last value after the last one, linear in between.
inline double valueAround(const VisibilityFunction& f, std::size_t k, double z, int c) {
    if (k == 0) return 1.0;
    if (k == f.size()) return f.value(k - 1, c);
    return lerp(f.z(k - 1), f.value(k - 1, c), f.z(k), f.value(k, c), z);
}

}  // namespace

void naiveAverage(std::span<const VisibilityFunction> inputs, std::span<const double> weights, int channels,
                  VertexSink& sink) {
    double weightSum = 0.0;
    for (double w : weights) weightSum += w;

    // Sort all input vertices by depth (with their counts).
    std::vector<std::pair<float, std::uint32_t>> all;
    std::size_t total = 0;
    for (const VisibilityFunction& f : inputs) total += f.size();
    all.reserve(total);
    for (const VisibilityFunction& f : inputs)
        for (std::size_t i = 0; i < f.size(); ++i) all.emplace_back(f.z(i), f.count(i));
    std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

    double left[kMaxChannels], value[kMaxChannels];
    for (std::size_t i = 0; i < all.size();) {
        const float z = all[i].first;
        std::uint64_t count = 0;
        for (; i < all.size() && all[i].first == z; ++i) count += all[i].second;

        // Evaluate all n functions at z: left limit (first vertex with z_k >= z)
        // and value (first vertex with z_k > z, V right-continuous).
        std::fill(left, left + channels, 0.0);
        std::fill(value, value + channels, 0.0);
        for (std::size_t k = 0; k < inputs.size(); ++k) {
            const VisibilityFunction& f = inputs[k];
            const auto zs = f.depths();
            const std::size_t lo = static_cast<std::size_t>(std::lower_bound(zs.begin(), zs.end(), z) - zs.begin());
            const std::size_t hi = static_cast<std::size_t>(std::upper_bound(zs.begin(), zs.end(), z) - zs.begin());
            const double w = weights[k] / weightSum;
            for (int c = 0; c < channels; ++c) {
                left[c] += w * valueAround(f, lo, z, c);
                value[c] += w * valueAround(f, hi, z, c);
            }
        }

        bool step = false;
        for (int c = 0; c < channels; ++c)
            if (value[c] != left[c]) step = true;
        const auto count32 = static_cast<std::uint32_t>(count);
        if (!sink.push(z, left, step ? 0u : count32)) return;
        if (step && !sink.push(z, value, count32)) return;
    }
}

}  // namespace dsm::bench
