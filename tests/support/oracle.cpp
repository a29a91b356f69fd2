#include "oracle.h"

#include <algorithm>
#include <cmath>

namespace dsm::test {

namespace {

double lerp(double za, double va, double zb, double vb, double z) {
    return va + (z - za) / (zb - za) * (vb - va);
}

}  // namespace

double leftLimit(const VisibilityFunction& f, double z, int channel, std::size_t layer) {
    const std::size_t b = f.layerBegin(layer), e = f.layerEnd(layer);
    std::size_t k = b;
    while (k < e && f.z(k) < z) ++k;  // first vertex with z_k >= z
    if (k == b) return 1.0;
    if (k == e) return f.value(e - 1, channel);
    if (f.z(k) == z) return f.value(k, channel);
    return lerp(f.z(k - 1), f.value(k - 1, channel), f.z(k), f.value(k, channel), z);
}

double valueAt(const VisibilityFunction& f, double z, int channel, std::size_t layer) {
    const std::size_t b = f.layerBegin(layer), e = f.layerEnd(layer);
    std::size_t k = b;
    while (k < e && f.z(k) <= z) ++k;  // first vertex with z_k > z
    if (k == b) return 1.0;
    if (k == e) return f.value(e - 1, channel);
    return lerp(f.z(k - 1), f.value(k - 1, channel), f.z(k), f.value(k, channel), z);
}

std::vector<ExactVertex> naiveAverage(std::span<const VisibilityFunction> inputs, std::span<const double> weights,
                                      int channels) {
    std::vector<double> depths;
    double total = 0.0;
    for (std::size_t k = 0; k < inputs.size(); ++k) {
        total += weights[k];
        for (float z : inputs[k].depths()) depths.push_back(z);
    }
    std::sort(depths.begin(), depths.end());
    depths.erase(std::unique(depths.begin(), depths.end()), depths.end());
    std::vector<ExactVertex> out;
    out.reserve(depths.size());
    for (double z : depths) {
        ExactVertex v{z, {}, {}};
        for (int c = 0; c < channels; ++c) {
            double l = 0.0, r = 0.0;
            for (std::size_t k = 0; k < inputs.size(); ++k) {
                l += weights[k] * leftLimit(inputs[k], z, c);
                r += weights[k] * valueAt(inputs[k], z, c);
            }
            v.left[c] = l / total;
            v.right[c] = r / total;
        }
        out.push_back(v);
    }
    return out;
}

static double maxErrorImpl(const VisibilityFunction& exact, const VisibilityFunction& approx, std::size_t layer,
                           bool mapChannels) {
    std::vector<double> probes;
    for (std::size_t i = exact.layerBegin(layer); i < exact.layerEnd(layer); ++i) probes.push_back(exact.z(i));
    if (layer < approx.layerCount())
        for (std::size_t i = approx.layerBegin(layer); i < approx.layerEnd(layer); ++i) probes.push_back(approx.z(i));
    std::sort(probes.begin(), probes.end());
    probes.erase(std::unique(probes.begin(), probes.end()), probes.end());
    const std::size_t n = probes.size();
    for (std::size_t i = 0; i + 1 < n; ++i) probes.push_back(0.5 * (probes[i] + probes[i + 1]));
    if (n > 0) probes.push_back(probes[n - 1] * 2.0 + 1.0);
    double worst = 0.0;
    const int channels = mapChannels ? exact.channels() : std::min(exact.channels(), approx.channels());
    for (double z : probes) {
        for (int c = 0; c < channels; ++c) {
            const int ca = std::min(c, approx.channels() - 1);
            worst = std::max(worst, std::abs(leftLimit(exact, z, c, layer) - leftLimit(approx, z, ca, layer)));
            worst = std::max(worst, std::abs(valueAt(exact, z, c, layer) - valueAt(approx, z, ca, layer)));
        }
    }
    return worst;
}

double maxError(const VisibilityFunction& exact, const VisibilityFunction& approx, std::size_t layer) {
    return maxErrorImpl(exact, approx, layer, false);
}

double maxErrorAllChannels(const VisibilityFunction& exact, const VisibilityFunction& approx, std::size_t layer) {
    return maxErrorImpl(exact, approx, layer, true);
}

}  // namespace dsm::test
