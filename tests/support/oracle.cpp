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

std::vector<ExactVertex> exactVertices(const VisibilityFunction& f, std::size_t layer) {
    std::vector<ExactVertex> out;
    const std::size_t b = f.layerBegin(layer), e = f.layerEnd(layer);
    for (std::size_t i = b; i < e;) {
        std::size_t last = i;
        while (last + 1 < e && f.z(last + 1) == f.z(i)) ++last;
        ExactVertex v{f.z(i), {}, {}};
        for (int c = 0; c < f.channels(); ++c) {
            v.left[c] = i == b ? 1.0 : f.value(i, c);
            v.right[c] = f.value(last, c);
        }
        out.push_back(v);
        i = last + 1;
    }
    return out;
}

namespace {

// leftLimit / valueAt by binary search over one layer.
double fastLeft(const VisibilityFunction& f, double z, int c, std::size_t layer) {
    const std::size_t b = f.layerBegin(layer), e = f.layerEnd(layer);
    const auto d = f.depths();
    const std::size_t k = static_cast<std::size_t>(
        std::lower_bound(d.begin() + static_cast<std::ptrdiff_t>(b), d.begin() + static_cast<std::ptrdiff_t>(e), z,
                         [](float zk, double q) { return zk < q; }) -
        d.begin());
    if (k == b) return 1.0;
    if (k == e) return f.value(e - 1, c);
    if (f.z(k) == z) return f.value(k, c);
    return lerp(f.z(k - 1), f.value(k - 1, c), f.z(k), f.value(k, c), z);
}

double fastValue(const VisibilityFunction& f, double z, int c, std::size_t layer) {
    const std::size_t b = f.layerBegin(layer), e = f.layerEnd(layer);
    const auto d = f.depths();
    const std::size_t k = static_cast<std::size_t>(
        std::upper_bound(d.begin() + static_cast<std::ptrdiff_t>(b), d.begin() + static_cast<std::ptrdiff_t>(e), z,
                         [](double q, float zk) { return q < zk; }) -
        d.begin());
    if (k == b) return 1.0;
    if (k == e) return f.value(e - 1, c);
    return lerp(f.z(k - 1), f.value(k - 1, c), f.z(k), f.value(k, c), z);
}

}  // namespace

double maxErrorExact(std::span<const ExactVertex> exact, const VisibilityFunction& approx, int channels,
                     std::size_t layer) {
    if (layer >= approx.layerCount()) return exact.empty() ? 0.0 : 1.0;
    double worst = 0.0;
    auto check = [&](double z, const double* ref, bool left) {
        for (int c = 0; c < channels; ++c) {
            const int ca = std::min(c, approx.channels() - 1);
            const double a = left ? fastLeft(approx, z, ca, layer) : fastValue(approx, z, ca, layer);
            worst = std::max(worst, std::abs(a - ref[c]));
        }
    };
    const double ones[kMaxChannels] = {1.0, 1.0, 1.0};
    for (std::size_t i = 0; i < exact.size(); ++i) {
        const ExactVertex& v = exact[i];
        check(v.z, v.left, true);
        check(v.z, v.right, false);
        if (i == 0 && v.z > 0.0) check(0.5 * v.z, ones, false);
        if (i + 1 < exact.size()) {
            const ExactVertex& w = exact[i + 1];
            const double zm = 0.5 * (v.z + w.z);
            double mid[kMaxChannels];
            for (int c = 0; c < channels; ++c) mid[c] = lerp(v.z, v.right[c], w.z, w.left[c], zm);
            if (zm > v.z && zm < w.z) check(zm, mid, false);
        } else {
            check(2.0 * v.z + 1.0, v.right, false);
        }
    }
    // Vertices of approx that fall between exact vertices.
    for (std::size_t i = approx.layerBegin(layer); i < approx.layerEnd(layer); ++i) {
        const double z = approx.z(i);
        const auto it = std::upper_bound(exact.begin(), exact.end(), z,
                                         [](double q, const ExactVertex& x) { return q < x.z; });
        double ref[kMaxChannels];
        if (it == exact.begin()) {
            check(z, ones, false);
        } else if (it == exact.end()) {
            check(z, (it - 1)->right, false);
        } else if ((it - 1)->z != z) {
            for (int c = 0; c < channels; ++c) ref[c] = lerp((it - 1)->z, (it - 1)->right[c], it->z, it->left[c], z);
            check(z, ref, false);
        }
    }
    return worst;
}

VisibilityFunction randomMonotone(std::mt19937_64& rng, std::size_t vertices, int channels, bool withCounts,
                                  const RandomShape& shape) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::uniform_int_distribution<std::uint32_t> countDist(0, shape.maxCount);
    std::uniform_int_distribution<int> gridSteps(1, 4);
    VisibilityFunction f(channels, withCounts);
    float z = shape.depthGrid > 0.0f ? shape.depthGrid * static_cast<float>(gridSteps(rng) - 1)
                                     : static_cast<float>(unit(rng) * shape.maxGap);
    float v[kMaxChannels] = {1.0f, 1.0f, 1.0f};
    for (std::size_t i = 0; i < vertices; ++i) {
        if (i > 0 && unit(rng) >= shape.stepProbability)
            z += shape.depthGrid > 0.0f ? shape.depthGrid * static_cast<float>(gridSteps(rng))
                                        : static_cast<float>(1e-3 + unit(rng) * shape.maxGap);
        for (int c = 0; c < channels; ++c) {
            if (unit(rng) < 0.5) continue;
            double next = v[c] * (0.6 + 0.4 * unit(rng));
            if (unit(rng) < shape.zeroProbability) next = 0.0;
            v[c] = std::min(v[c], static_cast<float>(next));
        }
        f.append(z, v, withCounts ? countDist(rng) : 0u);
    }
    return f;
}

double rayTransmittance(const SampleRay& ray, double z, int channel, bool leftLimit) {
    double tau = 1.0;
    for (const SurfaceHit& h : ray.hits)
        if (leftLimit ? h.z < z : h.z <= z) tau *= 1.0 - static_cast<double>(h.opacity[static_cast<std::size_t>(channel)]);
    std::vector<VolumeSample> s(ray.volume.begin(), ray.volume.end());
    // Samples at one depth keep their order: the first ends the segment before,
    // the last starts the one after.
    std::stable_sort(s.begin(), s.end(), [](const VolumeSample& a, const VolumeSample& b) { return a.z < b.z; });
    if (s.empty() || z <= s.front().z) return tau;
    double depth = 0.0, previousTau = 1.0;
    for (std::size_t i = 1; i < s.size(); ++i) {
        const double za = s[i - 1].z, zb = s[i].z;
        depth += (zb - za) * (static_cast<double>(s[i - 1].extinction) + s[i].extinction) / 2.0;
        const double t = std::exp(-depth);
        if (z < zb) return tau * lerp(za, previousTau, zb, t, z);
        previousTau = t;
    }
    return tau * previousTau;
}

bool RecordingSink::push(float z, const double* values, std::uint32_t count) {
    if (z > refuseBeyond) return false;
    Vertex v{z, {}, count};
    for (int c = 0; c < channels; ++c) v.v[static_cast<std::size_t>(c)] = values[c];
    vertices.push_back(v);
    return true;
}

}  // namespace dsm::test
