// The weighted average of many piecewise-linear functions in O(n log n)
// (Lokovic & Veach 2000, §5.1, equation 1).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "dsm/span.h"
#include "dsm/version.h"
#include "dsm/vertex_sink.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// Streams V(z) = sum_k w_k tau_k(z) / sum_k w_k into `sink`, in z order.
///
/// Each input is read as a single-layer function (implicit 1 before its first
/// vertex, constant after its last). The sweep keeps the next vertex of every
/// input in a heap and tracks the output's value and slope, so each input vertex
/// costs O(log n). Vertical steps change the value, not the slope.
///
/// Output: one vertex per distinct input depth z carrying the left limit V(z-),
/// followed by a second vertex at the same z with V(z) when any input steps
/// there. The count of a depth (the sum of the counts of all input vertices at
/// it) rides on the last vertex emitted at that depth. The result is clamped to
/// [0, 1] and made non-increasing, which only removes rounding noise: it agrees
/// with the direct O(n^2) evaluation to about 1e-12.
///
/// Ties between inputs at one depth are taken in input order, so the output
/// is deterministic. Inputs must share one channel count (1 or 3) equal to
/// `channels`; weights must be finite, >= 0, with a positive sum. Throws
/// dsm::Error otherwise, naming the input index.
///
/// Returns the depth of the vertex the sink refused, or nothing when the sink
/// took every vertex.
DSM_API std::optional<float> sweep(Span<const VisibilityFunction> inputs, Span<const double> weights,
                           int channels, VertexSink& sink);

/// One input of the sweep, read once ahead of it: its vertices grouped by
/// depth, each depth with the change of value it brings to a sweep and the
/// slope after it (per channel, unweighted). A function averaged into several pixels
/// (a sample inside the filters of several) is thus read, and its slopes
/// divided out, once instead of once per pixel; sweeping it gives exactly
/// (the same doubles) what sweeping the function gives. Keeps its storage
/// from one assign() to the next. An input of up to kInlineDepths depths
/// (mono; one for RGB) keeps them inside the object, so that inputs held side
/// by side (a tile's samples) are read by the sweep in turn.
/// Not copyable; moving keeps what was assigned.
class DSM_API SweepInput {
public:
    /// Depths of a mono input kept inside the object.
    static constexpr std::size_t kInlineDepths = 3;

    SweepInput() = default;
    SweepInput(SweepInput&& other) noexcept;
    SweepInput& operator=(SweepInput&& other) noexcept;
    SweepInput(const SweepInput&) = delete;
    SweepInput& operator=(const SweepInput&) = delete;

    /// What the sweep meets at one depth of the input.
    struct Step {
        float z;
        std::uint32_t count;  // the counts of the input's vertices at z
        std::uint32_t flags;  // kStartsSloping, ...: changes of the input's state at z
    };
    /// The input's segment after z slopes (in some channel) and the one before did not.
    static constexpr std::uint32_t kStartsSloping = 1u;
    /// The input's segment after z is flat and the one before sloped.
    static constexpr std::uint32_t kStopsSloping = 2u;
    /// Channel c reaches 0 at z (kReachesZero << 2c) or leaves 0 (kLeavesZero << 2c).
    static constexpr std::uint32_t kReachesZero = 4u;
    static constexpr std::uint32_t kLeavesZero = 8u;

    /// Prepares `f`, which must have one layer and 1 or 3 channels, and no NaN
    /// depth; throws dsm::Error (argument) otherwise.
    void assign(const VisibilityView& f);

    int channels() const { return channels_; }
    /// Vertices of the prepared function.
    std::size_t vertexCount() const { return vertices_; }
    /// Its distinct depths (in storage order, equal neighbours grouped).
    std::size_t size() const { return size_; }
    bool empty() const { return size_ == 0; }
    /// Whether some segment of the function slopes (in some channel); false
    /// for vertical steps between flat stretches, such as the transmittance
    /// of surface hits alone.
    bool slopes() const { return slopes_; }
    const Step& step(std::size_t i) const { return stepData_[i]; }
    /// At depth i, per channel: the change of value (the step's height), then
    /// the slope after it, each `channels()` doubles.
    const double* changes(std::size_t i) const { return numberData_ + i * 2 * static_cast<std::size_t>(channels_); }

private:
    // Prepares surface-only transmittances without building the function.
    friend class TransmittanceBuilder;

    template <std::size_t NC>
    std::size_t assignWith(const VisibilityView& f);
    // Points stepData_ and numberData_ at room for `depths` depths of
    // `channels` channels and sets channels_. Inline where they fit inside
    // (a sample's few hits, prepared by the million).
    void reserveDepths(std::size_t depths, int channels) {
        if (depths * static_cast<std::size_t>(channels) <= kInlineDepths) {
            channels_ = channels;
            stepData_ = inlineSteps_;
            numberData_ = inlineNumbers_;
        } else {
            reserveHeapDepths(depths, channels);
        }
    }
    void reserveHeapDepths(std::size_t depths, int channels);

    // Where the steps and numbers are: inside the object (inlineSteps_,
    // inlineNumbers_) or in the heap arrays.
    Step* stepData_ = inlineSteps_;
    double* numberData_ = inlineNumbers_;
    Step inlineSteps_[kInlineDepths];
    double inlineNumbers_[2 * kInlineDepths];
    // Grown (never shrunk, never initialised) to the largest input seen that
    // does not fit inside.
    std::unique_ptr<Step[]> steps_;
    std::unique_ptr<double[]> numbers_;
    std::size_t stepCapacity_ = 0;
    std::size_t numberCapacity_ = 0;
    std::size_t size_ = 0;
    std::size_t vertices_ = 0;
    int channels_ = 1;
    bool slopes_ = false;
};

/// The sweep's output kept as it comes, values in double precision, for a
/// caller that hands it on after the sweep (to a compressor, timed apart).
/// Sweeping into it (the Sweeper overload) stores each vertex without a
/// virtual call, after making room for two vertices per step of the inputs
/// (the most a sweep can emit; about the memory the inputs take). Keeps its
/// storage from one clear() to the next.
class DSM_API SweptVertices final : public VertexSink {
public:
    /// Vertices of `channels` (1 or 3) values.
    explicit SweptVertices(int channels) : channels_(static_cast<std::size_t>(channels)) {}
    bool push(float z, const double* values, std::uint32_t count) override {
        if (size_ == z_.size()) grow();
        z_[size_] = z;
        // One or three values, written out: a loop here becomes a call to memcpy.
        double* v = v_.data() + size_ * channels_;
        v[0] = values[0];
        if (channels_ == 3) {
            v[1] = values[1];
            v[2] = values[2];
        }
        count_[size_] = count;
        ++size_;
        return true;
    }
    void clear() { size_ = 0; }
    int channels() const { return static_cast<int>(channels_); }
    std::size_t size() const { return size_; }
    const float* depths() const { return z_.data(); }
    /// size() * channels() values, vertex-major.
    const double* values() const { return v_.data(); }
    const std::uint32_t* counts() const { return count_.data(); }

private:
    // The sweep writes a pixel's vertices into the arrays directly, with room
    // made ahead for as many as it can emit.
    friend class Sweeper;

    // The arrays are kept at their largest size and written by index.
    void grow();
    // Room for `vertices` vertices in all (kept: size() is unchanged).
    void reserve(std::size_t vertices);

    std::size_t channels_;
    std::size_t size_ = 0;
    std::vector<float> z_;
    std::vector<double> v_;
    std::vector<std::uint32_t> count_;
};

/// sweep() with its working memory (heap, per-input state) kept between
/// calls, for a caller that sweeps many pixels on one thread: once its buffers
/// have grown to the most inputs, sweeping allocates nothing. Same results and
/// errors as sweep(), over functions or views of them. Not thread-safe: one
/// per thread.
class DSM_API Sweeper {
public:
    Sweeper();
    ~Sweeper();
    Sweeper(Sweeper&&) noexcept;
    Sweeper& operator=(Sweeper&&) noexcept;

    std::optional<float> sweep(Span<const VisibilityFunction> inputs, Span<const double> weights, int channels,
                               VertexSink& sink);
    std::optional<float> sweep(Span<const VisibilityView> inputs, Span<const double> weights, int channels,
                               VertexSink& sink);
    /// The same over inputs prepared ahead (each may be swept into many pixels).
    std::optional<float> sweep(Span<const SweepInput* const> inputs, Span<const double> weights, int channels,
                               VertexSink& sink);
    /// The same into `out`, whose channel count must be `channels`.
    std::optional<float> sweep(Span<const SweepInput* const> inputs, Span<const double> weights, int channels,
                               SweptVertices& out);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

DSM_NAMESPACE_END
