#include "dsm/sweep.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

// Heap entry: the depth of an input's next vertex, and the input index. Ties
// are broken by index so the order of floating-point updates is fixed.
struct Event {
    float z;
    std::uint32_t input;
};
bool earlier(const Event& a, const Event& b) { return a.z < b.z || (a.z == b.z && a.input < b.input); }

// Restores the min-heap order (earliest event on top) below position i after
// heap[i] changed: the next vertex of the input on top replaces it in one
// sift-down, where a pop and a push would sift twice.
void siftDown(std::vector<Event>& heap, std::size_t i) {
    const std::size_t n = heap.size();
    const Event moving = heap[i];
    for (;;) {
        std::size_t child = 2 * i + 1;
        if (child >= n) break;
        if (child + 1 < n && earlier(heap[child + 1], heap[child])) ++child;
        if (!earlier(heap[child], moving)) break;
        heap[i] = heap[child];
        i = child;
    }
    heap[i] = moving;
}

// The running slope sum carries rounding errors of up to 2^-53 times the
// magnitudes that went through it since it was last computed exactly. Once
// those are this many times larger than the sum itself (a large slope term
// removed again, perhaps long ago), recompute it exactly.
constexpr double kCancellationLimit = 1e6;

}  // namespace

struct Sweeper::Impl {
    std::vector<double> w;
    std::vector<std::size_t> next;
    std::vector<double> slope;
    std::vector<std::uint32_t> sloped;
    std::vector<std::uint32_t> slopedAt;
    std::vector<unsigned char> atZero;
    std::vector<Event> heap;  // a binary min-heap under earlier(): the next event on top

    // Input is VisibilityFunction or VisibilityView (the same accessors).
    template <class Input>
    std::optional<float> run(Span<const Input> inputs, Span<const double> weights, int channels, VertexSink& sink) {
        // The channel count as a constant lets the compiler unroll the
        // per-channel loops (the arithmetic stays the same).
        return channels == 1 ? runWith<Input, 1>(inputs, weights, channels, sink)
                             : runWith<Input, kMaxChannels>(inputs, weights, channels, sink);
    }
    // `channels` is NC when valid (checked here, like the rest).
    template <class Input, std::size_t NC>
    std::optional<float> runWith(Span<const Input> inputs, Span<const double> weights, int channels,
                                 VertexSink& sink);
};

Sweeper::Sweeper() : impl_(std::make_unique<Impl>()) {}
Sweeper::~Sweeper() = default;
Sweeper::Sweeper(Sweeper&&) noexcept = default;
Sweeper& Sweeper::operator=(Sweeper&&) noexcept = default;

std::optional<float> Sweeper::sweep(Span<const VisibilityFunction> inputs, Span<const double> weights, int channels,
                                    VertexSink& sink) {
    return impl_->run(inputs, weights, channels, sink);
}

std::optional<float> Sweeper::sweep(Span<const VisibilityView> inputs, Span<const double> weights, int channels,
                                    VertexSink& sink) {
    return impl_->run(inputs, weights, channels, sink);
}

std::optional<float> sweep(Span<const VisibilityFunction> inputs, Span<const double> weights, int channels,
                           VertexSink& sink) {
    return Sweeper().sweep(inputs, weights, channels, sink);
}

template <class Input, std::size_t NC>
std::optional<float> Sweeper::Impl::runWith(Span<const Input> inputs, Span<const double> weights, int channels,
                                            VertexSink& sink) {
    if (channels != 1 && channels != kMaxChannels)
        throw Error(ErrorCode::argument, detail::concat("sweep: channel count ", channels, " is not 1 or 3"));
    if (inputs.size() != weights.size())
        throw Error(ErrorCode::argument,
                    detail::concat("sweep: ", inputs.size(), " inputs but ", weights.size(), " weights"));
    if (inputs.size() > UINT32_MAX) throw Error(ErrorCode::argument, "sweep: too many inputs");
    double weightSum = 0.0;
    for (std::size_t k = 0; k < inputs.size(); ++k) {
        if (!std::isfinite(weights[k]) || weights[k] < 0.0)
            throw Error(ErrorCode::argument,
                        detail::concat("sweep: weight ", weights[k], " of input ", k, " is not finite and >= 0"));
        if (inputs[k].channels() != channels)
            throw Error(ErrorCode::argument, detail::concat("sweep: input ", k, " has ", inputs[k].channels(),
                                                            " channels, expected ", channels));
        if (inputs[k].layerCount() != 1)
            throw Error(ErrorCode::argument, detail::concat("sweep: input ", k, " has ", inputs[k].layerCount(),
                                                            " layers; the sweep averages single-layer functions"));
        weightSum += weights[k];
    }
    if (inputs.empty()) return std::nullopt;
    if (!(weightSum > 0.0) || !std::isfinite(weightSum))
        throw Error(ErrorCode::argument,
                    detail::concat("sweep: the weights sum to ", weightSum, ", not a positive finite value"));

    const std::size_t n = inputs.size();
    constexpr std::size_t nc = NC;
    w.resize(n);
    for (std::size_t k = 0; k < n; ++k) w[k] = weights[k] / weightSum;
    next.assign(n, 0);
    slope.assign(n * nc, 0.0);  // current slope of each input, per channel
    // Inputs whose current segment slopes (in any channel of positive weight):
    // an exact recomputation of the slope sum only needs these, and when there
    // are none the sum is exactly 0. Kept in a list with swap-removal.
    sloped.clear();
    slopedAt.assign(n, UINT32_MAX);
    // Inputs of positive weight whose current value is exactly 0, per channel:
    // when all are, the average is exactly 0 too (blocked light stays blocked,
    // without the rounding residue of the running sum).
    atZero.assign(n * nc, 0);
    std::size_t zeroCount[kMaxChannels] = {0, 0, 0};
    std::size_t positive = 0;
    for (std::size_t k = 0; k < n; ++k) positive += w[k] > 0.0;

    // Inputs of weight 0 take part too: they add nothing to the value, but
    // their depths and sample counts belong to the output.
    heap.clear();
    for (std::size_t k = 0; k < n; ++k)
        if (!inputs[k].empty()) heap.push_back({inputs[k].z(0), static_cast<std::uint32_t>(k)});
    std::sort(heap.begin(), heap.end(), earlier);  // sorted is a heap

    double value[kMaxChannels] = {1.0, 1.0, 1.0};
    double outSlope[kMaxChannels] = {0.0, 0.0, 0.0};
    double lastEmitted[kMaxChannels] = {1.0, 1.0, 1.0};
    double left[kMaxChannels];
    double slopeMagnitude[kMaxChannels] = {0.0, 0.0, 0.0};  // through outSlope since it was exact
    double zCurrent = 0.0;

    while (!heap.empty()) {
        const float z = heap.front().z;
        for (std::size_t c = 0; c < nc; ++c) {
            left[c] = value[c] + outSlope[c] * (static_cast<double>(z) - zCurrent);
            left[c] = std::clamp(left[c], 0.0, lastEmitted[c]);
            value[c] = left[c];
        }
        zCurrent = z;

        std::uint64_t count = 0;
        while (!heap.empty() && heap.front().z == z) {
            const std::size_t k = heap.front().input;
            const Input& f = inputs[k];
            const std::size_t first = next[k];
            std::size_t last = first;
            count += f.count(first);
            while (last + 1 < f.size() && f.z(last + 1) == z) count += f.count(++last);
            const bool more = last + 1 < f.size();
            for (std::size_t c = 0; c < nc; ++c) {
                const int ch = static_cast<int>(c);
                const double before = first == 0 ? 1.0 : f.value(first, ch);
                const double after = f.value(last, ch);
                value[c] += w[k] * (after - before);
                const double newSlope =
                    more ? (static_cast<double>(f.value(last + 1, ch)) - after) /
                               (static_cast<double>(f.z(last + 1)) - static_cast<double>(z))
                         : 0.0;
                double& s = slope[k * nc + c];
                const double change = w[k] * (newSlope - s);
                if (change != 0.0) {
                    outSlope[c] += change;
                    slopeMagnitude[c] += std::abs(change) + std::abs(outSlope[c]);
                }
                s = newSlope;
                if (w[k] > 0.0 && (after == 0.0) != static_cast<bool>(atZero[k * nc + c])) {
                    atZero[k * nc + c] = after == 0.0;
                    if (after == 0.0)
                        ++zeroCount[c];
                    else
                        --zeroCount[c];
                }
            }
            bool isSloped = false;
            for (std::size_t c = 0; c < nc; ++c) isSloped = isSloped || (w[k] > 0.0 && slope[k * nc + c] != 0.0);
            if (isSloped && slopedAt[k] == UINT32_MAX) {
                slopedAt[k] = static_cast<std::uint32_t>(sloped.size());
                sloped.push_back(static_cast<std::uint32_t>(k));
            } else if (!isSloped && slopedAt[k] != UINT32_MAX) {
                const std::uint32_t moved = sloped.back();
                sloped[slopedAt[k]] = moved;
                slopedAt[moved] = slopedAt[k];
                sloped.pop_back();
                slopedAt[k] = UINT32_MAX;
            }
            next[k] = last + 1;
            if (more) {
                heap.front() = {f.z(last + 1), static_cast<std::uint32_t>(k)};
            } else {
                heap.front() = heap.back();
                heap.pop_back();
            }
            if (!heap.empty()) siftDown(heap, 0);
        }

        bool step = false;
        for (std::size_t c = 0; c < nc; ++c) {
            if (sloped.empty()) {
                outSlope[c] = 0.0;
                slopeMagnitude[c] = 0.0;
            } else if (slopeMagnitude[c] > kCancellationLimit * std::abs(outSlope[c])) {
                double exact = 0.0;
                for (std::uint32_t k : sloped) exact += w[k] * slope[k * nc + c];
                outSlope[c] = exact;
                slopeMagnitude[c] = std::abs(exact);
            }
            outSlope[c] = std::min(outSlope[c], 0.0);
            value[c] = std::clamp(value[c], 0.0, left[c]);
            if (zeroCount[c] == positive) {
                value[c] = 0.0;
                outSlope[c] = 0.0;
            }
            if (value[c] != left[c]) step = true;
        }
        if (count > UINT32_MAX)
            throw Error(ErrorCode::limit, detail::concat("sweep: ", count, " samples at depth ", z,
                                                         " exceed the 2^32 - 1 a vertex holds"));
        const std::uint32_t count32 = static_cast<std::uint32_t>(count);
        if (!sink.push(z, left, step ? 0u : count32)) return z;
        if (step && !sink.push(z, value, count32)) return z;
        std::copy(value, value + nc, lastEmitted);
    }
    return std::nullopt;
}

DSM_NAMESPACE_END
