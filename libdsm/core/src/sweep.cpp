#include "dsm/sweep.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <iterator>
#include <limits>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#include "dsm/error.h"
#include "event_keys.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

using detail::depthOf;
using detail::eventKey;
using detail::inputOf;

// Replaces the top of the min-heap heap[0, n) by `moving` and restores the
// heap order, bottom-up (Floyd): the hole at the top sinks to a leaf along the
// smaller children, one comparison a level, and `moving` rises from there.
// The input on top usually moves far behind (its next depth comes after most
// others'), so it rarely rises more than a level; sinking it from the top would
// compare twice a level. Keys are unique, so the order of events is that of
// any heap.
void replaceTop(std::uint64_t* heap, std::size_t n, std::uint64_t moving) {
    std::size_t i = 0;
    for (std::size_t child = 1; child < n; child = 2 * i + 1) {
        if (child + 1 < n && heap[child + 1] < heap[child]) ++child;
        heap[i] = heap[child];
        i = child;
    }
    while (i > 0) {
        const std::size_t parent = (i - 1) / 2;
        if (!(moving < heap[parent])) break;
        heap[i] = heap[parent];
        i = parent;
    }
    heap[i] = moving;
}

// Out of line, so that the loops that check counts stay small enough to inline.
[[noreturn, gnu::noinline, gnu::cold]] void throwCountLimit(std::uint64_t count, float z) {
    throw Error(ErrorCode::limit,
                detail::concat("sweep: ", count, " samples at depth ", z, " exceed the 2^32 - 1 a vertex holds"));
}

// The running slope sum carries rounding errors of up to 2^-53 times the
// magnitudes that went through it since it was last computed exactly. Once
// those are this many times larger than the sum itself (a large slope term
// removed again, perhaps long ago), recompute it exactly.
constexpr double kCancellationLimit = 1e6;

// Where `needed` items go: `inside` (room for `room`) when they fit, else
// `heap`, grown by doubling: a worker's inputs soon have room for every
// input they see, and hold little more.
template <class T>
T* storageFor(std::size_t needed, T* inside, std::size_t room, std::unique_ptr<T[]>& heap, std::size_t& capacity) {
    if (needed <= room) return inside;
    if (capacity < needed) {
        capacity = std::max(needed, 2 * capacity);
        heap = std::make_unique_for_overwrite<T[]>(capacity);
    }
    return heap.get();
}

// A SweptVertices' arrays as the sweep appends to them, with room for every
// vertex made ahead: the pointers and the size stay in registers, and a
// vertex costs its stores alone.
template <std::size_t NC>
struct DirectVertices {
    float* z;
    double* values;
    std::uint32_t* counts;
    std::size_t size;
    bool push(float depth, const double* v, std::uint32_t count) {
        z[size] = depth;
        for (std::size_t c = 0; c < NC; ++c) values[size * NC + c] = v[c];
        counts[size] = count;
        ++size;
        return true;
    }
};

}  // namespace

SweepInput::SweepInput(SweepInput&& other) noexcept { *this = std::move(other); }

SweepInput& SweepInput::operator=(SweepInput&& other) noexcept {
    if (this == &other) return *this;
    // The heap arrays move; what lies inside the object is copied, and each
    // pointer follows its data.
    const bool stepsInside = other.stepData_ == other.inlineSteps_;
    const bool numbersInside = other.numberData_ == other.inlineNumbers_;
    std::copy(std::begin(other.inlineSteps_), std::end(other.inlineSteps_), inlineSteps_);
    std::copy(std::begin(other.inlineNumbers_), std::end(other.inlineNumbers_), inlineNumbers_);
    steps_ = std::move(other.steps_);
    numbers_ = std::move(other.numbers_);
    stepCapacity_ = std::exchange(other.stepCapacity_, 0);
    numberCapacity_ = std::exchange(other.numberCapacity_, 0);
    size_ = std::exchange(other.size_, 0);
    vertices_ = std::exchange(other.vertices_, 0);
    channels_ = other.channels_;
    slopes_ = std::exchange(other.slopes_, false);
    stepData_ = stepsInside ? inlineSteps_ : steps_.get();
    numberData_ = numbersInside ? inlineNumbers_ : numbers_.get();
    other.stepData_ = other.inlineSteps_;
    other.numberData_ = other.inlineNumbers_;
    return *this;
}

void SweepInput::assign(const VisibilityView& f) {
    if (f.channels() != 1 && f.channels() != kMaxChannels)
        throw Error(ErrorCode::argument, detail::concat("sweep: an input has ", f.channels(), " channels, not 1 or 3"));
    if (f.layerCount() != 1)
        throw Error(ErrorCode::argument, detail::concat("sweep: an input has ", f.layerCount(),
                                                        " layers; the sweep averages single-layer functions"));
    vertices_ = f.size();
    const Span<const float> z = f.depths();
    std::size_t depths = 0;
    for (std::size_t i = 0; i < z.size(); ++i) depths += i == 0 || z[i] != z[i - 1];
    reserveDepths(depths, f.channels());
    slopes_ = false;
    size_ = channels_ == 1 ? assignWith<1>(f) : assignWith<kMaxChannels>(f);
}

void SweepInput::reserveHeapDepths(std::size_t depths, int channels) {
    channels_ = channels;
    const std::size_t numbers = depths * 2 * static_cast<std::size_t>(channels);
    stepData_ = storageFor(depths, inlineSteps_, kInlineDepths, steps_, stepCapacity_);
    numberData_ = storageFor(numbers, inlineNumbers_, 2 * kInlineDepths, numbers_, numberCapacity_);
}

template <std::size_t NC>
std::size_t SweepInput::assignWith(const VisibilityView& f) {
    const std::size_t n = f.size();
    const float* z = f.depths().data();
    const float* v = f.allValues().data();
    const std::uint32_t* counts = f.hasCounts() ? f.counts().data() : nullptr;
    Step* out = stepData_;
    double* numbers = numberData_;
    // The input's state after the depths read so far, as the sweep sees it.
    bool atZero[NC] = {};
    bool sloping = false;
    std::size_t depths = 0;
    for (std::size_t first = 0; first < n; ++depths) {
        const float depth = z[first];
        if (std::isnan(depth))
            throw Error(ErrorCode::argument, detail::concat("sweep: an input has depth NaN at vertex ", first));
        std::uint64_t count = counts ? counts[first] : 0u;
        std::size_t last = first;
        while (last + 1 < n && z[last + 1] == depth) {
            ++last;
            if (counts) count += counts[last];
        }
        if (count > UINT32_MAX) throwCountLimit(count, depth);
        const bool more = last + 1 < n;
        Step step{depth, static_cast<std::uint32_t>(count), 0u};
        double* valueChange = numbers + depths * 2 * NC;
        double* slopeAfter = valueChange + NC;
        bool slopingAfter = false;
        for (std::size_t c = 0; c < NC; ++c) {
            const double before = first == 0 ? 1.0 : v[first * NC + c];
            const double after = v[last * NC + c];
            valueChange[c] = after - before;
            const double newSlope =
                more ? (static_cast<double>(v[(last + 1) * NC + c]) - after) /
                           (static_cast<double>(z[last + 1]) - static_cast<double>(depth))
                     : 0.0;
            slopeAfter[c] = newSlope;
            slopingAfter = slopingAfter || newSlope != 0.0;
            if ((after == 0.0) != atZero[c]) {
                atZero[c] = after == 0.0;
                step.flags |= (atZero[c] ? kReachesZero : kLeavesZero) << (2 * c);
            }
        }
        if (slopingAfter != sloping) step.flags |= slopingAfter ? kStartsSloping : kStopsSloping;
        slopes_ = slopes_ || slopingAfter;
        sloping = slopingAfter;
        out[depths] = step;
        first = last + 1;
    }
    return depths;
}

struct Sweeper::Impl {
    // The weights of the sweep under way, as given (checked) and their sum.
    // The heap path normalises them into w ahead; the flat path divides
    // each as it gathers its input's steps, the same division.
    Span<const double> givenWeights;
    double weightSum = 0.0;
    std::vector<double> w;
    std::vector<std::size_t> next;
    std::vector<std::uint32_t> sloped;
    std::vector<std::uint32_t> slopedAt;
    std::vector<std::uint64_t> heap;  // a binary min-heap of eventKey()s: the next event on top
    // Inputs of steps alone: every step as an eventKey() of its index, the
    // step, and its change of value times the input's weight.
    std::vector<std::uint64_t> eventKeys;
    std::vector<std::uint64_t> eventScratch;
    std::vector<SweepInput::Step> eventSteps;
    std::vector<double> eventChanges;
    // The inputs given as functions or views, prepared here.
    std::vector<SweepInput> prepared;
    std::vector<const SweepInput*> preparedInputs;

    // Checks the arguments and keeps the weights and their sum. Calls
    // inputValid(k) once for each input k, whatever the weights, and on
    // failure checks again in input order, each weight and then
    // throwIfInvalid(k), so that the error names the first input whose
    // weight or itself is at fault, as one pass of checks would (a pixel's
    // inputs are checked without a branch each). False when there are no
    // inputs (nothing to sweep).
    template <class InputValid, class ThrowIfInvalid>
    bool checkArguments(std::size_t n, Span<const double> weights, int channels, InputValid&& inputValid,
                        ThrowIfInvalid&& throwIfInvalid);

    // Input is VisibilityFunction or VisibilityView (the same accessors).
    template <class Input>
    std::optional<float> runFunctions(Span<const Input> inputs, Span<const double> weights, int channels,
                                      VertexSink& sink) {
        const bool any = checkArguments(
            inputs.size(), weights, channels,
            [&](std::size_t k) { return inputs[k].channels() == channels && inputs[k].layerCount() == 1; },
            [&](std::size_t k) {
                if (inputs[k].channels() != channels)
                    throw Error(ErrorCode::argument, detail::concat("sweep: input ", k, " has ",
                                                                    inputs[k].channels(), " channels, expected ",
                                                                    channels));
                if (inputs[k].layerCount() != 1)
                    throw Error(ErrorCode::argument,
                                detail::concat("sweep: input ", k, " has ", inputs[k].layerCount(),
                                               " layers; the sweep averages single-layer functions"));
            });
        if (!any) return std::nullopt;
        if (prepared.size() < inputs.size()) prepared.resize(inputs.size());  // never shrunk: each keeps its storage
        preparedInputs.clear();
        InputScan scan;
        for (std::size_t k = 0; k < inputs.size(); ++k) {
            prepared[k].assign(VisibilityView(inputs[k]));
            preparedInputs.push_back(&prepared[k]);
            scan.add(prepared[k]);
        }
        return dispatch(Span<const SweepInput* const>(preparedInputs), channels, scan, sink);
    }

    template <class Sink>
    std::optional<float> runPrepared(Span<const SweepInput* const> inputs, Span<const double> weights, int channels,
                                     Sink& sink) {
        // What dispatch() needs, gathered in the same pass over the inputs.
        InputScan scan;
        const bool any = checkArguments(
            inputs.size(), weights, channels,
            [&](std::size_t k) {
                const SweepInput& f = *inputs[k];
                scan.add(f);
                return f.channels() == channels;
            },
            [&](std::size_t k) {
                if (inputs[k]->channels() != channels)
                    throw Error(ErrorCode::argument, detail::concat("sweep: input ", k, " has ",
                                                                    inputs[k]->channels(), " channels, expected ",
                                                                    channels));
            });
        if (!any) return std::nullopt;
        return dispatch(inputs, channels, scan, sink);
    }

    // Whether some input slopes, and their steps in all.
    struct InputScan {
        bool sloped = false;
        std::uint64_t events = 0;
        void add(const SweepInput& f) {
            sloped = sloped || f.slopes();
            events += f.size();
        }
    };
    // The channel count as a constant lets the compiler unroll the
    // per-channel loops; inputs that are all flat between their steps (rays
    // of surface hits alone) skip the slope bookkeeping, whose terms would
    // all be 0. The arithmetic on values is the same either way.
    template <class Sink>
    std::optional<float> dispatch(Span<const SweepInput* const> inputs, int channels, const InputScan& scan,
                                  Sink& sink) {
        const std::uint64_t events = scan.events;
        // The flat path numbers its events in 32 bits; the heap serves any input.
        const bool sloped = scan.sloped || events > UINT32_MAX;
        if (channels == 1) return sloped ? run<1, true>(inputs, events, sink) : run<1, false>(inputs, events, sink);
        return sloped ? run<kMaxChannels, true>(inputs, events, sink) : run<kMaxChannels, false>(inputs, events, sink);
    }

    // The sweep proper, over checked inputs with NC channels and the weights
    // checkArguments() kept, `events` steps in all. Sink is VertexSink, or a
    // final one whose push() the compiler calls directly.
    template <std::size_t NC, bool Sloped, class Sink>
    std::optional<float> run(Span<const SweepInput* const> inputs, std::uint64_t events, Sink& sink);
};

Sweeper::Sweeper() : impl_(std::make_unique<Impl>()) {}
Sweeper::~Sweeper() = default;
Sweeper::Sweeper(Sweeper&&) noexcept = default;
Sweeper& Sweeper::operator=(Sweeper&&) noexcept = default;

std::optional<float> Sweeper::sweep(Span<const VisibilityFunction> inputs, Span<const double> weights, int channels,
                                    VertexSink& sink) {
    return impl_->runFunctions(inputs, weights, channels, sink);
}

std::optional<float> Sweeper::sweep(Span<const VisibilityView> inputs, Span<const double> weights, int channels,
                                    VertexSink& sink) {
    return impl_->runFunctions(inputs, weights, channels, sink);
}

std::optional<float> Sweeper::sweep(Span<const SweepInput* const> inputs, Span<const double> weights, int channels,
                                    VertexSink& sink) {
    return impl_->runPrepared(inputs, weights, channels, sink);
}

std::optional<float> Sweeper::sweep(Span<const SweepInput* const> inputs, Span<const double> weights, int channels,
                                    SweptVertices& out) {
    if (out.channels() != channels)
        throw Error(ErrorCode::argument, detail::concat("sweep: the output has ", out.channels(),
                                                        " channels, the inputs ", channels));
    return impl_->runPrepared(inputs, weights, channels, out);
}

void SweptVertices::grow() { reserve(std::max<std::size_t>(64, 2 * z_.size())); }

void SweptVertices::reserve(std::size_t vertices) {
    if (vertices <= z_.size()) return;
    z_.resize(vertices);
    v_.resize(vertices * channels_);
    count_.resize(vertices);
}

std::optional<float> sweep(Span<const VisibilityFunction> inputs, Span<const double> weights, int channels,
                           VertexSink& sink) {
    return Sweeper().sweep(inputs, weights, channels, sink);
}

template <class InputValid, class ThrowIfInvalid>
bool Sweeper::Impl::checkArguments(std::size_t n, Span<const double> weights, int channels,
                                   InputValid&& inputValid, ThrowIfInvalid&& throwIfInvalid) {
    if (channels != 1 && channels != kMaxChannels)
        throw Error(ErrorCode::argument, detail::concat("sweep: channel count ", channels, " is not 1 or 3"));
    if (n != weights.size())
        throw Error(ErrorCode::argument, detail::concat("sweep: ", n, " inputs but ", weights.size(), " weights"));
    if (n > UINT32_MAX) throw Error(ErrorCode::argument, "sweep: too many inputs");
    double sum = 0.0;
    bool valid = true;
    for (std::size_t k = 0; k < n; ++k) {
        // Finite and >= 0 (NaN fails both comparisons); the input checked
        // whatever its weight.
        const double weight = weights[k];
        const bool inputOk = inputValid(k);
        valid &= (weight >= 0.0) & (weight <= std::numeric_limits<double>::max()) & inputOk;
        sum += weight;
    }
    if (!valid) {
        for (std::size_t k = 0; k < n; ++k) {
            if (!std::isfinite(weights[k]) || weights[k] < 0.0)
                throw Error(ErrorCode::argument,
                            detail::concat("sweep: weight ", weights[k], " of input ", k, " is not finite and >= 0"));
            throwIfInvalid(k);
        }
    }
    if (n == 0) return false;
    if (!(sum > 0.0) || !std::isfinite(sum))
        throw Error(ErrorCode::argument,
                    detail::concat("sweep: the weights sum to ", sum, ", not a positive finite value"));
    givenWeights = weights;
    weightSum = sum;
    return true;
}

template <std::size_t NC, bool Sloped, class Sink>
std::optional<float> Sweeper::Impl::run(Span<const SweepInput* const> inputs, std::uint64_t events, Sink& sink) {
    if constexpr (std::is_same_v<Sink, SweptVertices>) {
        // Each depth emits at most two vertices, and there are at most
        // `events` depths (the inputs' steps, all told).
        sink.reserve(sink.size_ + 2 * events);
        DirectVertices<NC> direct{sink.z_.data(), sink.v_.data(), sink.count_.data(), sink.size_};
        const std::optional<float> refused = run<NC, Sloped>(inputs, events, direct);
        sink.size_ = direct.size;
        return refused;
    }
    const std::size_t n = inputs.size();
    constexpr std::size_t nc = NC;
    // Inputs whose current segment slopes (in any channel of positive weight):
    // an exact recomputation of the slope sum only needs these, and when there
    // are none the sum is exactly 0. Kept in a list with swap-removal.
    sloped.clear();
    // Inputs of positive weight whose current value is exactly 0, per channel:
    // when all are, the average is exactly 0 too (blocked light stays blocked,
    // without the rounding residue of the running sum).
    std::size_t zeroCount[kMaxChannels] = {0, 0, 0};
    std::size_t positive = 0;  // inputs of positive weight, counted below

    double value[kMaxChannels] = {1.0, 1.0, 1.0};
    double outSlope[kMaxChannels] = {0.0, 0.0, 0.0};
    double lastEmitted[kMaxChannels] = {1.0, 1.0, 1.0};
    double left[kMaxChannels] = {1.0, 1.0, 1.0};  // channels beyond NC are never read
    double slopeMagnitude[kMaxChannels] = {0.0, 0.0, 0.0};  // through outSlope since it was exact
    double zCurrent = 0.0;

    // Three steps of the loops below, shared by the heap and the flat path
    // (always inlined: called as functions they cost the flat path a tenth).
    // The value just before depth z, where the next events are.
    // Where nothing slopes (the flat path), the value has not moved since it
    // was emitted, in [0, lastEmitted]: the same doubles without the slope's
    // term and the clamp.
    const auto arrive = [&](float z) __attribute__((always_inline)) {
        for (std::size_t c = 0; c < nc; ++c) {
            if constexpr (Sloped) {
                left[c] = value[c] + outSlope[c] * (static_cast<double>(z) - zCurrent);
                left[c] = std::clamp(left[c], 0.0, lastEmitted[c]);
                value[c] = left[c];
            } else {
                left[c] = value[c];
            }
        }
        zCurrent = z;
    };
    // The zero crossings of an input of positive weight at a step.
    const auto countZeros = [&](std::uint32_t flags) __attribute__((always_inline)) {
        for (std::size_t c = 0; c < nc; ++c) {
            if (flags & (SweepInput::kReachesZero << (2 * c)))
                ++zeroCount[c];
            else if (flags & (SweepInput::kLeavesZero << (2 * c)))
                --zeroCount[c];
        }
    };
    // After every event at depth z: emits the vertex (two for a step); false
    // when the sink refuses.
    const auto leave = [&](float z, std::uint64_t count) __attribute__((always_inline)) {
        bool step = false;
        for (std::size_t c = 0; c < nc; ++c) {
            if constexpr (Sloped) {
                if (sloped.empty()) {
                    outSlope[c] = 0.0;
                    slopeMagnitude[c] = 0.0;
                } else if (slopeMagnitude[c] > kCancellationLimit * std::abs(outSlope[c])) {
                    double exact = 0.0;
                    for (std::uint32_t k : sloped) exact += w[k] * inputs[k]->changes(next[k] - 1)[nc + c];
                    outSlope[c] = exact;
                    slopeMagnitude[c] = std::abs(exact);
                }
                outSlope[c] = std::min(outSlope[c], 0.0);
            }
            value[c] = std::clamp(value[c], 0.0, left[c]);
            if (zeroCount[c] == positive) {
                value[c] = 0.0;
                outSlope[c] = 0.0;
            }
            if (value[c] != left[c]) step = true;
        }
        if (count > UINT32_MAX) throwCountLimit(count, z);
        const std::uint32_t count32 = static_cast<std::uint32_t>(count);
        if (!sink.push(z, left, step ? 0u : count32)) return false;
        if (step && !sink.push(z, value, count32)) return false;
        if constexpr (Sloped) std::copy(value, value + nc, lastEmitted);
        return true;
    };

    if constexpr (Sloped) {
        w.resize(n);
        for (std::size_t k = 0; k < n; ++k) {
            w[k] = givenWeights[k] / weightSum;
            positive += w[k] > 0.0;
        }
        // A heap of the inputs' next depths: a sloped input's slope before
        // each depth is the one after its previous depth, so each input is
        // walked in turn.
        next.assign(n, 0);
        slopedAt.assign(n, UINT32_MAX);
        // Inputs of weight 0 take part too: they add nothing to the value,
        // but their depths and sample counts belong to the output.
        heap.clear();
        for (std::size_t k = 0; k < n; ++k)
            if (!inputs[k]->empty()) heap.push_back(eventKey(inputs[k]->step(0).z, static_cast<std::uint32_t>(k)));
        std::make_heap(heap.begin(), heap.end(), std::greater<>());  // a min-heap, laid out as replaceTop() reads it

        while (!heap.empty()) {
            const std::uint32_t depth = depthOf(heap.front());
            const float z = inputs[inputOf(heap.front())]->step(next[inputOf(heap.front())]).z;
            arrive(z);
            std::uint64_t count = 0;
            do {
                const std::uint32_t k = inputOf(heap.front());
                const SweepInput& f = *inputs[k];
                const std::size_t i = next[k]++;
                const SweepInput::Step& step = f.step(i);
                const double* valueChange = f.changes(i);
                const double wk = w[k];
                count += step.count;
                for (std::size_t c = 0; c < nc; ++c) value[c] += wk * valueChange[c];
                const double* slopeAfter = valueChange + nc;
                // The slope before this depth: the one after the input's
                // previous depth, 0 before its first.
                const double* slopeBefore = i == 0 ? nullptr : f.changes(i - 1) + nc;
                for (std::size_t c = 0; c < nc; ++c) {
                    const double change = wk * (slopeAfter[c] - (slopeBefore ? slopeBefore[c] : 0.0));
                    if (change != 0.0) {
                        outSlope[c] += change;
                        slopeMagnitude[c] += std::abs(change) + std::abs(outSlope[c]);
                    }
                }
                if (step.flags != 0 && wk > 0.0) {
                    countZeros(step.flags);
                    if (step.flags & SweepInput::kStartsSloping) {
                        slopedAt[k] = static_cast<std::uint32_t>(sloped.size());
                        sloped.push_back(k);
                    } else if (step.flags & SweepInput::kStopsSloping) {
                        const std::uint32_t moved = sloped.back();
                        sloped[slopedAt[k]] = moved;
                        slopedAt[moved] = slopedAt[k];
                        sloped.pop_back();
                        slopedAt[k] = UINT32_MAX;
                    }
                }
                if (i + 1 < f.size()) {
                    replaceTop(heap.data(), heap.size(), eventKey(f.step(i + 1).z, k));
                } else {
                    const std::uint64_t last = heap.back();
                    heap.pop_back();
                    if (!heap.empty()) replaceTop(heap.data(), heap.size(), last);
                }
            } while (!heap.empty() && depthOf(heap.front()) == depth);
            if (!leave(z, count)) return z;
        }
    } else {
        // Steps alone: every input's steps gathered in input order, each with
        // its weighted change of value, then sorted by depth (ties in input
        // order, as the heap takes them) and summed in that order: the same
        // operations in the same order as the heap's, without its
        // unpredictable comparisons or a walk through the inputs per event.
        if (eventKeys.size() < events) {
            eventKeys.resize(events);
            eventScratch.resize(events);
            eventSteps.resize(events);
            eventChanges.resize(events * kMaxChannels);
        }
        std::uint64_t* keys = eventKeys.data();
        SweepInput::Step* steps = eventSteps.data();
        double* changes = eventChanges.data();
        std::size_t e = 0;
        for (std::size_t k = 0; k < n; ++k) {
            const SweepInput& f = *inputs[k];
            const double wk = givenWeights[k] / weightSum;
            positive += wk > 0.0;
            for (std::size_t i = 0; i < f.size(); ++i, ++e) {
                SweepInput::Step step = f.step(i);
                if (!(wk > 0.0)) step.flags = 0;  // only inputs of positive weight count towards 0
                steps[e] = step;
                const double* valueChange = f.changes(i);
                for (std::size_t c = 0; c < nc; ++c) changes[e * nc + c] = wk * valueChange[c];
                keys[e] = eventKey(step.z, static_cast<std::uint32_t>(e));
            }
        }
        keys = detail::sortEventKeys(keys, eventScratch.data(), events);

        for (e = 0; e < events;) {
            const std::uint32_t depth = depthOf(keys[e]);
            const float z = steps[inputOf(keys[e])].z;
            arrive(z);
            std::uint64_t count = 0;
            do {
                const std::uint32_t event = inputOf(keys[e]);
                const SweepInput::Step& step = steps[event];
                count += step.count;
                for (std::size_t c = 0; c < nc; ++c) value[c] += changes[event * nc + c];
                if (step.flags != 0) countZeros(step.flags);
            } while (++e < events && depthOf(keys[e]) == depth);
            if (!leave(z, count)) return z;
        }
    }
    return std::nullopt;
}

DSM_NAMESPACE_END
