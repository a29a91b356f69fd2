#include "dsm/visibility.h"

#include <algorithm>
#include <cmath>

#include "dsm/error.h"
#include "dsm/vertex_sink.h"
#include "segment_search.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::lerpSegment;

namespace {

void checkChannelCount(int channels) {
    if (channels != 1 && channels != kMaxChannels)
        throw Error(ErrorCode::argument,
                    detail::concat("visibility function: channel count ", channels, " is not 1 or 3"));
}

}  // namespace

VisibilityFunction::VisibilityFunction(int channels, bool withCounts)
    : channels_(channels), withCounts_(withCounts) {
    checkChannelCount(channels);
}

std::uint64_t VisibilityFunction::totalCount() const {
    std::uint64_t total = 0;
    for (std::uint32_t c : count_) total += c;
    return total;
}

void VisibilityFunction::append(float z, const float* values, std::uint32_t count) {
    z_.push_back(z);
    // One or three values (the constructor's check), pushed one by one: a
    // range insert costs several times as much for so few.
    v_.push_back(values[0]);
    if (channels_ == kMaxChannels) {
        v_.push_back(values[1]);
        v_.push_back(values[2]);
    }
    if (withCounts_) count_.push_back(count);
}

void VisibilityFunction::setLastValues(const float* values) {
    std::copy(values, values + channels_, v_.end() - channels_);
}

void VisibilityFunction::addToLastCount(std::uint64_t count) {
    if (!withCounts_ || count_.empty()) return;
    const std::uint64_t sum = count_.back() + count;
    if (sum > UINT32_MAX)
        throw Error(ErrorCode::argument, detail::concat("visibility function: sample count ", sum, " at vertex ",
                                                        count_.size() - 1, " exceeds 2^32 - 1"));
    count_.back() = static_cast<std::uint32_t>(sum);
}

void VisibilityFunction::reserve(std::size_t vertices) {
    z_.reserve(vertices);
    v_.reserve(vertices * static_cast<std::size_t>(channels_));
    if (withCounts_) count_.reserve(vertices);
}

void VisibilityFunction::clear() {
    z_.clear();
    v_.clear();
    count_.clear();
    layerBegin_.clear();
}

void VisibilityFunction::reset(int channels, bool withCounts) {
    checkChannelCount(channels);
    clear();
    channels_ = channels;
    withCounts_ = withCounts;
}

double VisibilityFunction::evaluate(double z, int channel) const { return view().evaluate(z, channel); }

void VisibilityFunction::evaluate(double z, double* out) const { view().evaluate(z, out); }

double VisibilityFunction::evaluateLayer(std::size_t layer, double z, int channel) const {
    return view().evaluateLayer(layer, z, channel);
}

void VisibilityFunction::validate() const {
    const std::size_t n = z_.size();
    if (v_.size() != n * static_cast<std::size_t>(channels_))
        throw Error(ErrorCode::argument, detail::concat("visibility function: ", v_.size(), " values for ", n,
                                                        " vertices of ", channels_, " channels"));
    if (withCounts_ && count_.size() != n)
        throw Error(ErrorCode::argument,
                    detail::concat("visibility function: ", count_.size(), " counts for ", n, " vertices"));
    view().validate();
}

void VisibilityView::validate() const {
    const std::size_t n = z_.size();
    if (v_.size() != n * static_cast<std::size_t>(channels_))
        throw Error(ErrorCode::argument, detail::concat("visibility function: ", v_.size(), " values for ", n,
                                                        " vertices of ", channels_, " channels"));
    if (!count_.empty() && count_.size() != n)
        throw Error(ErrorCode::argument,
                    detail::concat("visibility function: ", count_.size(), " counts for ", n, " vertices"));
    std::size_t previousBegin = 0;
    for (std::size_t layer = 1; layer < layerCount(); ++layer) {
        const std::size_t b = layerBegin(layer);
        if (b <= previousBegin || b >= n)
            throw Error(ErrorCode::argument, detail::concat("visibility function: layer ", layer, " starts at vertex ",
                                                            b, ", outside (", previousBegin, ", ", n, ")"));
        previousBegin = b;
    }
    std::size_t nextLayer = 1;
    for (std::size_t i = 0; i < n; ++i) {
        const float z = z_[i];
        if (!std::isfinite(z))
            throw Error(ErrorCode::argument, detail::concat("vertex ", i, ": depth ", z, " is not finite"));
        if (z < 0.0f) throw Error(ErrorCode::argument, detail::concat("vertex ", i, ": depth ", z, " is negative"));
        if (i > 0 && z < z_[i - 1])
            throw Error(ErrorCode::argument,
                        detail::concat("vertex ", i, ": depth ", z, " is less than the previous depth ", z_[i - 1]));
        bool layerStart = (i == 0);
        if (nextLayer < layerCount() && i == layerBegin(nextLayer)) {
            layerStart = true;
            ++nextLayer;
        }
        for (int c = 0; c < channels_; ++c) {
            const float v = value(i, c);
            if (!std::isfinite(v) || v < 0.0f || v > 1.0f)
                throw Error(ErrorCode::argument,
                            detail::concat("vertex ", i, " channel ", c, ": visibility ", v, " is outside [0, 1]"));
            if (!layerStart && v > value(i - 1, c))
                throw Error(ErrorCode::argument, detail::concat("vertex ", i, " channel ", c, ": visibility ", v,
                                                                " increases from the previous ", value(i - 1, c)));
        }
    }
}

bool VisibilityFunction::isMonochrome() const {
    if (channels_ == 1) return true;
    for (std::size_t i = 0; i < z_.size(); ++i) {
        const float* v = values(i);
        for (int c = 1; c < channels_; ++c)
            if (v[c] != v[0]) return false;
    }
    return true;
}

VisibilityFunction VisibilityFunction::toMonochrome() const {
    VisibilityFunction mono(1, withCounts_);
    mono.reserve(size());
    for (std::size_t layer = 0; layer < layerCount(); ++layer) {
        if (layer > 0) mono.beginLayer();
        for (std::size_t i = layerBegin(layer); i < layerEnd(layer); ++i) mono.append(z_[i], values(i), count(i));
    }
    return mono;
}

namespace {

// V(z) on vertices [begin, end) of `f`: right-continuous, 1 before the first.
double evaluateRange(const VisibilityView& f, std::size_t begin, std::size_t end, double z, int channel) {
    const auto zs = f.depths();
    const std::size_t k = begin + detail::firstDepthAbove(zs.data() + begin, end - begin, z);
    if (k == begin) return 1.0;
    if (k == end) return f.value(end - 1, channel);
    return lerpSegment(zs[k - 1], f.value(k - 1, channel), zs[k], f.value(k, channel), z);
}

}  // namespace

double VisibilityView::evaluate(double z, int channel) const {
    const std::size_t end0 = lightEnd();
    if (layerCount() > 1 && z >= z_[end0 - 1]) return 0.0;
    return evaluateRange(*this, 0, end0, z, channel);
}

void VisibilityView::evaluate(double z, double* out) const {
    for (int c = 0; c < channels_; ++c) out[c] = evaluate(z, c);
}

double VisibilityView::evaluateLayer(std::size_t layer, double z, int channel) const {
    if (layer >= layerCount()) return 1.0;
    return evaluateRange(*this, layerBegin(layer), layerEnd(layer), z, channel);
}

VisibilityFunction VisibilityView::toFunction(bool withCounts) const {
    VisibilityFunction f(channels_, withCounts && !count_.empty());
    f.reserve(size());
    for (std::size_t layer = 0; layer < layerCount(); ++layer) {
        if (layer > 0) f.beginLayer();
        for (std::size_t i = layerBegin(layer); i < layerEnd(layer); ++i) f.append(z_[i], values(i), count(i));
    }
    return f;
}

std::size_t VisibilityCursor::locate(double z) {
    const auto zs = function_.depths();
    const std::size_t end0 = function_.lightEnd();
    std::size_t k = std::min(next_, end0);
    while (k < end0 && static_cast<double>(zs[k]) <= z) {
        ++k;
        ++steps_;
    }
    while (k > 0 && static_cast<double>(zs[k - 1]) > z) {
        --k;
        ++steps_;
    }
    next_ = k;
    return k;
}

double VisibilityCursor::evaluate(double z, int channel) {
    const VisibilityView& f = function_;
    const std::size_t end0 = f.lightEnd();
    if (f.layerCount() > 1 && z >= f.z(end0 - 1)) return 0.0;
    const std::size_t k = locate(z);
    if (k == 0) return 1.0;
    if (k == end0) return f.value(end0 - 1, channel);
    return lerpSegment(f.z(k - 1), f.value(k - 1, channel), f.z(k), f.value(k, channel), z);
}

void VisibilityCursor::evaluate(double z, double* out) {
    for (int c = 0; c < function_.channels(); ++c) out[c] = evaluate(z, c);
}

bool CollectingSink::push(float z, const double* values, std::uint32_t count) {
    float v[kMaxChannels];
    for (int c = 0; c < out_.channels(); ++c) v[c] = static_cast<float>(values[c]);
    out_.append(z, v, count);
    return true;
}

DSM_NAMESPACE_END
