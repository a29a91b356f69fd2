// Piecewise-linear visibility functions: the value stored in every pixel of a
// deep shadow map (Lokovic & Veach 2000, §3.1).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "dsm/span.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// Largest channel count: a function is monochrome (1) or RGB (3).
inline constexpr int kMaxChannels = 3;

class VisibilityFunction;

/// A read-only view of a visibility function whose arrays live elsewhere (a
/// VisibilityFunction, or a pixel of a decoded tile). Same representation and
/// the same evaluation rules as VisibilityFunction, which documents them. Cheap
/// to copy; valid while the arrays it views are.
///
/// Thread safety: a view is immutable; any number of threads may read one (and
/// the arrays it views) at once, as long as nobody modifies those arrays.
class DSM_API VisibilityView {
public:
    VisibilityView() = default;
    /// `values` holds z.size() * channels floats, vertex-major; `counts` is
    /// empty or holds one count per vertex; `layerStarts` holds the first
    /// vertex of layers 1, 2, ... (empty for a single layer).
    VisibilityView(Span<const float> z, Span<const float> values, Span<const std::uint32_t> counts,
                   int channels, Span<const std::uint32_t> layerStarts = {})
        : z_(z), v_(values), count_(counts), layerStarts_(layerStarts), channels_(channels) {}

    int channels() const { return channels_; }
    /// True when the viewed function carries counts (and has vertices).
    bool hasCounts() const { return !count_.empty(); }
    std::size_t size() const { return z_.size(); }
    bool empty() const { return z_.empty(); }
    float z(std::size_t i) const { return z_[i]; }
    float value(std::size_t i, int channel = 0) const {
        return v_[i * static_cast<std::size_t>(channels_) + static_cast<std::size_t>(channel)];
    }
    const float* values(std::size_t i) const { return v_.data() + i * static_cast<std::size_t>(channels_); }
    std::uint32_t count(std::size_t i) const { return count_.empty() ? 0u : count_[i]; }
    Span<const float> depths() const { return z_; }
    Span<const float> allValues() const { return v_; }
    Span<const std::uint32_t> counts() const { return count_; }
    Span<const std::uint32_t> layerStarts() const { return layerStarts_; }

    std::size_t layerCount() const { return layerStarts_.size() + 1; }
    std::size_t layerBegin(std::size_t layer) const { return layer == 0 ? 0 : layerStarts_[layer - 1]; }
    std::size_t layerEnd(std::size_t layer) const {
        return layer + 1 < layerCount() ? layerStarts_[layer] : z_.size();
    }
    /// End of the light-centre function: vertices [0, lightEnd()) are layer 0.
    std::size_t lightEnd() const { return layerEnd(0); }

    /// Light-centre visibility at z (see VisibilityFunction::evaluate).
    double evaluate(double z, int channel = 0) const;
    void evaluate(double z, double* out) const;
    /// Visibility of layer L alone (1 before its first vertex).
    double evaluateLayer(std::size_t layer, double z, int channel = 0) const;

    /// The invariants of VisibilityFunction::validate(), on the viewed arrays.
    void validate() const;

    /// A copy that owns its data. `withCounts` false drops the counts.
    VisibilityFunction toFunction(bool withCounts = true) const;

private:
    Span<const float> z_;
    Span<const float> v_;
    Span<const std::uint32_t> count_;
    Span<const std::uint32_t> layerStarts_;
    int channels_ = 1;
};

/// A visibility function V(z): the fraction of a light beam that reaches depth z.
///
/// Representation
///   Vertices (z_i, V_i) in storage order with 0 <= z_0 <= z_1 <= ..., stored
///   as float32 (the on-disk precision). Equal consecutive z form a vertical
///   step. V_i lies in [0, 1] and never increases along a layer. Before the first
///   vertex V = 1; after the last vertex V keeps the last value. Each vertex
///   holds one value (monochrome) or three (R, G, B).
///
/// Value at a step (used everywhere in libdsm)
///   V is right-continuous: at a depth z that carries several vertices, V(z) is
///   the value of the *last* of them, the value after the step. An occluder at
///   depth z therefore shadows a receiver at exactly z, as an ordinary depth map
///   with a "<=" test does; renderers add a bias to avoid self-shadowing.
///   Formally V(z) = lerp between vertex k-1 and vertex k where k is the first
///   vertex with z_k > z (1 if k = 0, V_{n-1} if k = n).
///
/// Sample counts (optional, Xie et al. 2007 §5.1)
///   count_i is the number of original samples (surface hits or volume steps)
///   represented between vertex i-1 and vertex i, including those at z_i.
///
/// Layers (multilayer transparent shadow maps, Xie et al. 2007 §5.1)
///   Vertices are grouped into one or more layers in z order. Layer 0 is the
///   ordinary deep shadow function seen from the light centre. Layer L > 0
///   describes only what lies behind the depth where layer L-1 ended, as if the
///   light started afresh there: it again starts at an implicit V = 1. The
///   light-centre visibility of a layered function is layer 0, and 0 at and
///   beyond the depth of layer 0's last vertex (the layer ended because all light
///   was blocked there, within the compression tolerance).
///
/// Thread safety: as for a standard container. Const members may be called
/// from any number of threads at once; a modifying member (append, beginLayer,
/// clear, assignment, ...) needs the caller to make sure no other thread uses
/// the function, or a view of it, at the same time.
class DSM_API VisibilityFunction {
public:
    /// An empty function (V = 1 everywhere) with `channels` (1 or 3) values
    /// per vertex and, when `withCounts`, a sample count per vertex.
    explicit VisibilityFunction(int channels = 1, bool withCounts = false);

    int channels() const { return channels_; }
    bool hasCounts() const { return withCounts_; }
    std::size_t size() const { return z_.size(); }
    bool empty() const { return z_.empty(); }

    float z(std::size_t i) const { return z_[i]; }
    float value(std::size_t i, int channel = 0) const {
        return v_[i * static_cast<std::size_t>(channels_) + static_cast<std::size_t>(channel)];
    }
    /// Pointer to the channels() values of vertex i.
    const float* values(std::size_t i) const { return v_.data() + i * static_cast<std::size_t>(channels_); }
    /// Sample count of vertex i; 0 when the function keeps no counts.
    std::uint32_t count(std::size_t i) const { return withCounts_ ? count_[i] : 0u; }
    /// Sum of all counts (0 without counts).
    std::uint64_t totalCount() const;

    Span<const float> depths() const { return z_; }
    /// All values, vertex-major: vertex i channel c at [i * channels() + c].
    Span<const float> allValues() const { return v_; }
    Span<const std::uint32_t> counts() const { return count_; }

    /// Number of layers, at least 1.
    std::size_t layerCount() const { return layerBegin_.size() + 1; }
    /// Index of the first vertex of layer L (0 for L = 0).
    std::size_t layerBegin(std::size_t layer) const { return layer == 0 ? 0 : layerBegin_[layer - 1]; }
    /// One past the last vertex of layer L.
    std::size_t layerEnd(std::size_t layer) const {
        return layer + 1 < layerCount() ? layerBegin_[layer] : z_.size();
    }

    /// Append a vertex to the last layer. No checks: use validate() on data that
    /// did not come from libdsm. `values` holds channels() floats.
    void append(float z, const float* values, std::uint32_t count = 0);
    /// Monochrome convenience.
    void append(float z, float value, std::uint32_t count = 0) { append(z, &value, count); }
    /// Start a new layer; following appends go to it.
    void beginLayer() { layerBegin_.push_back(static_cast<std::uint32_t>(z_.size())); }
    /// Overwrite the values of the last vertex.
    void setLastValues(const float* values);
    /// Add to the count of the last vertex (no effect without counts).
    void addToLastCount(std::uint64_t count);
    void reserve(std::size_t vertices);
    void clear();
    /// Empties the function and gives it `channels` (1 or 3; dsm::Error
    /// (argument) otherwise) and counts or none, keeping its storage: refilling
    /// a function allocates nothing while it has room.
    void reset(int channels, bool withCounts);

    /// Light-centre visibility at depth z for one channel (0 <= channel <
    /// channels()), by binary search. Computed in double from the stored floats.
    double evaluate(double z, int channel = 0) const;
    /// All channels at once into out[channels()].
    void evaluate(double z, double* out) const;
    /// Visibility of layer L alone at depth z (1 before its first vertex).
    double evaluateLayer(std::size_t layer, double z, int channel = 0) const;

    /// Checks every invariant: z finite, >= 0 and non-decreasing; values finite,
    /// in [0, 1] and non-increasing within each layer; layer starts increasing.
    /// Throws dsm::Error naming the vertex index, channel and value.
    void validate() const;

    /// True when every vertex's channels are equal (always true for one channel).
    bool isMonochrome() const;
    /// The same function with one channel (channel 0). Requires isMonochrome()
    /// or accepts the loss of the other channels.
    VisibilityFunction toMonochrome() const;

    /// A view of this function (valid until it is modified).
    VisibilityView view() const { return VisibilityView(z_, v_, count_, channels_, layerBegin_); }
    operator VisibilityView() const { return view(); }

    /// Same channels, counts flag, vertices and layers.
    friend bool operator==(const VisibilityFunction& a, const VisibilityFunction& b) {
        return a.channels_ == b.channels_ && a.withCounts_ == b.withCounts_ && a.z_ == b.z_ && a.v_ == b.v_ &&
               a.count_ == b.count_ && a.layerBegin_ == b.layerBegin_;
    }
    friend bool operator!=(const VisibilityFunction& a, const VisibilityFunction& b) { return !(a == b); }

private:

    int channels_;
    bool withCounts_;
    std::vector<float> z_;
    std::vector<float> v_;
    std::vector<std::uint32_t> count_;
    std::vector<std::uint32_t> layerBegin_;  // first vertex of layers 1, 2, ...
};

/// Coherent evaluation (Lokovic & Veach §3.4): remembers the segment of the
/// previous query and searches linearly forward or backward from it, so a run
/// of lookups at nearby depths costs O(1) each. Same results as
/// VisibilityFunction::evaluate. Not thread-safe (evaluation moves the cursor):
/// one cursor per thread. The function must outlive it and not change while
/// it is used.
class DSM_API VisibilityCursor {
public:
    explicit VisibilityCursor(const VisibilityView& function) : function_(function) {}
    /// Starts the search at `position` (a value of position() from an earlier
    /// cursor over the same function).
    VisibilityCursor(const VisibilityView& function, std::size_t position) : function_(function), next_(position) {}
    explicit VisibilityCursor(const VisibilityFunction& function) : function_(function.view()) {}
    double evaluate(double z, int channel = 0);
    void evaluate(double z, double* out);
    /// Number of vertices stepped over by the linear searches so far (for tests
    /// and benchmarks of coherence).
    std::uint64_t stepsTaken() const { return steps_; }
    /// Where the next search starts.
    std::size_t position() const { return next_; }

private:
    std::size_t locate(double z);  // first vertex of layer 0 with z_k > z
    VisibilityView function_;
    std::size_t next_ = 0;  // cached: first vertex with z_k > last query
    std::uint64_t steps_ = 0;
};

DSM_NAMESPACE_END
