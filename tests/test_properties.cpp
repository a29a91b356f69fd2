// Property tests (rapidcheck): the compressor's guarantee (greedy and
// centred), the sweep against its oracle, transmittance against direct
// evaluation, buildVisibility's light-centre bound, and the cursor against
// evaluate(), on random input.
#include <dsm/dsm.h>
#include <gtest/gtest.h>
#include <rapidcheck.h>
#include <rapidcheck/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <tuple>
#include <vector>

#include "oracle.h"

namespace {

using dsm::VisibilityFunction;

// Integers uniform in [min, max) whatever the size parameter: rapidcheck's
// inRange() scales the range with the size, which would leave small cases
// without drops, zeros or opacities. Sizes still set the lengths.
rc::Gen<int> uniform(int min, int max) { return rc::gen::resize(100, rc::gen::inRange(min, max)); }

// One generated vertex: a depth increment in grid units (0 repeats the
// previous depth: a step), a code per channel for how far the value drops,
// and a sample count.
using VertexCode = std::tuple<int, int, int, int, int>;

// Drop codes: 0..399 keep the value (flat stretches, exact ties), 400..999
// scale it down, 1000 drops it to 0.
double dropped(double v, int code) {
    if (code < 400) return v;
    return v * (1.0 - (code - 400) / 600.0);
}

rc::Gen<std::vector<VertexCode>> genCodes() {
    return rc::gen::container<std::vector<VertexCode>>(
        rc::gen::tuple(uniform(0, 4), uniform(0, 1001), uniform(0, 1001), uniform(0, 1001), uniform(0, 4)));
}

// A valid single-layer function from codes. `greyMode`: 0 independent
// channels, 1 identical channels, 2 channels within `spread` of each other.
VisibilityFunction build(const std::vector<VertexCode>& codes, int channels, float grid, int greyMode = 0,
                         float spread = 0.0f) {
    VisibilityFunction f(channels, true);
    double v[3] = {1.0, 1.0, 1.0};
    float z = 0.0f;
    float last[3] = {1.0f, 1.0f, 1.0f};
    for (std::size_t i = 0; i < codes.size(); ++i) {
        const auto& [dz, d0, d1, d2, count] = codes[i];
        if (i > 0) z += grid * static_cast<float>(dz);
        const int drops[3] = {d0, d1, d2};
        float out[3];
        for (int c = 0; c < channels; ++c) {
            v[c] = dropped(v[c], greyMode == 0 ? drops[c] : drops[0]);
            float x = static_cast<float>(v[c]);
            if (greyMode == 2 && c > 0) x = std::max(0.0f, x - spread * static_cast<float>(c) / 2.0f);
            out[c] = std::min(x, last[c]);  // non-increasing as floats too
            last[c] = out[c];
        }
        f.append(z, out, static_cast<std::uint32_t>(count));
    }
    return f;
}

rc::Gen<float> genGrid() { return rc::gen::element(1e-3f, 0.25f, 1.0f, 1000.0f); }

// Tolerances in [0, 1], with the special values 0 and 1 and small ones
// weighted in.
rc::Gen<double> genTolerance() {
    return rc::gen::oneOf(rc::gen::just(0.0), rc::gen::just(1.0),
                          rc::gen::map(uniform(0, 1000001), [](int x) { return x / 1e6; }),
                          rc::gen::map(uniform(0, 1001), [](int x) { return x / 1e5; }));
}

double bound(double eps) { return std::max(eps, 0x1p-25) + 1e-12; }

// The compressor's documented output properties.
void checkCompressed(const VisibilityFunction& f, const VisibilityFunction& g, double eps) {
    RC_ASSERT(dsm::test::maxErrorAllChannels(f, g) <= bound(eps));
    try {
        g.validate();  // values in [0, 1], non-increasing, depths ordered
    } catch (const dsm::Error& e) {
        RC_FAIL(e.what());
    }
    const std::set<float> depths(f.depths().begin(), f.depths().end());
    for (float z : g.depths()) RC_ASSERT(depths.count(z) == 1u);
    RC_ASSERT(g.totalCount() == f.totalCount());
    RC_ASSERT(g.size() <= f.size() + 1);
}

RC_GTEST_PROP(Properties, CompressorBoundMono, ()) {
    const auto codes = *genCodes();
    const float grid = *genGrid();
    const double eps = *genTolerance();
    const VisibilityFunction f = build(codes, 1, grid);
    checkCompressed(f, dsm::compress(f, eps), eps);
}

RC_GTEST_PROP(Properties, CompressorBoundRgb, ()) {
    const auto codes = *genCodes();
    const float grid = *genGrid();
    const double eps = *genTolerance();
    const int greyMode = *uniform(0, 3);
    const float spread = static_cast<float>(eps * *rc::gen::element(0.5, 1.0, 2.0));
    const VisibilityFunction f = build(codes, 3, grid, greyMode, spread);
    const bool allowMono = *rc::gen::arbitrary<bool>();
    const VisibilityFunction g = dsm::compress(f, eps, allowMono);
    checkCompressed(f, g, eps);
    if (!allowMono) RC_ASSERT(g.channels() == 3);
    if (allowMono && f.isMonochrome()) RC_ASSERT(g.channels() == 1);
}

// Centred segments keep the same guarantee, for one channel and for RGB
// (apart, identical or within a spread), the function taken as one run (in
// blocks of eight where segments are long enough) or vertex by vertex.
RC_GTEST_PROP(Properties, CentredCompressorBound, ()) {
    const auto codes = *genCodes();
    const float grid = *genGrid();
    const double eps = *genTolerance();
    const int channels = *rc::gen::element(1, 3);
    const int greyMode = channels == 3 ? *uniform(0, 3) : 0;
    const float spread = static_cast<float>(eps * *rc::gen::element(0.5, 1.0, 2.0));
    const VisibilityFunction f = build(codes, channels, grid, greyMode, spread);
    dsm::CompressorOptions options;
    options.tolerance = eps;
    options.channels = channels;
    options.keepCounts = true;
    options.centred = true;
    dsm::Compressor compressor(options);
    if (*rc::gen::arbitrary<bool>()) {
        RC_ASSERT(compressor.pushValid(f.depths().data(), f.allValues().data(), f.counts().data(), f.size()) ==
                  f.size());
    } else {
        for (std::size_t i = 0; i < f.size(); ++i) RC_ASSERT(compressor.push(f.z(i), f.values(i), f.count(i)));
    }
    checkCompressed(f, compressor.finish(), eps);
}

RC_GTEST_PROP(Properties, CompressorBoundDoubleInput, ()) {
    // Values that are not floats: the 2^-25 term of the bound applies.
    const auto codes = *genCodes();
    const double eps = *genTolerance();
    const int channels = *rc::gen::element(1, 3);
    dsm::CompressorOptions options;
    options.tolerance = eps;
    options.channels = channels;
    options.keepCounts = true;
    dsm::Compressor compressor(options);
    std::vector<dsm::test::ExactVertex> exact;
    double v[3] = {1.0, 1.0, 1.0};
    float z = 0.0f;
    std::uint64_t total = 0;
    for (std::size_t i = 0; i < codes.size(); ++i) {
        const auto& [dz, d0, d1, d2, count] = codes[i];
        if (i > 0) z += 0.1f * static_cast<float>(dz);
        const int drops[3] = {d0, d1, d2};
        for (int c = 0; c < channels; ++c) v[c] = dropped(v[c] * (1.0 - 1e-9 * drops[c]), drops[c]);
        RC_ASSERT(compressor.push(z, v, static_cast<std::uint32_t>(count)));
        total += static_cast<std::uint64_t>(count);
        if (exact.empty() || exact.back().z != z) {
            // The first vertex at a depth is the left limit there (1 before
            // the first vertex of all).
            dsm::test::ExactVertex e{z, {}, {}};
            for (int c = 0; c < channels; ++c) e.left[c] = exact.empty() ? 1.0 : v[c];
            exact.push_back(e);
        }
        for (int c = 0; c < channels; ++c) exact.back().right[c] = v[c];
    }
    const VisibilityFunction g = compressor.finish();
    RC_ASSERT(dsm::test::maxErrorExact(exact, g, channels) <= bound(eps));
    RC_ASSERT(g.totalCount() == total);
}

RC_GTEST_PROP(Properties, SweepMatchesNaiveAverage, ()) {
    const int channels = *rc::gen::element(1, 3);
    const int n = *uniform(1, 13);
    const float grid = *rc::gen::element(0.25f, 0.1f);
    std::vector<VisibilityFunction> inputs;
    std::vector<double> weights;
    for (int k = 0; k < n; ++k) {
        inputs.push_back(build(*rc::gen::resize(30, genCodes()), channels, grid));
        weights.push_back(k == 0 ? *uniform(1, 10) : *uniform(0, 10) * 0.5);
    }
    dsm::test::RecordingSink sink;
    sink.channels = channels;
    RC_ASSERT(!dsm::sweep(inputs, weights, channels, sink).has_value());
    const auto exact = dsm::test::naiveAverage(inputs, weights, channels);
    std::map<float, std::uint64_t> countAt;
    std::uint64_t total = 0;
    for (const VisibilityFunction& f : inputs) {
        for (std::size_t i = 0; i < f.size(); ++i) countAt[f.z(i)] += f.count(i);
        total += f.totalCount();
    }
    std::size_t i = 0;
    double previous[3] = {1.0, 1.0, 1.0};
    std::uint64_t outTotal = 0;
    for (const auto& e : exact) {
        RC_ASSERT(i < sink.vertices.size());
        RC_ASSERT(sink.vertices[i].z == static_cast<float>(e.z));
        std::size_t last = i;
        while (last + 1 < sink.vertices.size() && sink.vertices[last + 1].z == sink.vertices[i].z) ++last;
        RC_ASSERT(last - i <= 1u);
        for (int c = 0; c < channels; ++c) {
            const auto cc = static_cast<std::size_t>(c);
            RC_ASSERT(std::abs(sink.vertices[i].v[cc] - e.left[c]) <= 1e-9);
            RC_ASSERT(std::abs(sink.vertices[last].v[cc] - e.right[c]) <= 1e-9);
            for (std::size_t k = i; k <= last; ++k) {
                RC_ASSERT(sink.vertices[k].v[cc] >= 0.0);
                RC_ASSERT(sink.vertices[k].v[cc] <= previous[c]);
                previous[c] = sink.vertices[k].v[cc];
            }
        }
        RC_ASSERT(sink.vertices[last].count == countAt[static_cast<float>(e.z)]);
        for (std::size_t k = i; k <= last; ++k) outTotal += sink.vertices[k].count;
        i = last + 1;
    }
    RC_ASSERT(i == sink.vertices.size());
    RC_ASSERT(outTotal == total);
}

// Random rays on a coarse depth grid (shared depths, hits on volume samples).
struct Rays {
    std::vector<std::vector<dsm::SurfaceHit>> hits;
    std::vector<std::vector<dsm::VolumeSample>> volumes;
    std::vector<dsm::SampleRay> rays;
    std::uint64_t samples = 0;
};

Rays genRays(int n, int channels) {
    Rays r;
    r.hits.resize(static_cast<std::size_t>(n));
    r.volumes.resize(static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k) {
        const auto hitCodes = *rc::gen::resize(
            10, rc::gen::container<std::vector<std::tuple<int, int, int, int>>>(
                    rc::gen::tuple(uniform(0, 40), uniform(0, 101), uniform(0, 101), uniform(0, 101))));
        for (const auto& [zi, o0, o1, o2] : hitCodes) {
            dsm::SurfaceHit h{0.25f * static_cast<float>(zi), {o0 / 100.0f, o1 / 100.0f, o2 / 100.0f}};
            if (channels == 1) h.opacity = {h.opacity[0], 0.0f, 0.0f};
            r.hits[static_cast<std::size_t>(k)].push_back(h);
            r.samples += channels == 1 ? o0 != 0 : (o0 != 0 || o1 != 0 || o2 != 0);
        }
        const auto volumeCodes = *rc::gen::resize(
            8, rc::gen::container<std::vector<std::pair<int, int>>>(
                   rc::gen::pair(uniform(0, 40), uniform(0, 300))));
        for (const auto& [zi, kappa] : volumeCodes)
            r.volumes[static_cast<std::size_t>(k)].push_back({0.25f * static_cast<float>(zi), kappa / 100.0f});
        // One count per volume step of positive length: distinct sample depths - 1.
        std::vector<int> depths;
        for (const auto& code : volumeCodes) depths.push_back(code.first);
        std::sort(depths.begin(), depths.end());
        depths.erase(std::unique(depths.begin(), depths.end()), depths.end());
        if (!depths.empty()) r.samples += depths.size() - 1;
    }
    for (int k = 0; k < n; ++k)
        r.rays.push_back({r.hits[static_cast<std::size_t>(k)], r.volumes[static_cast<std::size_t>(k)]});
    return r;
}

RC_GTEST_PROP(Properties, TransmittanceMatchesDirectEvaluation, ()) {
    const int channels = *rc::gen::element(1, 3);
    const Rays r = genRays(1, channels);
    const dsm::SampleRay& ray = r.rays[0];
    const VisibilityFunction t = dsm::transmittance(ray, channels, true);
    try {
        t.validate();
    } catch (const dsm::Error& e) {
        RC_FAIL(e.what());
    }
    RC_ASSERT(t.totalCount() == r.samples);
    for (int zi = 0; zi <= 82; ++zi) {
        const double z = 0.125 * zi;  // every grid depth and every midpoint
        for (int c = 0; c < channels; ++c) {
            RC_ASSERT(std::abs(dsm::test::valueAt(t, z, c) - dsm::test::rayTransmittance(ray, z, c)) <= 2e-7);
            RC_ASSERT(std::abs(dsm::test::leftLimit(t, z, c) - dsm::test::rayTransmittance(ray, z, c, true)) <=
                      2e-7);
        }
    }
}

RC_GTEST_PROP(Properties, BuildVisibilityLightCentreBound, ()) {
    const int channels = *rc::gen::element(1, 3);
    const int n = *uniform(1, 9);
    const Rays r = genRays(n, channels);
    std::vector<double> weights;
    for (int k = 0; k < n; ++k) weights.push_back(1.0 + *uniform(0, 4));
    dsm::CompressorOptions options;
    options.tolerance = *rc::gen::element(0.0, 0.01, dsm::autoTolerance(n), 0.3);
    options.channels = channels;
    options.keepCounts = true;
    options.maxLayers = *uniform(1, 5);
    const VisibilityFunction f = dsm::buildVisibility(r.rays, weights, options);
    try {
        f.validate();
    } catch (const dsm::Error& e) {
        RC_FAIL(e.what());
    }
    RC_ASSERT(f.layerCount() <= static_cast<std::size_t>(options.maxLayers));
    RC_ASSERT(f.totalCount() == r.samples);

    // Light-centre visibility: layer 0, then 0 from its last vertex on.
    VisibilityFunction centre(f.channels());
    for (std::size_t i = f.layerBegin(0); i < f.layerEnd(0); ++i) centre.append(f.z(i), f.values(i));
    if (f.layerCount() > 1) {
        const float zeros[3] = {0.0f, 0.0f, 0.0f};
        centre.append(f.z(f.layerEnd(0) - 1), zeros);
    }
    for (double z : {0.0, 1.3, 5.0, 9.9, 20.0})
        RC_ASSERT(std::abs(centre.evaluate(z) - f.evaluate(z)) <= 1e-12);

    // The exact average at every grid depth and midpoint.
    std::vector<dsm::test::ExactVertex> exact;
    double total = 0.0;
    for (double w : weights) total += w;
    for (int zi = 0; zi <= 82; ++zi) {
        const double z = 0.125 * zi;
        dsm::test::ExactVertex e{z, {}, {}};
        for (int c = 0; c < channels; ++c) {
            for (std::size_t k = 0; k < r.rays.size(); ++k) {
                e.left[c] += weights[k] * dsm::test::rayTransmittance(r.rays[k], z, c, true) / total;
                e.right[c] += weights[k] * dsm::test::rayTransmittance(r.rays[k], z, c) / total;
            }
        }
        exact.push_back(e);
    }
    RC_ASSERT(dsm::test::maxErrorExact(exact, centre, channels) <= bound(options.tolerance) + 1e-6);
}

RC_GTEST_PROP(Properties, CursorAgreesWithEvaluate, ()) {
    const VisibilityFunction f = build(*genCodes(), 3, 0.5f);
    const auto queries = *rc::gen::container<std::vector<int>>(uniform(-10, 400));
    dsm::VisibilityCursor cursor(f);
    for (int q : queries) {
        const double z = 0.125 * q;  // vertex depths, midpoints, beyond both ends
        for (int c = 0; c < 3; ++c) {
            RC_ASSERT(std::abs(cursor.evaluate(z, c) - f.evaluate(z, c)) <= 1e-12);
            RC_ASSERT(std::abs(f.evaluate(z, c) - dsm::test::valueAt(f, z, c)) <= 1e-12);
        }
    }
}

}  // namespace
