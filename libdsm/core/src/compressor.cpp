#include "dsm/compressor.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

// Largest rounding error of a value in [0, 1] stored as float32: half the
// float spacing just below 1.
constexpr double kStoreRounding = 0x1p-25;

// The greedy segment builder of Lokovic & Veach §3.3 for one layer at a time,
// all channels at once, writing straight into `out`. The segment origin is the
// last stored vertex (exact float values), or a "virtual" origin at V = 1 while
// the layer has stored nothing (V = 1 is implicit before the first vertex).
class Greedy {
public:
    Greedy(int channels, double tolerance, bool keepCounts)
        : channels_(channels),
          // Leave room for the float rounding of segment end points, so that the
          // stored function, not just the ideal line, is within tolerance.
          window_(std::max(0.0, tolerance - 2.0 * kStoreRounding)),
          out_(channels, keepCounts) {}

    void push(float z, const double* v, std::uint64_t count) {
        if (!started_) {
            started_ = true;
            originZ_ = z;
            std::fill(originV_, originV_ + channels_, 1.0);
            originStored_ = false;
            originIsStep_ = false;
        }
        if (!open_ && z == originZ_) {
            absorbAtOrigin(v, count);
            return;
        }
        if (open_ && !fitsWindow(z, v)) {
            closeSegment();
            if (z == originZ_) {
                absorbAtOrigin(v, count);
                return;
            }
        }
        if (!open_) {
            // The first window after an origin is always reachable: the origin is
            // within tolerance of the input there and the input never increases.
            // Rounding of the origin may leave a lower bound a hair above 0;
            // a flat segment then stays within tolerance.
            open_ = true;
            for (int c = 0; c < channels_; ++c) {
                double lo, hi;
                windowSlopes(z, v[c], c, lo, hi);
                hi_[c] = std::min(hi, 0.0);
                lo_[c] = std::min(lo, hi_[c]);
                rawSlopes(z, v[c], c, rawLo_[c], rawHi_[c]);
            }
        } else {
            for (int c = 0; c < channels_; ++c) {
                double lo, hi;
                windowSlopes(z, v[c], c, lo, hi);
                lo_[c] = std::max(lo_[c], lo);
                hi_[c] = std::min(hi_[c], hi);
                rawSlopes(z, v[c], c, lo, hi);
                rawLo_[c] = std::max(rawLo_[c], lo);
                rawHi_[c] = std::min(rawHi_[c], hi);
            }
        }
        lastZ_ = z;
        segmentCount_ += count;
    }

    // Ends the current layer: closes the open segment and makes sure the layer
    // stores at least one vertex when it must (its end depth, or counts).
    void finishLayer(bool recordEnd) {
        if (!started_) return;
        if (open_) closeSegment();
        if (!originStored_ && (recordEnd || originCount_ > 0)) storeOrigin();
        started_ = false;
    }

    void beginLayer() {
        if (!out_.empty()) out_.beginLayer();
    }

    VisibilityFunction take() {
        VisibilityFunction result = std::move(out_);
        out_ = VisibilityFunction(result.channels(), result.hasCounts());
        started_ = false;
        open_ = false;
        return result;
    }

private:
    void windowSlopes(float z, double v, int c, double& lo, double& hi) const {
        const double dz = static_cast<double>(z) - originZ_;
        const double top = std::min(v + window_, 1.0);
        const double bottom = std::max(v - window_, 0.0);
        lo = (bottom - originV_[c]) / dz;
        hi = (top - originV_[c]) / dz;
    }

    // The windows before clipping to [0, 1] and to non-increasing lines.
    void rawSlopes(float z, double v, int c, double& lo, double& hi) const {
        const double dz = static_cast<double>(z) - originZ_;
        lo = (v - window_ - originV_[c]) / dz;
        hi = (v + window_ - originV_[c]) / dz;
    }

    bool fitsWindow(float z, const double* v) const {
        for (int c = 0; c < channels_; ++c) {
            double lo, hi;
            windowSlopes(z, v[c], c, lo, hi);
            if (std::max(lo_[c], lo) > std::min(hi_[c], hi)) return false;
        }
        return true;
    }

    void addCount(std::uint64_t count) {
        if (originStored_)
            out_.addToLastCount(count);
        else
            originCount_ += count;
    }

    // An input vertex at the origin's depth: only the last value at a depth
    // matters (V is right-continuous), so it either fits the origin value or
    // becomes (or replaces) a step vertex at that depth.
    void absorbAtOrigin(const double* v, std::uint64_t count) {
        bool fits = true;
        for (int c = 0; c < channels_; ++c)
            if (std::abs(v[c] - originV_[c]) > window_) fits = false;
        if (fits) {
            addCount(count);
            return;
        }
        float stored[kMaxChannels];
        for (int c = 0; c < channels_; ++c) {
            stored[c] = std::clamp(static_cast<float>(v[c]), 0.0f, static_cast<float>(originV_[c]));
            originV_[c] = stored[c];
        }
        if (originIsStep_) {
            out_.setLastValues(stored);
            out_.addToLastCount(count);
        } else {
            out_.append(originZ_, stored, 0);
            out_.addToLastCount(originCount_ + count);
            originCount_ = 0;
        }
        originStored_ = true;
        originIsStep_ = true;
    }

    void storeOrigin() {
        float stored[kMaxChannels];
        for (int c = 0; c < channels_; ++c) stored[c] = static_cast<float>(originV_[c]);
        out_.append(originZ_, stored, 0);
        out_.addToLastCount(originCount_);
        originCount_ = 0;
        originStored_ = true;
    }

    // Emits the segment from the origin to the last accepted input depth with
    // the midpoint slope, and makes its end the new origin.
    void closeSegment() {
        const double dz = static_cast<double>(lastZ_) - originZ_;
        float end[kMaxChannels];
        bool flat = true;
        for (int c = 0; c < channels_; ++c) {
            // Lokovic & Veach's midpoint rule, taken on the windows the data
            // itself defines and then moved into the feasible range. Clipping
            // at V = 1 or at slope 0 first would bias the midpoint: flat runs
            // (lit space, the plateau after a surface) would tilt by eps / 2.
            double slope = 0.5 * (rawLo_[c] + rawHi_[c]);
            if (!(rawLo_[c] <= rawHi_[c])) slope = 0.5 * (lo_[c] + hi_[c]);
            slope = std::clamp(slope, lo_[c], hi_[c]);
            const double ideal = originV_[c] + slope * dz;
            end[c] = std::clamp(static_cast<float>(ideal), 0.0f, static_cast<float>(originV_[c]));
            if (end[c] != static_cast<float>(originV_[c])) flat = false;
        }
        open_ = false;
        if (!originStored_ && flat) {
            // Still V = 1 throughout: slide the virtual origin forward.
            originZ_ = lastZ_;
            originCount_ += segmentCount_;
            segmentCount_ = 0;
            return;
        }
        if (!originStored_) storeOrigin();
        out_.append(lastZ_, end, 0);
        out_.addToLastCount(segmentCount_);
        segmentCount_ = 0;
        originZ_ = lastZ_;
        for (int c = 0; c < channels_; ++c) originV_[c] = end[c];
        originStored_ = true;
        originIsStep_ = false;
    }

    int channels_;
    double window_;
    VisibilityFunction out_;

    bool started_ = false;       // the layer has seen input
    float originZ_ = 0.0f;
    double originV_[kMaxChannels] = {1.0, 1.0, 1.0};
    bool originStored_ = false;  // origin is a stored vertex (else virtual V = 1)
    bool originIsStep_ = false;  // origin is a step vertex that a deeper value at its depth may replace
    std::uint64_t originCount_ = 0;  // counts waiting for the first stored vertex

    bool open_ = false;  // a segment has accepted at least one vertex beyond the origin
    double lo_[kMaxChannels] = {};
    double hi_[kMaxChannels] = {};
    double rawLo_[kMaxChannels] = {};
    double rawHi_[kMaxChannels] = {};
    float lastZ_ = 0.0f;
    std::uint64_t segmentCount_ = 0;
};

}  // namespace

struct Compressor::Impl {
    explicit Impl(const CompressorOptions& o)
        : options(o),
          full(o.channels, o.tolerance, o.keepCounts),
          grey(1, 0.5 * o.tolerance, o.keepCounts),
          greyPossible(o.channels == kMaxChannels && o.allowMonochrome) {
        resetsLeft = std::max(o.maxLayers, 1) - 1;
    }

    void reset() {
        full.take();
        grey.take();
        greyPossible = options.channels == kMaxChannels && options.allowMonochrome;
        maxSpread = 0.0;
        resetsLeft = std::max(options.maxLayers, 1) - 1;
        layerEnding = false;
        layerClosed = false;
        layers = 0;
        inputIndex = 0;
        previousZ = 0.0f;
        haveLayerInput = false;
    }

    void validate(float z, const double* v) {
        const auto index = inputIndex;
        if (!std::isfinite(z) || z < 0.0f)
            throw Error(ErrorCode::argument, detail::concat("compressor: input vertex ", index, ": depth ", z,
                                                            " is not a finite value >= 0"));
        if (inputIndex > 0 && z < previousZ)
            throw Error(ErrorCode::argument, detail::concat("compressor: input vertex ", index, ": depth ", z,
                                                            " is less than the previous depth ", previousZ));
        for (int c = 0; c < options.channels; ++c) {
            if (!(v[c] >= 0.0 && v[c] <= 1.0))
                throw Error(ErrorCode::argument, detail::concat("compressor: input vertex ", index, " channel ", c,
                                                                ": visibility ", v[c], " is outside [0, 1]"));
            if (haveLayerInput && v[c] > previousV[c])
                throw Error(ErrorCode::argument,
                            detail::concat("compressor: input vertex ", index, " channel ", c, ": visibility ", v[c],
                                           " increases from the previous ", previousV[c]));
        }
    }

    void startLayer() {
        full.beginLayer();
        grey.beginLayer();
        ++layers;
        haveLayerInput = false;
    }

    void endLayer(bool recordEnd) {
        full.finishLayer(recordEnd);
        if (greyPossible) grey.finishLayer(recordEnd);
    }

    CompressorOptions options;
    Greedy full;
    Greedy grey;          // the channels' mid-range at half tolerance
    bool greyPossible;
    double maxSpread = 0.0;
    int resetsLeft = 0;
    bool layerEnding = false;  // a vertex at or below tolerance was seen
    float layerEndZ = 0.0f;
    bool layerClosed = false;  // refused a vertex: the next push starts a layer
    int layers = 0;
    std::uint64_t inputIndex = 0;
    float previousZ = 0.0f;
    double previousV[kMaxChannels] = {1.0, 1.0, 1.0};
    bool haveLayerInput = false;
};

Compressor::Compressor(const CompressorOptions& options) {
    if (options.channels != 1 && options.channels != kMaxChannels)
        throw Error(ErrorCode::argument,
                    detail::concat("compressor: channel count ", options.channels, " is not 1 or 3"));
    if (!(options.tolerance >= 0.0) || std::isnan(options.tolerance))
        throw Error(ErrorCode::argument,
                    detail::concat("compressor: tolerance ", options.tolerance, " is not a value >= 0"));
    if (options.maxLayers < 1 || options.maxLayers > 255)
        throw Error(ErrorCode::argument,
                    detail::concat("compressor: layer count ", options.maxLayers, " is not in [1, 255]"));
    impl_ = std::make_unique<Impl>(options);
}

Compressor::~Compressor() = default;

bool Compressor::push(float z, const float* values, std::uint32_t count) {
    double v[kMaxChannels];
    for (int c = 0; c < impl_->options.channels; ++c) v[c] = values[c];
    return push(z, v, count);
}

bool Compressor::push(float z, const double* values, std::uint32_t count) {
    Impl& s = *impl_;
    if (s.layerEnding && z > s.layerEndZ) {
        // All light is blocked at layerEndZ: end the layer and refuse this
        // vertex, so the producer restarts behind that depth.
        s.endLayer(true);
        s.layerEnding = false;
        s.layerClosed = true;
        return false;
    }
    if (s.layerClosed || s.layers == 0) {
        s.layerClosed = false;
        s.startLayer();
    }
    s.validate(z, values);
    ++s.inputIndex;
    s.previousZ = z;
    std::copy(values, values + s.options.channels, s.previousV);
    s.haveLayerInput = true;

    s.full.push(z, values, count);
    if (s.greyPossible) {
        double lo = values[0], hi = values[0];
        for (int c = 1; c < s.options.channels; ++c) {
            lo = std::min(lo, values[c]);
            hi = std::max(hi, values[c]);
        }
        s.maxSpread = std::max(s.maxSpread, hi - lo);
        // Collapsing to the mid-range costs up to half the spread; keep the grey
        // result only while that and its own half tolerance fit the budget.
        if (s.maxSpread > s.options.tolerance || (s.maxSpread > 0.0 && s.options.tolerance < 4.0 * kStoreRounding)) {
            s.greyPossible = false;
        } else {
            const double mid = 0.5 * (lo + hi);
            s.grey.push(z, &mid, count);
        }
    }

    if (s.resetsLeft > 0 && !s.layerEnding) {
        bool blocked = true;
        for (int c = 0; c < s.options.channels; ++c)
            if (values[c] > s.options.tolerance) blocked = false;
        if (blocked) {
            s.layerEnding = true;
            s.layerEndZ = z;
            --s.resetsLeft;
        }
    }
    return true;
}

void Compressor::beginLayer() {
    Impl& s = *impl_;
    if (s.layers == 0 || s.layerClosed) return;  // the next push starts one anyway
    s.endLayer(true);
    s.layerEnding = false;
    s.layerClosed = true;
}

float Compressor::layerEndDepth() const { return impl_->layerEndZ; }

int Compressor::layersUsed() const { return impl_->layers; }

VisibilityFunction Compressor::finish() {
    Impl& s = *impl_;
    // A layer after the first keeps at least one vertex even when its input
    // stayed at V = 1 within tolerance: an empty last layer is not valid.
    if (!s.layerClosed) s.endLayer(s.layerEnding || s.layers > 1);
    VisibilityFunction rgb = s.full.take();
    VisibilityFunction grey = s.grey.take();
    const bool exactGrey = s.options.channels == kMaxChannels && s.options.allowMonochrome && s.maxSpread == 0.0;
    const bool useGrey = s.greyPossible && !exactGrey;
    s.reset();
    if (exactGrey) return rgb.toMonochrome();
    if (useGrey) return grey;
    return rgb;
}

VisibilityFunction compress(const VisibilityFunction& input, double tolerance, bool allowMonochrome) {
    CompressorOptions options;
    options.tolerance = tolerance;
    options.channels = input.channels();
    options.keepCounts = input.hasCounts();
    options.allowMonochrome = allowMonochrome;
    Compressor compressor(options);
    for (std::size_t layer = 0; layer < input.layerCount(); ++layer) {
        if (layer > 0) compressor.beginLayer();
        for (std::size_t i = input.layerBegin(layer); i < input.layerEnd(layer); ++i)
            compressor.push(input.z(i), input.values(i), input.count(i));
    }
    return compressor.finish();
}

double autoTolerance(double samplesPerPixel) {
    if (!(samplesPerPixel >= 1.0) || !std::isfinite(samplesPerPixel))
        throw Error(ErrorCode::argument, detail::concat("auto tolerance: samples per pixel ", samplesPerPixel,
                                                        " is not a finite value >= 1"));
    return 0.25 / std::sqrt(samplesPerPixel);
}

DSM_NAMESPACE_END
