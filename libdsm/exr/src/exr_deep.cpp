// Deep OpenEXR interop (spec/exr-interop.md).
//
// A map's pixel is a piecewise-linear visibility V(z); a deep EXR pixel is a
// list of samples whose transmittance is exponential inside each volume
// sample. Export turns vertical steps into point samples and sloped segments
// into volume samples, subdividing a segment until the chord and the
// exponential agree within a bound; import evaluates the (possibly messy)
// samples exactly in log space between their fronts and backs, and places
// chord vertices densely enough for the same kind of bound, then compresses.
#include "dsm/exr_deep.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <numbers>

#include <ImathBox.h>
#include <ImathMatrix.h>
#include <ImathVec.h>
#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepImageStateAttribute.h>
#include <ImfDeepScanLineInputPart.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfDeepTiledInputPart.h>
#include <ImfMultiPartInputFile.h>
#include <ImfDeepTiledOutputFile.h>
#include <ImfDoubleAttribute.h>
#include <ImfHeader.h>
#include <ImfIntAttribute.h>
#include <ImfMatrixAttribute.h>
#include <ImfPartType.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <ImfTestFile.h>
#include <ImfVecAttribute.h>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include <sys/stat.h>

#include "dsm/compressor.h"
#include "dsm/error.h"
#include "dsm/names.h"
#include "dsm/output_file.h"
#include "dsm/reader.h"
#include "dsm/writer.h"
#include "naming_file.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

// ---------------------------------------------------------------------------
// The chord of an exponential

/// Largest gap between the chord of r^t over t in [0, 1] and r^t itself, with
/// u = -ln r >= 0. The gap 1 - t(1 - r) - r^t peaks where r^t = (1 - r) / u.
double chordGap(double u) {
    if (!(u < std::numeric_limits<double>::infinity())) return 1.0;
    if (u < 1e-4) return u * u / 8.0 - u * u * u / 16.0;  // series; the closed form cancels here
    const double m = -std::expm1(-u);  // 1 - r, exact for small u
    const double tPeak = std::log(u / m) / u;
    return std::max(0.0, 1.0 - tPeak * m - m / u);
}

/// Largest u = -ln(vb / va) of a piece starting at visibility va whose chord
/// gap va * chordGap(u) stays within `bound`; infinity when any drop is fine.
double largestLogDrop(double va, double bound) {
    if (va <= bound) return std::numeric_limits<double>::infinity();
    const double target = bound / va;  // < 1
    // chordGap(u) ~ u^2 / 8 for small u: bracket that guess, then bisect to a
    // relative 1e-7 (finer only makes pieces shorter by nothing one can see).
    const double guess = std::sqrt(8.0 * target);
    double lo = chordGap(0.5 * guess) <= target ? 0.5 * guess : 0.0, hi = 2.0 * guess + 1e-300;
    while (chordGap(hi) <= target) lo = hi, hi *= 2.0;
    for (int i = 0; i < 80 && hi - lo > 1e-7 * hi; ++i) {
        const double mid = 0.5 * (lo + hi);
        (chordGap(mid) <= target ? lo : hi) = mid;
    }
    return lo;
}

/// The next float above z, for pieces that would otherwise not advance.
float nextFloatUp(float z) { return std::nextafter(z, std::numeric_limits<float>::infinity()); }

constexpr int kMaxTracked = 4;  // R, G, B and their mean

// ---------------------------------------------------------------------------
// Export of one function

class SampleBuilder {
public:
    SampleBuilder(int channels, double bound, std::vector<DeepSample>& out)
        : channels_(channels), tracked_(channels == 1 ? 1 : 4), bound_(bound), out_(out) {
        std::fill(std::begin(v_), std::end(v_), 1.0);
    }

    double largestDeviation() const { return largest_; }
    std::uint64_t oneStepExcess() const { return oneStepExcess_; }
    bool allBlack() const {
        for (int c = 0; c < tracked_; ++c)
            if (v_[c] > 0.0) return false;
        return true;
    }

    /// A vertical step at z to `next` (channels() values).
    void step(float z, const double* next) {
        double target[kMaxTracked];
        expand(next, target);
        if (!lower(target)) return;
        emit(z, z, v_, target);
        std::copy(target, target + kMaxTracked, v_);
    }

    /// A linear segment from (z0, current values) to (z1, next).
    void segment(float z0, float z1, const double* next) {
        double target[kMaxTracked];
        expand(next, target);
        if (!lower(target)) return;
        if (!(z1 > z0)) return step(z0, next);
        const double start[kMaxTracked] = {v_[0], v_[1], v_[2], v_[3]};
        double t = 0.0;
        float zAt = z0;
        while (t < 1.0) {
            double va[kMaxTracked], vb[kMaxTracked];
            for (int c = 0; c < tracked_; ++c) va[c] = start[c] + t * (target[c] - start[c]);
            double dt = 1.0 - t;
            for (int c = 0; c < tracked_; ++c) {
                const double slope = target[c] - start[c];
                if (!(slope < 0.0) || va[c] <= 0.0) continue;
                const double u = largestLogDrop(va[c], bound_);
                if (u == std::numeric_limits<double>::infinity()) continue;
                const double vbMin = va[c] * std::exp(-u);
                dt = std::min(dt, (vbMin - va[c]) / slope);
            }
            // The piece ends at a float depth; its values are the map's there.
            const double tWanted = t + dt;
            float zNext = tWanted >= 1.0 ? z1 : static_cast<float>(z0 + tWanted * (double(z1) - double(z0)));
            if (!(zNext > zAt)) zNext = std::min(nextFloatUp(zAt), z1);  // below float resolution: one step
            if (zNext >= z1) zNext = z1;
            auto tOf = [&](float zq) { return zq >= z1 ? 1.0 : (double(zq) - double(z0)) / (double(z1) - double(z0)); };
            auto valuesAt = [&](double tq) {
                for (int c = 0; c < tracked_; ++c) vb[c] = tq >= 1.0 ? target[c] : start[c] + tq * (target[c] - start[c]);
            };
            auto within = [&] {
                for (int c = 0; c < tracked_; ++c)
                    if (exponentialDeviation(va[c], vb[c]) > bound_) return false;
                return true;
            };
            // Rounding to floats (of depth, and of t near 1) can overshoot the
            // wanted end: shorten the piece until it is within the bound.
            valuesAt(tOf(zNext));
            while (!within() && zNext > nextFloatUp(zAt)) {
                float shorter = static_cast<float>(0.5 * (double(zAt) + double(zNext)));
                if (!(shorter > zAt) || !(shorter < zNext)) shorter = std::nextafter(zNext, zAt);
                zNext = shorter;
                valuesAt(tOf(zNext));
            }
            const double tNext = tOf(zNext);
            // A piece one float step long cannot be cut further: its excess
            // lies strictly between two adjacent float depths.
            const bool oneStep = zNext == nextFloatUp(zAt) && !within();
            emit(zAt, zNext, va, vb, oneStep);
            t = tNext;
            zAt = zNext;
        }
        std::copy(target, target + kMaxTracked, v_);
    }

private:
    void expand(const double* values, double* tracked) const {
        if (channels_ == 1) {
            std::fill(tracked, tracked + kMaxTracked, values[0]);
            return;
        }
        for (int c = 0; c < 3; ++c) tracked[c] = values[c];
        tracked[3] = (values[0] + values[1] + values[2]) / 3.0;
    }
    bool lower(const double* target) const {
        for (int c = 0; c < tracked_; ++c)
            if (target[c] < v_[c]) return true;
        return false;
    }
    static float alphaOf(double before, double after) {
        if (!(before > 0.0)) return 1.0f;
        return static_cast<float>(std::clamp(1.0 - after / before, 0.0, 1.0));
    }
    void emit(float z, float zBack, const double* before, const double* after, bool oneStep = false) {
        DeepSample s;
        s.z = z;
        s.zBack = zBack;
        for (int c = 0; c < 3; ++c) s.alphaRGB[static_cast<std::size_t>(c)] = alphaOf(before[c], after[c]);
        s.alpha = alphaOf(before[tracked_ == 1 ? 0 : 3], after[tracked_ == 1 ? 0 : 3]);
        if (zBack > z)
            for (int c = 0; c < tracked_; ++c) {
                const double deviation = exponentialDeviation(before[c], after[c]);
                if (oneStep && deviation > bound_) ++oneStepExcess_;
                else largest_ = std::max(largest_, deviation);
            }
        out_.push_back(s);
    }

    int channels_;
    int tracked_;
    double bound_;
    std::vector<DeepSample>& out_;
    double v_[kMaxTracked];
    double largest_ = 0.0;
    std::uint64_t oneStepExcess_ = 0;
};

std::vector<DeepSample> samplesOf(const VisibilityView& f, double maxDeviation, double* largest,
                                  std::uint64_t* oneStepExcess = nullptr) {
    if (!(maxDeviation > 0.0) || !std::isfinite(maxDeviation))
        throw Error(ErrorCode::argument,
                    concat("deep EXR export: the largest deviation must be a positive number, got ", maxDeviation));
    std::vector<DeepSample> out;
    SampleBuilder builder(f.channels(), maxDeviation, out);
    const std::size_t end = f.lightEnd();
    double values[kMaxChannels];
    for (std::size_t i = 0; i < end && !builder.allBlack(); ++i) {
        for (int c = 0; c < f.channels(); ++c) values[c] = f.value(i, c);
        if (i == 0 || f.z(i) == f.z(i - 1)) builder.step(f.z(i), values);
        else builder.segment(f.z(i - 1), f.z(i), values);
    }
    if (f.layerCount() > 1 && end > 0 && !builder.allBlack()) {  // layer 0 ended because the light was gone
        const double black[kMaxChannels] = {0.0, 0.0, 0.0};
        builder.step(f.z(end - 1), black);
    }
    if (largest) *largest = builder.largestDeviation();
    if (oneStepExcess) *oneStepExcess = builder.oneStepExcess();
    return out;
}

// ---------------------------------------------------------------------------
// Import of one pixel

struct Volume {
    double front, back;
    double rate[kMaxChannels];  // d(ln T)/dz inside the sample, <= 0
};

}  // namespace

double exponentialDeviation(double v0, double v1) {
    if (!(v0 > 0.0)) return 0.0;
    if (!(v1 > 0.0)) return v0;
    if (v1 >= v0) return 0.0;
    return v0 * chordGap(-std::log(v1 / v0));
}

std::vector<DeepSample> deepSamplesFromVisibility(const VisibilityView& function, double maxDeviation) {
    return samplesOf(function, maxDeviation, nullptr);
}

VisibilityFunction visibilityFromDeepSamples(std::span<const DeepSample> samples, int channels,
                                             double maxLinearError) {
    if (channels != 1 && channels != 3)
        throw Error(ErrorCode::argument, concat("deep samples: channels must be 1 or 3, got ", channels));
    if (!(maxLinearError > 0.0) || !std::isfinite(maxLinearError))
        throw Error(ErrorCode::argument,
                    concat("deep samples: the linearisation error must be a positive number, got ", maxLinearError));
    auto alphaOf = [&](const DeepSample& s, int c) { return channels == 1 ? s.alpha : s.alphaRGB[std::size_t(c)]; };

    // Events: every front and back; point samples and opaque volume fronts
    // are steps, other volumes change the log-slope while they are active.
    std::vector<double> breaks;
    std::vector<std::pair<double, std::array<double, kMaxChannels>>> steps;  // depth, ln(1 - alpha)
    std::vector<Volume> volumes;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const DeepSample& s = samples[i];
        if (!std::isfinite(s.z) || s.z < 0.0f || !std::isfinite(s.zBack))
            throw Error(ErrorCode::argument,
                        concat("sample ", i, ": depth Z ", s.z, " ZBack ", s.zBack, " (must be finite, Z >= 0)"));
        for (int c = 0; c < channels; ++c) {
            const float a = alphaOf(s, c);
            if (!(a >= 0.0f && a <= 1.0f))
                throw Error(ErrorCode::argument, concat("sample ", i, ": alpha ", a, " is outside [0, 1]"));
        }
        std::array<double, kMaxChannels> logT{0.0, 0.0, 0.0};
        bool any = false;
        for (int c = 0; c < channels; ++c) {
            logT[std::size_t(c)] = std::log1p(-double(alphaOf(s, c)));
            any = any || alphaOf(s, c) > 0.0f;
        }
        if (!any) continue;
        breaks.push_back(s.z);
        if (!(s.zBack > s.z)) {
            steps.push_back({s.z, logT});
            continue;
        }
        // An opaque channel is gone just behind the front: a step there.
        Volume v{s.z, s.zBack, {0.0, 0.0, 0.0}};
        std::array<double, kMaxChannels> opaque{0.0, 0.0, 0.0};
        bool anyOpaque = false;
        for (int c = 0; c < channels; ++c) {
            const double lt = logT[std::size_t(c)];
            if (std::isinf(lt)) opaque[std::size_t(c)] = lt, anyOpaque = true;
            else v.rate[c] = lt / (double(s.zBack) - double(s.z));
        }
        if (anyOpaque) steps.push_back({s.z, opaque});
        volumes.push_back(v);
        breaks.push_back(s.zBack);
    }
    std::sort(breaks.begin(), breaks.end());
    breaks.erase(std::unique(breaks.begin(), breaks.end()), breaks.end());
    std::sort(steps.begin(), steps.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

    // Volumes enter and leave the running log-slope at their fronts and backs
    // (both are breakpoints); with none active the slope is exactly 0.
    std::vector<const Volume*> byFront, byBack;
    for (const Volume& v : volumes) byFront.push_back(&v), byBack.push_back(&v);
    std::sort(byFront.begin(), byFront.end(), [](auto* a, auto* b) { return a->front < b->front; });
    std::sort(byBack.begin(), byBack.end(), [](auto* a, auto* b) { return a->back < b->back; });
    std::size_t nextFront = 0, nextBack = 0, active = 0;
    double rate[kMaxChannels] = {0.0, 0.0, 0.0};

    VisibilityFunction out(channels);
    double logT[kMaxChannels] = {0.0, 0.0, 0.0};
    std::size_t nextStep = 0;
    auto push = [&](double z) {
        float v[kMaxChannels];
        for (int c = 0; c < channels; ++c) v[c] = static_cast<float>(std::exp(logT[c]));
        out.append(static_cast<float>(z), v);
    };
    for (std::size_t b = 0; b < breaks.size(); ++b) {
        const double z = breaks[b];
        if (b == 0) {
            push(z);  // V = 1 up to the first event
        } else if (active == 0) {
            push(z);  // flat since the previous breakpoint
        } else {
            // Exponential stretch from the previous breakpoint to z, in chords.
            const double z0 = breaks[b - 1];
            const double start[kMaxChannels] = {logT[0], logT[1], logT[2]};
            double at = z0;
            float zAt = static_cast<float>(z0);
            while (at < z) {
                double dz = z - at;
                for (int c = 0; c < channels; ++c) {
                    if (!(rate[c] < 0.0)) continue;
                    const double u = largestLogDrop(std::exp(logT[c]), maxLinearError);
                    if (u != std::numeric_limits<double>::infinity()) dz = std::min(dz, u / -rate[c]);
                }
                // Chord ends sit on float depths (breakpoints are floats), not
                // past the wanted end; at least one float step.
                float zNext = static_cast<float>(at + dz);
                if (double(zNext) > at + dz) zNext = std::nextafter(zNext, zAt);
                if (!(zNext > zAt)) zNext = nextFloatUp(zAt);
                double next = std::min(double(zNext), z);
                for (int c = 0; c < channels; ++c) logT[c] = start[c] + rate[c] * (next - z0);
                push(next);
                at = next;
                zAt = zNext;
            }
        }
        for (; nextBack < byBack.size() && byBack[nextBack]->back <= z; ++nextBack, --active)
            for (int c = 0; c < channels; ++c) rate[c] -= byBack[nextBack]->rate[c];
        for (; nextFront < byFront.size() && byFront[nextFront]->front <= z; ++nextFront, ++active)
            for (int c = 0; c < channels; ++c) rate[c] += byFront[nextFront]->rate[c];
        for (int c = 0; c < channels; ++c) rate[c] = active == 0 ? 0.0 : std::min(rate[c], 0.0);
        bool stepped = false;
        for (; nextStep < steps.size() && steps[nextStep].first == z; ++nextStep) {
            for (int c = 0; c < channels; ++c) logT[c] += steps[nextStep].second[std::size_t(c)];
            stepped = true;
        }
        if (stepped) push(z);
    }
    return out;
}

// ---------------------------------------------------------------------------
// Camera matrices

namespace {

using Matrix4 = std::array<std::array<double, 4>, 4>;

Matrix4 multiply(const Matrix4& a, const Matrix4& b) {
    Matrix4 r{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) r[i][j] += a[i][k] * b[k][j];
    return r;
}

Matrix4 transpose(const Matrix4& a) {
    Matrix4 r{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) r[i][j] = a[j][i];
    return r;
}

/// Gauss-Jordan with partial pivoting; false when singular.
bool invert(Matrix4 a, Matrix4& inverse) {
    Matrix4 r{};
    for (int i = 0; i < 4; ++i) r[i][i] = 1.0;
    for (int col = 0; col < 4; ++col) {
        int pivot = col;
        for (int row = col + 1; row < 4; ++row)
            if (std::abs(a[row][col]) > std::abs(a[pivot][col])) pivot = row;
        if (!(std::abs(a[pivot][col]) > 1e-300)) return false;
        std::swap(a[col], a[pivot]);
        std::swap(r[col], r[pivot]);
        const double scale = 1.0 / a[col][col];
        for (int j = 0; j < 4; ++j) a[col][j] *= scale, r[col][j] *= scale;
        for (int row = 0; row < 4; ++row) {
            if (row == col) continue;
            const double f = a[row][col];
            for (int j = 0; j < 4; ++j) a[row][j] -= f * a[col][j], r[row][j] -= f * r[col][j];
        }
    }
    inverse = r;
    return true;
}

Matrix4 worldToLightMatrix(const LightCamera& camera) {
    Matrix4 m{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) m[i][j] = camera.worldToLight[std::size_t(4 * i + j)];
    return m;
}

/// Light space to NDC, column-vector convention (spec/exr-interop.md).
Matrix4 projectionMatrix(const LightCamera& camera) {
    const auto& w = camera.screenWindow;
    const double dx = w[1] - w[0], dy = w[3] - w[2];
    if (camera.projection == Projection::Perspective)
        return {{{1 / dx, 0, -w[0] / dx, 0}, {0, -1 / dy, w[3] / dy, 0}, {0, 0, 0, 1}, {0, 0, 1, 0}}};
    return {{{1 / dx, 0, 0, -w[0] / dx}, {0, -1 / dy, 0, w[3] / dy}, {0, 0, 1, 0}, {0, 0, 0, 1}}};
}

std::array<std::array<float, 4>, 4> toFloat(const Matrix4& m) {
    std::array<std::array<float, 4>, 4> r{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) r[i][j] = static_cast<float>(m[i][j]);
    return r;
}

}  // namespace

StandardCameraMatrices standardCameraMatrices(const LightCamera& camera) {
    const Matrix4 w = worldToLightMatrix(camera);
    StandardCameraMatrices out;
    out.worldToCamera = toFloat(transpose(w));
    out.worldToNDC = toFloat(transpose(multiply(projectionMatrix(camera), w)));
    return out;
}

LightCamera cameraFromStandardMatrices(const Matrix4& worldToCamera, const Matrix4& worldToNDC) {
    const Matrix4 w = transpose(worldToCamera);
    Matrix4 wInverse;
    if (!invert(w, wInverse)) throw Error(ErrorCode::corrupt, "worldToCamera is singular");
    const Matrix4 p = multiply(transpose(worldToNDC), wInverse);
    double scale = 0.0;
    for (const auto& row : p)
        for (double v : row) scale = std::max(scale, std::abs(v));
    const double eps = 1e-5 * scale;
    auto zero = [&](double v) { return std::abs(v) <= eps; };
    auto notProjection = [] {
        return Error(ErrorCode::corrupt,
                     "worldToNDC is not a perspective or orthographic projection along the camera's z axis");
    };
    if (!(scale > 0.0) || !std::isfinite(scale)) throw notProjection();

    LightCamera camera;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) camera.worldToLight[std::size_t(4 * i + j)] = w[i][j];
    // NDC x = (a s + c), y = (b t + d) with (s, t) the screen coordinates.
    double a, c, b, d;
    if (!zero(p[3][2]) && zero(p[3][0]) && zero(p[3][1]) && zero(p[3][3])) {
        camera.projection = Projection::Perspective;
        if (!zero(p[0][1]) || !zero(p[0][3]) || !zero(p[1][0]) || !zero(p[1][3])) throw notProjection();
        a = p[0][0] / p[3][2], c = p[0][2] / p[3][2], b = p[1][1] / p[3][2], d = p[1][2] / p[3][2];
    } else if (!zero(p[3][3]) && zero(p[3][0]) && zero(p[3][1]) && zero(p[3][2])) {
        camera.projection = Projection::Orthographic;
        if (!zero(p[0][1]) || !zero(p[0][2]) || !zero(p[1][0]) || !zero(p[1][2])) throw notProjection();
        a = p[0][0] / p[3][3], c = p[0][3] / p[3][3], b = p[1][1] / p[3][3], d = p[1][3] / p[3][3];
    } else {
        throw notProjection();
    }
    if (zero(a) || zero(b)) throw notProjection();
    camera.screenWindow = {-c / a, (1.0 - c) / a, (1.0 - d) / b, -d / b};
    camera.validate();
    return camera;
}

// ---------------------------------------------------------------------------
// Files

namespace {

constexpr std::uint32_t kMaxExrExtent = 1u << 17;
constexpr std::uint64_t kMaxSamplesPerPixel = 1u << 24;
constexpr std::uint64_t kMaxSamplesPerBand = 1ull << 27;

std::string quoted(const std::string& path) { return concat("'", path, "'"); }

/// A maxDeviation or maxLinearError option: unset for the default, else in
/// [kMinExrErrorBound, 1] (NaN refused).
void checkErrorBoundOption(std::optional<double> value, const char* what) {
    if (!value) return;
    if (!(*value >= kMinExrErrorBound && *value <= 1.0))
        throw Error(ErrorCode::argument, concat(what, " ", *value, " is outside [", kMinExrErrorBound,
                                                ", 1] (float32 samples cannot keep a tighter bound)"));
}

/// Re-reads the offset tables of the EXR OpenEXR just wrote: every chunk must
/// be there before the file may replace the target.
void verifyWrittenExr(const OutputFile& file) {
    bool complete = false;
    try {
        Imf::MultiPartInputFile written(file.temporaryPath().c_str());
        complete = written.parts() == 1 && written.partComplete(0);
    } catch (const std::exception& e) {
        throw Error(ErrorCode::io, concat(quoted(file.path()), ": the written image does not read back: ", e.what()));
    }
    if (!complete) throw Error(ErrorCode::io, concat(quoted(file.path()), ": the written image is incomplete"));
}

/// Per-pixel sample lists of a band of rows and the frame buffer that points
/// OpenEXR at them. Rows [y0, y0 + rows) of columns [x0, x0 + width), in the
/// file's pixel coordinates.
struct Band {
    int x0 = 0, y0 = 0, width = 0, rows = 0;
    std::vector<unsigned> counts;
    std::vector<std::vector<DeepSample>> samples;
    std::vector<char*> z, zBack, alpha, alphaR, alphaG, alphaB;

    void reset(int x, int y, int w, int h) {
        x0 = x, y0 = y, width = w, rows = h;
        const std::size_t n = std::size_t(w) * std::size_t(h);
        counts.assign(n, 0);
        samples.assign(n, {});
        for (auto* v : {&z, &zBack, &alpha, &alphaR, &alphaG, &alphaB}) v->assign(n, nullptr);
    }
    /// Points every channel at the pixels' samples (after they are sized).
    void point() {
        for (std::size_t i = 0; i < samples.size(); ++i) {
            DeepSample* s = samples[i].data();
            if (!s) continue;
            z[i] = reinterpret_cast<char*>(&s->z);
            zBack[i] = reinterpret_cast<char*>(&s->zBack);
            alpha[i] = reinterpret_cast<char*>(&s->alpha);
            alphaR[i] = reinterpret_cast<char*>(&s->alphaRGB[0]);
            alphaG[i] = reinterpret_cast<char*>(&s->alphaRGB[1]);
            alphaB[i] = reinterpret_cast<char*>(&s->alphaRGB[2]);
        }
    }
    template <class T>
    char* base(std::vector<T>& v) const {
        // OpenEXR addresses pixel (x, y) at base + x * xStride + y * yStride.
        const std::ptrdiff_t offset = std::ptrdiff_t(x0) + std::ptrdiff_t(y0) * width;
        return reinterpret_cast<char*>(v.data()) - offset * std::ptrdiff_t(sizeof(T));
    }
    Imf::DeepFrameBuffer frameBuffer(bool withZBack, bool mono, bool colourSlices) {
        Imf::DeepFrameBuffer fb;
        fb.insertSampleCountSlice(
            Imf::Slice(Imf::UINT, base(counts), sizeof(unsigned), sizeof(unsigned) * std::size_t(width)));
        const std::size_t xs = sizeof(char*), ys = sizeof(char*) * std::size_t(width), ss = sizeof(DeepSample);
        auto slice = [&](const char* name, std::vector<char*>& v) {
            fb.insert(name, Imf::DeepSlice(Imf::FLOAT, base(v), xs, ys, ss));
        };
        slice("Z", z);
        if (withZBack) slice("ZBack", zBack);
        slice("A", alpha);
        if (!mono) {
            slice("AR", alphaR);
            slice("AG", alphaG);
            slice("AB", alphaB);
            if (colourSlices) {  // written only: R = AR etc. (spec/exr-interop.md)
                slice("R", alphaR);
                slice("G", alphaG);
                slice("B", alphaB);
            }
        }
        return fb;
    }
};

}  // namespace

// Both entry points attach to their errors the file each one names (the map or
// the image), whichever step below raised it.
ExrExportReport exportDeepExr(const std::string& dsmPath, const std::string& exrPath,
                              const ExrExportOptions& options) try {
    checkErrorBoundOption(options.maxDeviation, "deep EXR export: the largest deviation");
    checkOutputPath(exrPath);
    refuseOutputOverInputs(exrPath, {dsmPath});
    const auto map = DeepShadowMap::open(dsmPath);
    const MapInfo& info = map->info();
    if (options.level >= info.levels.size())
        throw Error(ErrorCode::argument, concat(quoted(dsmPath), ": level ", options.level,
                                                " does not exist (the map has ", info.levels.size(), " levels)"));
    const LevelInfo& level = info.levels[options.level];
    ExrExportReport report;
    report.width = level.width;
    report.height = level.height;
    report.channels = info.channels;
    report.maxDeviation =
        options.maxDeviation.value_or(std::clamp(level.tolerance / 2.0, 1e-5, 1e-3));
    if (!std::isfinite(report.maxDeviation))
        throw Error(ErrorCode::argument,
                    concat("deep EXR export: the largest deviation must be finite, got ", report.maxDeviation));
    if (options.tiled && (options.tileSize < 1 || options.tileSize > 65536))
        throw Error(ErrorCode::argument,
                    concat("deep EXR export: tile size ", options.tileSize, " is outside 1..65536"));
    const bool mono = info.channels == 1;
    const int width = int(level.width), height = int(level.height);

    const LightCamera& cam = info.camera;
    const double dx = cam.screenWindow[1] - cam.screenWindow[0], dy = cam.screenWindow[3] - cam.screenWindow[2];
    const Imath::Box2i window(Imath::V2i(0, 0), Imath::V2i(width - 1, height - 1));
    Imf::Header header(window, window, float((dx / width) / (dy / height)),
                       Imath::V2f(float((cam.screenWindow[0] + cam.screenWindow[1]) / 2),
                                  float((cam.screenWindow[2] + cam.screenWindow[3]) / 2)),
                       float(dx), Imf::INCREASING_Y, Imf::ZIPS_COMPRESSION);
    for (const char* name : {"Z", "ZBack", "A"}) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    if (!mono)
        for (const char* name : {"AR", "AG", "AB", "R", "G", "B"}) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    const StandardCameraMatrices standard = standardCameraMatrices(cam);
    Imath::M44f toCamera, toNDC;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            toCamera[i][j] = standard.worldToCamera[std::size_t(i)][std::size_t(j)],
            toNDC[i][j] = standard.worldToNDC[std::size_t(i)][std::size_t(j)];
    Imf::addWorldToCamera(header, toCamera);
    Imf::addWorldToNDC(header, toNDC);
    Imf::addDeepImageState(header, Imf::DIS_TIDY);
    Imath::M44d worldToLight;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) worldToLight[i][j] = cam.worldToLight[std::size_t(4 * j + i)];  // row-vector form
    header.insert("dsm:worldToLight", Imf::M44dAttribute(worldToLight));
    header.insert("dsm:projection", Imf::StringAttribute(projectionName(cam.projection)));
    header.insert("dsm:screenWindowMin", Imf::V2dAttribute(Imath::V2d(cam.screenWindow[0], cam.screenWindow[2])));
    header.insert("dsm:screenWindowMax", Imf::V2dAttribute(Imath::V2d(cam.screenWindow[1], cam.screenWindow[3])));
    header.insert("dsm:nearPlane", Imf::DoubleAttribute(cam.nearPlane));
    header.insert("dsm:level", Imf::IntAttribute(int(options.level)));
    header.insert("dsm:tolerance", Imf::DoubleAttribute(level.tolerance));
    header.insert("dsm:errorBound", Imf::DoubleAttribute(level.errorBound));
    header.insert("dsm:maxDeviation", Imf::DoubleAttribute(report.maxDeviation));
    header.insert("dsm:filter", Imf::StringAttribute(filterName(info.filter)));
    header.insert("dsm:filterWidth", Imf::DoubleAttribute(info.filterWidth));
    header.insert("dsm:metadata", Imf::StringAttribute(info.metadata));

    OutputFile output(exrPath);
    std::vector<double> largest(std::size_t(height), 0.0);
    std::vector<std::uint64_t> oneStep(std::size_t(height), 0);
    auto fill = [&](Band& band) {
        tbb::parallel_for(0, band.rows, [&](int r) {
            const int y = band.y0 + r;
            for (int x = 0; x < band.width; ++x) {
                const std::size_t i = std::size_t(r) * std::size_t(band.width) + std::size_t(x);
                double worst = 0.0;
                std::uint64_t excess = 0;
                try {
                    const PixelFunction f = map->pixel(options.level, std::uint32_t(x), std::uint32_t(y));
                    band.samples[i] = samplesOf(f.view(), report.maxDeviation, &worst, &excess);
                } catch (const Error& e) {
                    throw Error(e.code(), concat(quoted(dsmPath), " level ", options.level, " pixel ", x, ",", y, ": ",
                                                 e.what()));
                }
                band.counts[i] = unsigned(band.samples[i].size());
                largest[std::size_t(y)] = std::max(largest[std::size_t(y)], worst);
                oneStep[std::size_t(y)] += excess;
            }
        });
        band.point();
        for (const auto& pixel : band.samples)
            for (const DeepSample& s : pixel) ++(s.zBack > s.z ? report.volumeSamples : report.pointSamples);
    };
    try {
        Band band;
        if (options.tiled) {
            const int tile = int(options.tileSize);
            header.setTileDescription(Imf::TileDescription(unsigned(tile), unsigned(tile), Imf::ONE_LEVEL));
            header.setType(Imf::DEEPTILE);
            Imf::DeepTiledOutputFile out(output.temporaryPath().c_str(), header);
            for (int ty = 0; ty * tile < height; ++ty) {
                band.reset(0, ty * tile, width, std::min(tile, height - ty * tile));
                fill(band);
                out.setFrameBuffer(band.frameBuffer(true, mono, true));
                out.writeTiles(0, out.numXTiles(0) - 1, ty, ty);
            }
        } else {
            header.setType(Imf::DEEPSCANLINE);
            Imf::DeepScanLineOutputFile out(output.temporaryPath().c_str(), header);
            constexpr int kRows = 16;
            for (int y = 0; y < height; y += kRows) {
                band.reset(0, y, width, std::min(kRows, height - y));
                fill(band);
                out.setFrameBuffer(band.frameBuffer(true, mono, true));
                out.writePixels(band.rows);
            }
        }
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        // OpenEXR names the temporary file it was writing: name the output instead.
        std::string what = e.what();
        for (auto at = what.find(output.temporaryPath()); at != std::string::npos;
             at = what.find(output.temporaryPath(), at + exrPath.size()))
            what.replace(at, output.temporaryPath().size(), exrPath);
        throw Error(ErrorCode::io, concat(quoted(exrPath), ": ", what));
    }
    verifyWrittenExr(output);
    output.commit();
    for (double v : largest) report.largestDeviation = std::max(report.largestDeviation, v);
    for (std::uint64_t n : oneStep) report.oneStepExcess += n;
    return report;
} catch (const Error& e) {
    throw detail::withOneOf(e, {dsmPath, exrPath});
}

namespace {

/// The value size OpenEXR 3.1 reads for an attribute type whatever size the
/// file records, or 0 for a type read by its content or its recorded size.
std::uint32_t fixedExrAttributeSize(const std::string& type) {
    static const std::pair<const char*, std::uint32_t> kSizes[] = {
        {"box2f", 16},   {"box2i", 16},          {"chromaticities", 32}, {"compression", 1}, {"deepImageState", 1},
        {"double", 8},   {"envmap", 1},          {"float", 4},           {"int", 4},         {"keycode", 28},
        {"lineOrder", 1}, {"m33d", 72},          {"m33f", 36},           {"m44d", 128},      {"m44f", 64},
        {"rational", 8}, {"tiledesc", 9},        {"timecode", 8},        {"v2d", 16},        {"v2f", 8},
        {"v2i", 8},      {"v3d", 24},            {"v3f", 12},            {"v3i", 12}};
    for (const auto& [name, size] : kSizes)
        if (type == name) return size;
    return 0;
}

std::uint32_t littleEndian32(const std::string& bytes, std::size_t at) {
    std::uint32_t v = 0;
    for (std::size_t i = 0; i < 4; ++i) v |= std::uint32_t(std::uint8_t(bytes[at + i])) << (8 * i);
    return v;
}

/// Why OpenEXR 3.1 would read a different number of bytes than `value` (an
/// attribute of type `type`, as recorded) holds, or "" when it reads exactly
/// those: the types it reads by their content must fill their recorded size.
std::string exrAttributeDisagreement(const std::string& type, const std::string& value) {
    const std::size_t size = value.size();
    if (type == "chlist") {
        // name\0 (1 to 255 bytes), 16 bytes of channel, ..., then an empty name.
        for (std::size_t at = 0;;) {
            const std::size_t end = value.find('\0', at);
            if (end == std::string::npos || end - at > 255)
                return "its channel list does not end within them";
            if (end == at) {
                if (end + 1 == size) return "";
                return concat("its channel list ends after ", end + 1);
            }
            at = end + 1 + 16;
            if (at > size) return "its channel list does not end within them";
        }
    }
    if (type == "stringvector") {
        // int32 length + bytes, repeated until the recorded size is read.
        for (std::size_t at = 0; at < size;) {
            if (size - at < 4) return "its strings do not fill them";
            const std::uint32_t length = littleEndian32(value, at);
            at += 4;
            if (length > size - at) return "a string in it runs past them";
            at += length;
        }
        return "";
    }
    if (type == "floatvector") return size % 4 == 0 ? "" : "that is not a whole number of floats";
    if (type == "preview") {
        if (size < 8) return "a preview needs at least 8 for its width and height";
        const std::uint64_t pixels = std::uint64_t(littleEndian32(value, 0)) * littleEndian32(value, 4);
        return pixels * 4 + 8 == size ? "" : concat("its preview image needs ", pixels * 4 + 8);
    }
    if (type == "idmanifest") return size >= 4 ? "" : "an idmanifest needs at least 4 for its size field";
    return "";
}

/// Reads the attribute list of every header of an OpenEXR file without
/// OpenEXR and refuses a size no file of this length can hold. OpenEXR 3.1
/// allocates the size an attribute claims before reading it, so a few damaged
/// bytes would otherwise cost gigabytes. The layout (magic, version, then
/// name\0 type\0 int32-size value ..., a header ending in an empty name,
/// and multi-part files ending their headers with one more) is OpenEXR's
/// documented file layout. OpenEXR reads fixed-size types and channel lists
/// by their content, not by the recorded size; an attribute whose content
/// disagrees with its size is refused too, since OpenEXR would read the rest
/// of the header out of step and meet sizes this walk never checked.
/// Anything else is left for OpenEXR to judge.
void checkExrHeaderSizes(const std::string& path, std::uint64_t fileSize) {
    std::ifstream in(path, std::ios::binary);
    std::uint8_t start[8];
    if (!in.read(reinterpret_cast<char*>(start), sizeof start)) return;
    if (start[0] != 0x76 || start[1] != 0x2f || start[2] != 0x31 || start[3] != 0x01) return;
    const bool multiPart = (start[5] & 0x10) != 0;  // version flag bit 12
    std::uint64_t offset = sizeof start;
    // A name or type longer than 255 bytes is invalid; OpenEXR reports it.
    const auto readName = [&](std::string& name) {
        name.clear();
        for (char c; in.get(c);) {
            ++offset;
            if (c == '\0') return true;
            if (name.size() == 255) return false;
            name.push_back(c);
        }
        return false;
    };
    std::string name, type, value;
    int part = 0;
    for (bool headerStart = true;;) {
        if (!readName(name)) return;
        if (name.empty()) {
            // An empty name ends a header; right at a header's start it ends a
            // multi-part file's list of headers.
            if (!multiPart || headerStart) return;
            headerStart = true;
            ++part;
            continue;
        }
        headerStart = false;
        if (!readName(type)) return;
        std::uint8_t size[4];
        if (!in.read(reinterpret_cast<char*>(size), sizeof size)) return;
        offset += sizeof size;
        const std::int32_t claimed = static_cast<std::int32_t>(std::uint32_t(size[0]) | std::uint32_t(size[1]) << 8 |
                                                               std::uint32_t(size[2]) << 16 |
                                                               std::uint32_t(size[3]) << 24);
        const std::string attribute =
            concat(quoted(path), ": ", multiPart ? concat("part ", part, " ") : std::string(), "header attribute '",
                   name, "' (", type, ")");
        if (claimed < 0 || std::uint64_t(claimed) > fileSize - offset)
            throw Error(ErrorCode::corrupt, concat(attribute, " claims ", claimed, " bytes but the file has ",
                                                   fileSize - offset, " bytes left"));
        if (const std::uint32_t fixed = fixedExrAttributeSize(type); fixed != 0 && std::uint32_t(claimed) != fixed)
            throw Error(ErrorCode::corrupt,
                        concat(attribute, " records ", claimed, " bytes but a ", type, " holds ", fixed));
        if (type == "chlist" || type == "stringvector" || type == "floatvector" || type == "preview" ||
            type == "idmanifest") {
            value.resize(std::size_t(claimed));
            if (!in.read(value.data(), claimed)) return;
            if (const std::string why = exrAttributeDisagreement(type, value); !why.empty())
                throw Error(ErrorCode::corrupt, concat(attribute, " records ", claimed, " bytes but ", why));
        }
        offset += std::uint64_t(claimed);
        if (!in.seekg(static_cast<std::streamoff>(offset))) return;
    }
}

/// Bounds OpenEXR's own allocations for every file it opens from now on: its
/// header check refuses data windows and tiles larger than a map can be.
void limitOpenExrAllocations() {
    static const bool once = [] {
        Imf::Header::setMaxImageSize(int(kMaxExrExtent), int(kMaxExrExtent));
        Imf::Header::setMaxTileSize(int(kMaxExrExtent), int(kMaxExrExtent));
        return true;
    }();
    (void)once;
}

/// The deep EXR being imported: header checks and bands of pixels.
class DeepExrSource {
public:
    explicit DeepExrSource(const std::string& path) : path_(path) {
        // stat, not open: opening a FIFO would wait for a writer forever.
        struct stat st {};
        if (::stat(path.c_str(), &st) != 0)
            throw Error(ErrorCode::io, concat(quoted(path), ": cannot open: ", std::strerror(errno)));
        if (!S_ISREG(st.st_mode)) throw Error(ErrorCode::io, concat(quoted(path), ": not a regular file"));
        checkExrHeaderSizes(path, static_cast<std::uint64_t>(st.st_size));
        fileBytes_ = static_cast<std::uint64_t>(st.st_size);
        limitOpenExrAllocations();
        bool tiled = false, deep = false, multiPart = false;
        if (!Imf::isOpenExrFile(path.c_str(), tiled, deep, multiPart))
            throw Error(ErrorCode::format, concat(quoted(path), ": not an OpenEXR file"));
        if (!deep) throw Error(ErrorCode::format, concat(quoted(path), ": not a deep image (a flat OpenEXR file)"));
        // The tiled flag of isOpenExrFile() describes flat files only; a deep
        // part says what it is in its type attribute.
        (void)tiled;
        (void)multiPart;
        file_ = std::make_unique<Imf::MultiPartInputFile>(path.c_str());
        const std::string type = file_->header(0).type();
        if (type == Imf::DEEPTILE) tiledFile_ = std::make_unique<Imf::DeepTiledInputPart>(*file_, 0);
        else if (type == Imf::DEEPSCANLINE) scanFile_ = std::make_unique<Imf::DeepScanLineInputPart>(*file_, 0);
        else
            throw Error(ErrorCode::format, concat(quoted(path), ": part 0 is not a deep image (type '", type, "')"));
        const Imf::ChannelList& ch = header().channels();
        if (!ch.findChannel("Z"))
            throw Error(ErrorCode::format, concat(quoted(path), ": no Z channel (a deep image needs depths)"));
        hasZBack_ = ch.findChannel("ZBack") != nullptr;
        rgb_ = ch.findChannel("AR") && ch.findChannel("AG") && ch.findChannel("AB");
        if (!rgb_ && !ch.findChannel("A"))
            throw Error(ErrorCode::format,
                        concat(quoted(path), ": no A channel (nor AR, AG and AB): nothing gives the opacity"));
        data_ = header().dataWindow();
        display_ = header().displayWindow();
        const long long dw = (long long)display_.max.x - display_.min.x + 1;
        const long long dh = (long long)display_.max.y - display_.min.y + 1;
        if (dw < 1 || dh < 1 || dw > kMaxExrExtent || dh > kMaxExrExtent)
            throw Error(ErrorCode::limit,
                        concat(quoted(path), ": display window ", dw, " x ", dh, " is outside 1..", kMaxExrExtent));
        const long long ww = (long long)data_.max.x - data_.min.x + 1;
        if (ww > kMaxExrExtent)
            throw Error(ErrorCode::limit, concat(quoted(path), ": data window is wider than ", kMaxExrExtent));
    }

    const Imf::Header& header() const { return tiledFile_ ? tiledFile_->header() : scanFile_->header(); }

    /// The same for the tiles of rows [ty0, ty1] of level 0: a raw tile holds
    /// its coordinates (16 bytes), then the three sizes.
    void checkTiles(int nx, int ty0, int ty1) {
        std::vector<char> raw;
        for (int ty = ty0; ty <= ty1; ++ty)
            for (int tx = 0; tx < nx; ++tx) {
                int dx = tx, dy = ty, lx = 0, ly = 0;
                std::uint64_t bytes = 0;
                tiledFile_->rawTileData(dx, dy, lx, ly, nullptr, bytes);
                if (bytes < 40 || bytes > fileBytes_)
                    throw Error(ErrorCode::corrupt, concat(quoted(path_), ": tile ", tx, ",", ty, " records ", bytes,
                                                           " bytes, more than the file has"));
                raw.resize(std::size_t(bytes));
                dx = tx, dy = ty, lx = 0, ly = 0;
                tiledFile_->rawTileData(dx, dy, lx, ly, raw.data(), bytes);
                checkUnpackedSize(raw.data() + 24, "tile " + std::to_string(tx) + "," + std::to_string(ty));
            }
    }

    /// A packed and an unpacked size, as OpenEXR writes them: the second must
    /// be one zlib could produce from the first (at most 1032:1, plus a little).
    void checkUnpackedSize(const char* sizes, const std::string& what) const {
        std::uint64_t packed = 0, unpacked = 0;
        std::memcpy(&packed, sizes, 8);  // little-endian, as OpenEXR files and this machine are
        std::memcpy(&unpacked, sizes + 8, 8);
        if (unpacked > packed * 1032 + 4096)
            throw Error(ErrorCode::corrupt, concat(quoted(path_), ": ", what, " records ", unpacked,
                                                   " unpacked bytes from ", packed, " packed bytes"));
    }

    /// OpenEXR allocates a chunk's unpacked size as the file records it, before
    /// it decompresses anything: a few damaged bytes could ask for gigabytes.
    /// Each chunk of rows [y0, y1) is read raw first (its size checked against
    /// the file), and its unpacked size must be one zlib could produce from its
    /// packed bytes (at most 1032:1, plus a little).
    void checkScanlineChunks(int y0, int y1) {
        const int linesPerChunk = header().compression() == Imf::ZIP_COMPRESSION ? 16 : 1;
        std::vector<char> raw;
        const int first = data_.min.y + (y0 - data_.min.y) / linesPerChunk * linesPerChunk;
        for (int y = first; y < y1; y += linesPerChunk) {
            std::uint64_t bytes = 0;
            scanFile_->rawPixelData(y, nullptr, bytes);
            if (bytes < 28 || bytes > fileBytes_)
                throw Error(ErrorCode::corrupt, concat(quoted(path_), ": the chunk of row ", y, " records ", bytes,
                                                       " bytes, more than the file has"));
            raw.resize(std::size_t(bytes));
            scanFile_->rawPixelData(y, raw.data(), bytes);
            checkUnpackedSize(raw.data() + 12, "the chunk of row " + std::to_string(y));
        }
    }
    bool rgb() const { return rgb_; }
    const Imath::Box2i& display() const { return display_; }

    /// Reads file rows [y0, y1) of the data window (clipped) into `band`.
    void read(int y0, int y1, Band& band) {
        y0 = std::max(y0, data_.min.y), y1 = std::min(y1, data_.max.y + 1);
        const int width = data_.max.x - data_.min.x + 1;
        if (y1 <= y0 || width <= 0) {
            band.reset(data_.min.x, y0, 0, 0);
            return;
        }
        if (scanFile_) {
            band.reset(data_.min.x, y0, width, y1 - y0);
            scanFile_->setFrameBuffer(band.frameBuffer(hasZBack_, !rgb_, false));
            scanFile_->readPixelSampleCounts(y0, y1 - 1);
            size(band);
            checkScanlineChunks(y0, y1);
            scanFile_->readPixels(y0, y1 - 1);
        } else {
            // Whole rows of tiles covering [y0, y1).
            const Imf::TileDescription td = tiledFile_->header().tileDescription();
            const int ty0 = (y0 - data_.min.y) / int(td.ySize), ty1 = (y1 - 1 - data_.min.y) / int(td.ySize);
            const int top = data_.min.y + ty0 * int(td.ySize);
            const int bottom = std::min(data_.max.y + 1, data_.min.y + (ty1 + 1) * int(td.ySize));
            band.reset(data_.min.x, top, width, bottom - top);
            tiledFile_->setFrameBuffer(band.frameBuffer(hasZBack_, !rgb_, false));
            const int nx = tiledFile_->numXTiles(0);
            tiledFile_->readPixelSampleCounts(0, nx - 1, ty0, ty1, 0, 0);
            size(band);
            checkTiles(nx, ty0, ty1);
            tiledFile_->readTiles(0, nx - 1, ty0, ty1, 0, 0);
        }
        for (auto& pixel : band.samples)
            for (DeepSample& s : pixel) {
                if (!hasZBack_) s.zBack = s.z;
                if (!rgb_) s.alphaRGB = {s.alpha, s.alpha, s.alpha};
            }
    }

private:
    void size(Band& band) const {
        std::uint64_t total = 0;
        for (std::size_t i = 0; i < band.counts.size(); ++i) {
            if (band.counts[i] > kMaxSamplesPerPixel)
                throw Error(ErrorCode::corrupt,
                            concat(quoted(path_), " pixel ", band.x0 + int(i % std::size_t(band.width)), ",",
                                   band.y0 + int(i / std::size_t(band.width)), ": ", band.counts[i],
                                   " samples (more than ", kMaxSamplesPerPixel, ")"));
            total += band.counts[i];
        }
        if (total > kMaxSamplesPerBand)
            throw Error(ErrorCode::corrupt,
                        concat(quoted(path_), ": rows ", band.y0, "..", band.y0 + band.rows - 1, " hold ", total,
                               " samples (more than ", kMaxSamplesPerBand, " at once)"));
        for (std::size_t i = 0; i < band.counts.size(); ++i) band.samples[i].resize(band.counts[i]);
        band.point();
    }

    std::string path_;
    std::unique_ptr<Imf::MultiPartInputFile> file_;
    std::unique_ptr<Imf::DeepScanLineInputPart> scanFile_;
    std::uint64_t fileBytes_ = 0;
    std::unique_ptr<Imf::DeepTiledInputPart> tiledFile_;
    bool hasZBack_ = false;
    bool rgb_ = false;
    Imath::Box2i data_, display_;
};

template <class T>
const T* findAttribute(const Imf::Header& h, const char* name) {
    return h.findTypedAttribute<T>(name);
}

/// The camera from our exact attributes, or nothing when they are absent.
std::optional<LightCamera> cameraFromDsmAttributes(const Imf::Header& h) {
    const auto* m = findAttribute<Imf::M44dAttribute>(h, "dsm:worldToLight");
    const auto* p = findAttribute<Imf::StringAttribute>(h, "dsm:projection");
    const auto* lo = findAttribute<Imf::V2dAttribute>(h, "dsm:screenWindowMin");
    const auto* hi = findAttribute<Imf::V2dAttribute>(h, "dsm:screenWindowMax");
    if (!m || !p || !lo || !hi) return std::nullopt;
    LightCamera cam;
    if (p->value() == "perspective") cam.projection = Projection::Perspective;
    else if (p->value() == "orthographic") cam.projection = Projection::Orthographic;
    else
        throw Error(ErrorCode::corrupt,
                    concat("dsm:projection '", p->value(), "' is neither perspective nor orthographic"));
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) cam.worldToLight[std::size_t(4 * j + i)] = m->value()[i][j];
    cam.screenWindow = {lo->value().x, hi->value().x, lo->value().y, hi->value().y};
    if (const auto* n = findAttribute<Imf::DoubleAttribute>(h, "dsm:nearPlane")) cam.nearPlane = n->value();
    cam.validate();
    return cam;
}

std::optional<LightCamera> cameraFromStandardAttributes(const Imf::Header& h) {
    if (!Imf::hasWorldToCamera(h) || !Imf::hasWorldToNDC(h)) return std::nullopt;
    Matrix4 c{}, n{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) c[i][j] = Imf::worldToCamera(h)[i][j], n[i][j] = Imf::worldToNDC(h)[i][j];
    return cameraFromStandardMatrices(c, n);
}

/// A centred light of the given width (field of view or orthographic window)
/// with square pixels, placed by the file's worldToCamera when it has one.
LightCamera cameraFromWidth(const Imf::Header& h, const ExrImportOptions& options, std::uint32_t width,
                            std::uint32_t height) {
    LightCamera cam;
    double half = 0.0;
    if (options.fieldOfView) {
        const double degrees = *options.fieldOfView;
        if (!(degrees > 0.0 && degrees < 180.0))
            throw Error(ErrorCode::argument, concat("field of view ", degrees, " is not in (0, 180) degrees"));
        cam.projection = Projection::Perspective;
        half = std::tan(degrees * std::numbers::pi / 360.0);
    } else {
        const double width = options.orthoWidth.value_or(0.0);
        if (!std::isfinite(width) || !(width > 0.0))
            throw Error(ErrorCode::argument, concat("the orthographic width ", width, " is not a finite value > 0"));
        cam.projection = Projection::Orthographic;
        half = width / 2.0;
    }
    const double halfHeight = half * double(height) / double(width);
    cam.screenWindow = {-half, half, -halfHeight, halfHeight};
    if (Imf::hasWorldToCamera(h))
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) cam.worldToLight[std::size_t(4 * j + i)] = Imf::worldToCamera(h)[i][j];
    cam.validate();
    return cam;
}

}  // namespace

ExrImportReport importDeepExr(const std::string& exrPath, const std::string& dsmPath,
                              const ExrImportOptions& options) try {
    checkErrorBoundOption(options.maxLinearError, "deep EXR import: the linearisation error");
    if (options.tolerance && !(std::isfinite(*options.tolerance) && *options.tolerance >= 0.0))
        throw Error(ErrorCode::argument, concat("deep EXR import: the tolerance must be a finite value >= 0, got ",
                                                *options.tolerance));
    checkOutputPath(dsmPath);
    refuseOutputOverInputs(dsmPath, {exrPath});
    try {
        DeepExrSource source(exrPath);
        const Imf::Header& h = source.header();
        ExrImportReport report;
        report.channels = source.rgb() ? 3 : 1;
        const Imath::Box2i display = source.display();
        report.width = std::uint32_t(display.max.x - display.min.x + 1);
        report.height = std::uint32_t(display.max.y - display.min.y + 1);

        WriterOptions w;
        if (options.camera) {
            w.camera = *options.camera;
            report.cameraSource = "option";
        } else if (options.fieldOfView || options.orthoWidth) {
            w.camera = cameraFromWidth(h, options, report.width, report.height);
            report.cameraSource = options.fieldOfView ? "field of view" : "orthographic width";
        } else {
            std::optional<LightCamera> cam;
            try {
                if ((cam = cameraFromDsmAttributes(h))) report.cameraSource = "dsm attributes";
                else if ((cam = cameraFromStandardAttributes(h))) report.cameraSource = "standard attributes";
            } catch (const Error& e) {
                throw Error(ErrorCode::corrupt, concat(quoted(exrPath), ": light camera: ", e.what()));
            }
            if (!cam)
                throw Error(ErrorCode::argument, concat(quoted(exrPath),
                                                        ": no light camera: neither dsm:* nor worldToCamera and "
                                                        "worldToNDC attributes (give one explicitly)"));
            w.camera = *cam;
        }
        const auto* fileTolerance = findAttribute<Imf::DoubleAttribute>(h, "dsm:tolerance");
        report.tolerance = options.tolerance ? *options.tolerance
                           : fileTolerance && fileTolerance->value() >= 0.0 && std::isfinite(fileTolerance->value())
                               ? fileTolerance->value()
                               : kDefaultExrImportTolerance;
        if (!std::isfinite(report.tolerance) || report.tolerance < 0.0)
            throw Error(ErrorCode::argument,
                        concat("the tolerance must be a finite value >= 0, got ", report.tolerance));
        report.maxLinearError = options.maxLinearError.value_or(std::clamp(report.tolerance / 4.0, 1e-5, 1e-3));

        w.width = report.width;
        w.height = report.height;
        w.tileSize = options.tileSize;
        w.channels = report.channels;
        w.tolerance = report.tolerance;
        w.mipLevels = options.mipLevels;
        w.zlibLevel = options.zlibLevel;
        if (const auto* f = findAttribute<Imf::StringAttribute>(h, "dsm:filter")) {
            if (const auto filter = pixelFilterFromName(f->value())) w.filter = *filter;
        }
        if (const auto* fw = findAttribute<Imf::DoubleAttribute>(h, "dsm:filterWidth"))
            if (fw->value() > 0.0 && std::isfinite(fw->value())) w.filterWidth = fw->value();
        if (const auto* m = findAttribute<Imf::StringAttribute>(h, "dsm:metadata")) {
            w.metadata = m->value();
        } else {
            w.metadata = nlohmann::json{{"source", "deep OpenEXR"},
                                        {"file", std::filesystem::path(exrPath).filename().string()}}
                             .dump();
        }

        MapWriter writer(dsmPath, w);
        const int mapWidth = int(report.width);
        Band band;
        std::vector<VisibilityFunction> rows;  // the current row of map tiles
        std::vector<VisibilityFunction> tile;
        for (std::uint32_t ty = 0; ty < writer.tilesY(); ++ty) {
            const int top = int(ty * w.tileSize), rowCount = int(writer.tileHeight(ty));
            rows.assign(std::size_t(mapWidth) * std::size_t(rowCount), VisibilityFunction(report.channels));
            source.read(display.min.y + top, display.min.y + top + rowCount, band);
            std::vector<std::uint64_t> vertices(std::size_t(band.rows > 0 ? band.rows : 0), 0);
            tbb::parallel_for(0, band.rows, [&](int r) {
                const int fileY = band.y0 + r, mapY = fileY - display.min.y - top;
                if (mapY < 0 || mapY >= rowCount) return;
                for (int c = 0; c < band.width; ++c) {
                    const int fileX = band.x0 + c, mapX = fileX - display.min.x;
                    if (mapX < 0 || mapX >= mapWidth) continue;
                    const auto& samples = band.samples[std::size_t(r) * std::size_t(band.width) + std::size_t(c)];
                    if (samples.empty()) continue;
                    try {
                        const VisibilityFunction exact =
                            visibilityFromDeepSamples(samples, report.channels, report.maxLinearError);
                        auto& out = rows[std::size_t(mapY) * std::size_t(mapWidth) + std::size_t(mapX)];
                        out = compress(exact, report.tolerance);
                        vertices[std::size_t(r)] += out.size();
                    } catch (const Error& e) {
                        throw Error(ErrorCode::corrupt,
                                    concat(quoted(exrPath), " pixel ", fileX, ",", fileY, ": ", e.what()));
                    }
                }
            });
            for (const auto& pixel : band.samples) report.samples += pixel.size();
            for (std::uint64_t v : vertices) report.vertices += v;
            for (std::uint32_t tx = 0; tx < writer.tilesX(); ++tx) {
                tile.clear();
                for (std::uint32_t y = 0; y < writer.tileHeight(ty); ++y)
                    for (std::uint32_t x = 0; x < writer.tileWidth(tx); ++x)
                        tile.push_back(rows[std::size_t(y) * std::size_t(mapWidth) + tx * w.tileSize + x]);
                writer.writeTile(tx, ty, tile);
            }
        }
        writer.finish();
        return report;
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error(ErrorCode::io, concat(quoted(exrPath), ": ", e.what()));
    }
} catch (const Error& e) {
    throw detail::withOneOf(e, {exrPath, dsmPath});
}

DSM_NAMESPACE_END
