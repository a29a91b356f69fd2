#include "dsm/compressor.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "simd_lanes.h"
#include "slope_blocks.h"
#include "vertex_queue.h"
#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

// Largest rounding error of a value in [0, 1] stored as float32: half the
// float spacing just below 1.
constexpr double kStoreRounding = 0x1p-25;

// A segment is balanced when a feasible line's signed error against the input
// averages to at most this share of the band over the segment.
constexpr double kBalance = 0.1;
// The most vertices a centred segment takes past its balanced point and may
// take again: each input vertex is then taken at most this many times more.
constexpr std::size_t kMostPending = 4096;
// The most vertices taken again as one run (Greedy::replay()): a longer
// stretch is more often cut short by the segment's end, and its band is
// compared vertex by vertex first.
constexpr std::size_t kReplayRun = 32;

// pushValid() checks its input only in debug builds.
#ifdef NDEBUG
constexpr bool kTrustValidInput = true;
#else
constexpr bool kTrustValidInput = false;
#endif

// Calls f(0), ..., f(C - 1), unrolled: the per-vertex loops over channels are
// too short for a loop to pay.
template <int C, typename F>
inline void forEachChannel(F&& f) {
    [&]<int... c>(std::integer_sequence<int, c...>) { (f(c), ...); }(std::make_integer_sequence<int, C>{});
}

using detail::Double2;
using detail::laneMask;
using detail::Mask2;

// A range of slopes lo <= m <= hi of lines from a segment origin, each bound a
// numerator over a positive denominator (a depth difference), so that a new
// bound is compared by cross products instead of divisions. The two bounds
// share one two-lane register, the lower one negated: num = {hiNum, -loNum},
// den = {hiDen, loDen}; "a vertex lowers the top" and "it raises the bottom"
// are then one lane comparison each, and since negation is exact every
// product and comparison is the one of the bound it stands for.
struct SlopeWindow {
    Double2 num, den;
    // What hiNum * dz must reach for the segment's end dz beyond the origin to
    // stay at or above 0 (-origin * hiDen), or +inf (never reached) when the
    // window is inconsistent; kept by limitEnd() for the run loop. In both
    // lanes, so that the window is three whole registers: a lone double would
    // be copied as half a register and read back as a whole one, which the
    // processor cannot forward from the store (a stall on every push()).
    Double2 endLimit;

    double lo() const { return -num[1] / den[1]; }
    double hi() const { return num[0] / den[0]; }

    // lo <= hi and lo <= 0: the conditions that do not depend on the end.
    bool consistent() const { return (-num[1] * den[0] <= num[0] * den[1]) & (-num[1] <= 0.0); }

    // Whether a feasible slope is left for a segment ending dz beyond an
    // origin at V = origin: max(lo, -origin / dz) <= min(hi, 0).
    bool feasible(double origin, double dz) const { return consistent() & (-origin * den[0] <= num[0] * dz); }

    // The feasible slopes [lo, hi] for a segment ending dz beyond an origin at
    // V = origin: the window's, kept from rising and from ending below 0
    // (lo > hi moved up to hi).
    void feasibleSlopes(double origin, double dz, double& lo, double& hi) const {
        hi = std::min(this->hi(), 0.0);
        lo = std::min(std::max(this->lo(), -origin / dz), hi);
    }

    void limitEnd(double origin) {
        const double limit = consistent() ? -origin * den[0] : std::numeric_limits<double>::infinity();
        endLimit = Double2{limit, limit};
    }

    // The window of the slopes [lo, hi] themselves (each over a denominator
    // of 1), from an origin at V = origin.
    static SlopeWindow ofSlopes(double lo, double hi, double origin) {
        SlopeWindow w;
        w.num = Double2{hi, -lo};
        w.den = Double2{1.0, 1.0};
        w.limitEnd(origin);
        return w;
    }
};

// A centred segment's longest stretch between input vertices so far (the
// first of equals): its length, its end's depth beyond the origin, and the
// input's values there (detail::CentredRun, detail::kPlateauShare).
struct LongestStretch {
    double length = 0.0, endDz = 0.0;
    double endV[kMaxChannels] = {};
};

// The greedy segment builder of Lokovic & Veach §3.3 for one layer at a time,
// writing straight into `out`. The segment origin is the last stored vertex
// (exact float values), or a "virtual" origin at V = 1 while the layer has
// stored nothing (V = 1 is implicit before the first vertex). The channel
// count (1 or 3) is a template argument of the per-vertex work, and a
// 1-channel builder can be widened to 3 mid-stream (see widen()).
class Greedy {
public:
    Greedy(int channels, double tolerance, bool keepCounts, bool centred)
        : channels_(channels),
          centred_(centred),
          keepCounts_(keepCounts),
          // Leave room for the float rounding of segment end points, so that the
          // stored function, not just the ideal line, is within tolerance.
          band_(std::max(0.0, tolerance - 2.0 * kStoreRounding)),
          out_(channels, keepCounts) {}

    int channels() const { return channels_; }
    bool segmentOpen() const { return open_; }
    // The half-width of the target windows for exact input.
    double window() const { return band_; }

    // One input vertex with target windows v[c] +- band (0 <= band <= window()).
    template <int C>
    void push(float z, const double* v, std::uint32_t count, double band) {
        pushOne<C>(z, v, count, band);
        replay<C>();
    }

    // push() of a vertex that does not extend the open segment (if any).
    template <int C>
    void pushBeyond(float z, const double* v, std::uint32_t count, double band) {
        pushBeyondOne<C>(z, v, count, band);
        replay<C>();
    }

    // extendRun() of one vertex, inlined: the per-vertex push() path.
    template <int C>
    [[gnu::flatten]] bool extendOne(float z, const double* v, std::uint32_t count, double band) {
        return (centred_ ? extendRun<C, true, true>(&z, v, &count, 1, band)
                         : extendRun<C, true, false>(&z, v, &count, 1, band)) == 1;
    }

    // Extends the open segment by the leading vertices of a run that fit it:
    // narrows its slope window by each vertex's target window and stops (and
    // leaves the window as it was) at the first vertex that would leave no
    // feasible slope. Returns how many it took (0 when no segment is open).
    // Centred, the segment may instead close there at its balanced point, in
    // this run: the count then ends at that point, and the vertices after it
    // are the caller's to take again (see extendCentredRunBySlopes()).
    // The window the data defines (lines within band of the input) is kept;
    // the feasible slopes are those of it that also keep the output from
    // rising (slope <= 0) and from going below 0 at the segment's end
    // (slope >= -origin / dz; V <= 1 follows from not rising). The window
    // lives in registers through the loop: this is the per-vertex work.
    //
    // Only the vertices that move a bound (about a third on a hair pixel)
    // narrow and check the window; for the others only the end-above-0
    // condition can change: one product already made and one comparison.
    template <int C, typename T>
    std::size_t extendRun(const float* z, const T* v, const std::uint32_t* counts, std::size_t n, double band) {
        if (!open_) return 0;
        if (centred_)
            return counts ? extendRun<C, true, true>(z, v, counts, n, band)
                          : extendRun<C, false, true>(z, v, counts, n, band);
        return counts ? extendRun<C, true, false>(z, v, counts, n, band) : extendRun<C, false, false>(z, v, counts, n, band);
    }

    // A centred segment's input advanced by a vertex at depth z, dz beyond
    // the origin, with values v[c]: twice its integral (the trapezoid from
    // the previous vertex), its last vertex, and its longest stretch between
    // vertices (the first of equals). The walks of takeCentredVertex() and
    // the centred blocks do the same, in that order.
    template <int C, typename T>
    static void advanceInput(float z, double dz, const T* v, double& previousZ, LongestStretch& longest,
                             double* twiceIntegral, double* previousV) {
        const double step = static_cast<double>(z) - previousZ;
        previousZ = z;
        const bool longer = step > longest.length;
        if (longer) {
            longest.length = step;
            longest.endDz = dz;
        }
        forEachChannel<C>([&](int c) {
            const double value = static_cast<double>(v[c]);
            twiceIntegral[c] += step * (previousV[c] + value);
            previousV[c] = value;
            if (longer) longest.endV[c] = value;
        });
    }

    // With a band > 0 the window is kept as slopes (below); a band of 0 keeps
    // the exact cross products here. A vertex that moves bounds updates them
    // by branches for one channel (on smooth input nearly every vertex moves
    // the same bound, and a select would chain each vertex's comparison to
    // the previous one's result) and by selects for RGB (six bounds make too
    // many branches to predict).
    template <int C, bool withCounts, bool Centred, typename T>
    std::size_t extendRun(const float* z, const T* v, const std::uint32_t* counts, std::size_t n, double band) {
        if constexpr (C == 1 && !Centred)
            if (band > 0.0) return extendRunBySlopes<withCounts>(z, v, counts, n, band);
        if constexpr (Centred)
            if (band > 0.0) return extendCentredRunBySlopes<C, withCounts>(z, v, counts, n, band);
        if constexpr (C == 3 && !Centred)
            if (band > 0.0) return extendRgbRunBySlopes<withCounts>(z, v, counts, n, band);
        SlopeWindow w[C];
        Double2 origin[C];
        forEachChannel<C>([&](int c) {
            w[c] = window_[c];
            origin[c] = Double2{originV_[c], originV_[c]};
        });
        const Double2 halfWidth = {band, -band};
        const Double2 negateLower = {1.0, -1.0};
        const double originZ = originZ_;
        // Centred: the input's integral over the segment so far (twice it:
        // the trapezoids' halves are left out), and its last vertex.
        double twiceIntegral[C], previousV[C];
        double previousZ = lastZ_;
        LongestStretch longest = longest_;
        if constexpr (Centred)
            forEachChannel<C>([&](int c) {
                twiceIntegral[c] = twiceIntegral_[c];
                previousV[c] = inputV_[c];
            });
        std::uint64_t count = 0;
        std::size_t i = 0;
        for (; i < n; ++i) {
            const double dz = static_cast<double>(z[i]) - originZ;  // > 0 while a segment is open
            const Double2 dz2 = {dz, dz};
            Double2 target[C], product[C];
            int moves = 0;
            bool aboveZero = true;
            forEachChannel<C>([&](int c) {
                const double value = static_cast<double>(v[i * C + static_cast<std::size_t>(c)]);
                // {top, -bottom}: top = value + band - origin, bottom = value - band - origin
                target[c] = ((Double2{value, value} + halfWidth) - origin[c]) * negateLower;
                // lane 0: top * hiDen < hiNum * dz; lane 1: bottom * loDen > loNum * dz
                product[c] = w[c].num * dz2;
                moves |= laneMask(target[c] * w[c].den < product[c]) << (2 * c);
                aboveZero &= w[c].endLimit[0] <= product[c][0];
            });
            if (moves != 0) {
                SlopeWindow narrowed[C];
                bool feasible = true;
                forEachChannel<C>([&](int c) {
                    if constexpr (C == 1) {
                        narrowed[c] = w[c];
                        if (moves & 1) {
                            narrowed[c].num[0] = target[c][0];
                            narrowed[c].den[0] = dz;
                        }
                        if (moves & 2) {
                            narrowed[c].num[1] = target[c][1];
                            narrowed[c].den[1] = dz;
                        }
                    } else {
                        const Mask2 moved = target[c] * w[c].den < product[c];
                        narrowed[c].num = moved ? target[c] : w[c].num;
                        narrowed[c].den = moved ? dz2 : w[c].den;
                    }
                    feasible &= narrowed[c].feasible(originV_[c], dz);
                });
                if (!feasible) break;
                forEachChannel<C>([&](int c) {
                    w[c] = narrowed[c];
                    w[c].limitEnd(originV_[c]);
                });
            } else if (!aboveZero) {
                break;
            }
            if constexpr (withCounts) count += counts[i];
            if constexpr (Centred) {
                advanceInput<C>(z[i], dz, &v[i * C], previousZ, longest, twiceIntegral, previousV);
                const std::uint32_t vertexCount = withCounts ? counts[i] : 0u;
                noteBalance<C>(w, twiceIntegral, longest, previousV, z[i], &v[i * C], vertexCount, band,
                               segmentCount_ + count);
            }
        }
        if constexpr (Centred) longest_ = longest;
        forEachChannel<C>([&](int c) {
            window_[c] = w[c];
            if constexpr (Centred) {
                twiceIntegral_[c] = twiceIntegral[c];
                inputV_[c] = previousV[c];
            }
        });
        segmentCount_ += count;
        if (i > 0) lastZ_ = z[i - 1];
        return i;
    }

    // extendRun() for one channel, not centred, with a band > 0 (a band of 0
    // needs the exact cross products: its window is a single slope). The
    // window is held as two slopes, and each vertex's bounds are slopes too
    // (slope_blocks.h). The window after a vertex is the least top and the
    // greatest bottom so far, and min and max are exact, so a block of
    // vertices taken at once leaves the window that taking them one by one
    // would; and a window feasible at a block's last vertex was feasible at
    // each before it (feasibleWindow()). So whole blocks are taken with no
    // branch a vertex to mispredict (takeSlopeBlocks()), and only the block
    // where the segment ends, and the run's last vertices, one by one.
    template <bool withCounts, typename T>
    std::size_t extendRunBySlopes(const float* z, const T* v, const std::uint32_t* counts, std::size_t n,
                                  double band, const double* bands = nullptr) {
        if (n == 0) return 0;
        const detail::SlopeFrame frame = detail::slopeFrame(originZ_, originV_[0], band);
        double hi = window_[0].hi(), lo = window_[0].lo();
        std::uint64_t count = 0;
        std::size_t taken = 0;
        if (blocksFit(z, n))
            taken = detail::takeSlopeBlocks(z, v, bands, withCounts ? counts : nullptr, n, frame, lo, hi, count);
        for (; taken < n; ++taken) {
            const detail::VertexSlopes s =
                detail::vertexSlopes(z[taken], v[taken], bands ? detail::withBand(frame, bands[taken]) : frame);
            const double nextHi = std::min(hi, s.top), nextLo = std::max(lo, s.bottom);
            if (!detail::feasibleWindow(nextLo, nextHi, frame.originV, s.dz)) break;
            hi = nextHi;
            lo = nextLo;
            if constexpr (withCounts) count += counts[taken];
        }
        window_[0] = SlopeWindow::ofSlopes(lo, hi, frame.originV);
        segmentCount_ += count;
        if (taken > 0) lastZ_ = z[taken - 1];
        return taken;
    }

    // Whether a run of n vertices can be taken in blocks of eight: n >= 8 and
    // every depth difference from the origin in [kLeastFastDepth,
    // kMostFastDepth]. Depths never fall along a run, so its first and last
    // bound them all.
    bool blocksFit(const float* z, std::size_t n) const {
        return n >= 8 && static_cast<double>(z[0]) - originZ_ >= detail::kLeastFastDepth &&
               static_cast<double>(z[n - 1]) - originZ_ <= detail::kMostFastDepth;
    }

    // extendRun() centred, with a band > 0, for one channel or RGB: each
    // channel's window as two slopes, each vertex's bounds as vertexSlopes()
    // makes them (one 1 / dz for the channels), and whether the segment can
    // be balanced ending at each vertex worked out in slopes too, with that
    // 1 / dz instead of the divisions of balanced(): the same test
    // (takeCentredVertex()). Blocks of eight go at once where they can
    // (takeCentredBlocks() and takeCentredRgbBlocks(), the same arithmetic),
    // the run's last few vertices one by one. Each vertex's band is `band`,
    // or bands[i] (grey RGB, one channel). The run's last balanced vertex is
    // kept by its index, and the run ends as endCentredRun() says: the
    // segment may close at that vertex within the run, the count returned
    // then ending there.
    // Not inlined: extendOne() would otherwise carry all of it into the
    // greedy rule's vertex-by-vertex push().
    template <int C, bool withCounts, typename T>
    [[gnu::noinline]] std::size_t extendCentredRunBySlopes(const float* z, const T* v, const std::uint32_t* counts,
                                                           std::size_t n, double band,
                                                           const double* bands = nullptr) {
        if (n == 0) return 0;
        constexpr std::size_t nc = C;
        detail::CentredFrameOf<C> frame;
        detail::CentredRunOf<C> r{};
        for (int c = 0; c < C; ++c) {
            frame.slopes[c] = detail::slopeFrame(originZ_, originV_[c], band);
            r.lo[c] = window_[c].lo();
            r.hi[c] = window_[c].hi();
            r.twiceIntegral[c] = twiceIntegral_[c];
            r.previousV[c] = inputV_[c];
            r.longestEndV[c] = longest_.endV[c];
        }
        frame.margin = kBalance * band_;
        r.previousZ = lastZ_;
        r.count = 0;
        r.longest = longest_.length;
        r.longestEndDz = longest_.endDz;
        r.balancedAt = detail::kNotBalanced;
        const std::uint32_t* vertexCounts = withCounts ? counts : nullptr;
        std::size_t i = 0;
        if (blocksFit(z, n)) {
            if constexpr (C == 1)
                i = detail::takeCentredBlocks(z, v, bands, vertexCounts, n, frame, r);
            else
                i = detail::takeCentredRgbBlocks(z, v, vertexCounts, n, frame, r);
        }
        if (C == 1 && bands) {
            // The margin stays the run's: balanced() measures it from band_ too.
            for (; i < n; ++i) {
                const detail::CentredFrameOf<C> own{{detail::withBand(frame.slopes[0], bands[i])}, frame.margin};
                if (!detail::takeCentredVertex(z[i], v + i * nc, withCounts ? counts[i] : 0u, i, own, r)) break;
            }
        } else {
            for (; i < n; ++i)
                if (!detail::takeCentredVertex(z[i], v + i * nc, withCounts ? counts[i] : 0u, i, frame, r)) break;
        }
        return endCentredRun<C>(z, v, vertexCounts, n, i, band, bands, r);
    }

    // Ends a centred run of C channels that took its vertices up to i
    // (exclusive), in the state r. Its last balanced vertex r.balancedAt
    // (kNotBalanced when none), with the state there, becomes the balanced
    // point. When the segment then closes within the run (i < n) and none of
    // its vertices waits from an earlier run, it closes at that vertex here,
    // and the count returned ends there: the caller takes the vertices after
    // it again from its own arrays, as replay() would take them from copies.
    // Otherwise the vertices after it wait in pending_ (each of band
    // bands[k], or all of `band`), as notePoint() would leave them vertex by
    // vertex; the state after the run becomes the open segment's, and i is
    // returned. Inlined: a call costs a one-channel run 2 % more instructions.
    template <int C, typename T>
    [[gnu::always_inline]] std::size_t endCentredRun(const float* z, const T* v, const std::uint32_t* counts,
                                                     std::size_t n, std::size_t i, double band, const double* bands,
                                                     const detail::CentredRunOf<C>& r) {
        constexpr std::size_t nc = C;
        const std::size_t b = r.balancedAt;
        std::size_t waiting = 0;  // the first of the run's vertices after its balanced point
        if (b != detail::kNotBalanced) {
            SlopeWindow w[C];
            double inputV[C];
            LongestStretch longest;
            longest.length = r.balancedLongest;
            longest.endDz = r.balancedLongestEndDz;
            for (int c = 0; c < C; ++c) {
                w[c] = SlopeWindow::ofSlopes(r.balancedLo[c], r.balancedHi[c], originV_[c]);
                inputV[c] = static_cast<double>(v[b * nc + static_cast<std::size_t>(c)]);
                longest.endV[c] = r.balancedLongestEndV[c];
            }
            notePoint<C>(true, w, r.balancedIntegral, longest, inputV, z[b], v + b * nc, counts ? counts[b] : 0u, band,
                         segmentCount_ + r.balancedCount);
            waiting = b + 1;
        }
        if (balancedPoint_.valid && pending_.empty() && i < n && i > waiting && i - waiting <= kMostPending) {
            closeSegment<C>(true);
            return waiting;
        }
        noteUnbalanced<C>(z + waiting, v + waiting * nc, counts ? counts + waiting : nullptr, i - waiting, band,
                          bands ? bands + waiting : nullptr);
        for (int c = 0; c < C; ++c) {
            window_[c] = SlopeWindow::ofSlopes(r.lo[c], r.hi[c], originV_[c]);
            twiceIntegral_[c] = r.twiceIntegral[c];
            inputV_[c] = r.previousV[c];
            longest_.endV[c] = r.longestEndV[c];
        }
        longest_.length = r.longest;
        longest_.endDz = r.longestEndDz;
        segmentCount_ += r.count;
        if (i > 0) lastZ_ = z[i - 1];
        return i;
    }

    // extendRun() for RGB, greedy, with a band > 0: each channel's window as
    // two slopes and each vertex's bounds as vertexSlopes() makes them, with
    // one 1 / dz for the three channels; the segment takes a vertex while
    // every channel's window stays feasible. Whole blocks of eight go first
    // (takeRgbSlopeBlocks(), the same windows bit for bit).
    template <bool withCounts, typename T>
    std::size_t extendRgbRunBySlopes(const float* z, const T* v, const std::uint32_t* counts, std::size_t n,
                                     double band) {
        constexpr int C = 3;
        detail::SlopeFrame frame[C];
        double lo[C], hi[C];
        forEachChannel<C>([&](int c) {
            frame[c] = detail::slopeFrame(originZ_, originV_[c], band);
            lo[c] = window_[c].lo();
            hi[c] = window_[c].hi();
        });
        std::uint64_t count = 0;
        std::size_t i = 0;
        if (blocksFit(z, n))
            i = detail::takeRgbSlopeBlocks(z, v, withCounts ? counts : nullptr, n, frame, lo, hi, count);
        for (; i < n; ++i) {
            const T* values = v + i * C;
            const double dz = static_cast<double>(z[i]) - originZ_;
            const double inverse = detail::depthInverse(z[i], originZ_, dz);
            double nextLo[C], nextHi[C];
            bool feasible = true;
            forEachChannel<C>([&](int c) {
                const detail::VertexSlopes s = detail::slopesScaledBy(inverse, dz, values[c], frame[c]);
                nextHi[c] = std::min(hi[c], s.top);
                nextLo[c] = std::max(lo[c], s.bottom);
                feasible &= detail::feasibleWindow(nextLo[c], nextHi[c], frame[c].originV, dz);
            });
            if (!feasible) break;
            std::copy(nextLo, nextLo + C, lo);
            std::copy(nextHi, nextHi + C, hi);
            if constexpr (withCounts) count += counts[i];
        }
        forEachChannel<C>([&](int c) { window_[c] = SlopeWindow::ofSlopes(lo[c], hi[c], frame[c].originV); });
        segmentCount_ += count;
        if (i > 0) lastZ_ = z[i - 1];
        return i;
    }

    // extendRun() of one channel whose vertices have bands of their own (grey
    // RGB input: the channels' mid-range, its band narrowed by their spread),
    // each > 0. Centred, they go through extendCentredRunBySlopes() with
    // their bands, and the segment may close early within the run.
    std::size_t extendGreyRun(const float* z, const double* mids, const double* bands, const std::uint32_t* counts,
                              std::size_t n) {
        if (!open_) return 0;
        // The run's own band (band_) is not read where each vertex has one.
        if (centred_)
            return counts ? extendCentredRunBySlopes<1, true>(z, mids, counts, n, band_, bands)
                          : extendCentredRunBySlopes<1, false>(z, mids, counts, n, band_, bands);
        return counts ? extendRunBySlopes<true>(z, mids, counts, n, band_, bands)
                      : extendRunBySlopes<false>(z, mids, counts, n, band_, bands);
    }

    // Ends the current layer: closes the open segment and makes sure the layer
    // stores at least one vertex when it must (its end depth, or counts).
    void finishLayer(bool recordEnd) {
        if (!started_) return;
        while (open_) {  // a replay may open a segment again
            if (channels_ == 1) {
                closeSegment<1>(backtracks());
                replay<1>();
            } else {
                closeSegment<3>(backtracks());
                replay<3>();
            }
        }
        if (!originStored_ && (recordEnd || originCount_ > 0)) storeOrigin();
        started_ = false;
    }

    void beginLayer() {
        if (!out_.empty()) out_.beginLayer();
    }

    // Turns a 1-channel builder into a 3-channel one with every channel equal
    // to the single one so far: its output is replicated and its open windows
    // become each channel's windows. Valid for three input channels that the
    // single channel's targets kept within every channel's tolerance.
    void widen() {
        VisibilityFunction wide(3, out_.hasCounts());
        wide.reserve(out_.size());
        std::size_t layer = 1;
        for (std::size_t i = 0; i < out_.size(); ++i) {
            for (; layer < out_.layerCount() && out_.layerBegin(layer) == i; ++layer) wide.beginLayer();
            const float v[3] = {out_.value(i), out_.value(i), out_.value(i)};
            wide.append(out_.z(i), v, out_.count(i));
        }
        for (; layer < out_.layerCount(); ++layer) wide.beginLayer();
        out_ = std::move(wide);
        for (int c = 1; c < 3; ++c) {
            originV_[c] = originV_[0];
            inputV_[c] = inputV_[0];
            twiceIntegral_[c] = twiceIntegral_[0];
            longest_.endV[c] = longest_.endV[0];
            window_[c] = window_[0];
        }
        channels_ = 3;
        // The vertices after the balanced point were the channels' mid-range:
        // the segment closes where its window does.
        balancedPoint_.valid = false;
        pending_.clear();
    }

    // Hands the output to `result`, keeping `result`'s storage for the next
    // function; restart() follows.
    void take(VisibilityFunction& result) { std::swap(result, out_); }

    // Starts the next function, of `channels` channels.
    void restart(int channels) {
        channels_ = channels;
        out_.reset(channels, keepCounts_);
        started_ = false;
        open_ = false;
        balancedPoint_.valid = false;
        pending_.clear();
        toReplay_.clear();
    }

private:
    // Inlined: push() per vertex is the path of Compressor::push(), and the
    // compiler's own choice made it a call (7 % slower on a hair pixel).
    template <int C>
    [[gnu::always_inline]] void pushOne(float z, const double* v, std::uint32_t count, double band) {
        if (!started_) {
            started_ = true;
            originZ_ = z;
            std::fill(originV_, originV_ + C, 1.0);
            originStored_ = false;
            originIsStep_ = false;
        }
        if (open_ && extendOne<C>(z, v, count, band)) return;
        pushBeyondOne<C>(z, v, count, band);
    }

    template <int C>
    void pushBeyondOne(float z, const double* v, std::uint32_t count, double band) {
        if (open_) {
            // A segment that closes at its balanced point hands the vertices
            // after it back to be taken again (replay()): this one goes after
            // them and before the rest, so it goes to the front first.
            const bool backtrack = backtracks();
            if (backtrack) toReplay_.pushFront<C>(z, v, count, band);
            if (closeSegment<C>(backtrack)) return;
        }
        if (z == originZ_) {
            absorbAtOrigin<C>(v, count, band);
            return;
        }
        open<C>(z, v, band);
        lastZ_ = z;
        segmentCount_ += count;
        if (centred_) noteBalance<C>(window_, twiceIntegral_, longest_, inputV_, z, v, count, band, segmentCount_);
    }

    // Opens a segment from the origin to its first vertex beyond the origin's
    // depth. Its window of feasible slopes is never empty: the origin is within
    // tolerance of the input there and the input never increases (rounding of
    // the origin aside, which closeSegment() absorbs).
    template <int C>
    void open(float z, const double* v, double band) {
        const double dz = static_cast<double>(z) - originZ_;
        for (int c = 0; c < C; ++c) {
            window_[c].num = Double2{v[c] + band - originV_[c], -(v[c] - band - originV_[c])};
            window_[c].den = Double2{dz, dz};
            window_[c].limitEnd(originV_[c]);
            if (centred_) {
                twiceIntegral_[c] = dz * (inputV_[c] + v[c]);
                inputV_[c] = v[c];
                longest_.endV[c] = v[c];
            }
        }
        if (centred_) {
            longest_.length = dz;  // the stretch from the origin
            longest_.endDz = dz;
        }
        open_ = true;
        balancedPoint_.valid = false;
        pending_.clear();
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
    template <int C>
    void absorbAtOrigin(const double* v, std::uint64_t count, double band) {
        if (centred_) std::copy(v, v + C, inputV_);  // the input at this depth from here on (right-continuous)
        bool fits = true;
        for (int c = 0; c < C; ++c)
            if (std::abs(v[c] - originV_[c]) > band) fits = false;
        if (fits) {
            addCount(count);
            return;
        }
        float stored[kMaxChannels];
        for (int c = 0; c < C; ++c) {
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

    // Whether a segment from the origin to depth z with this window, input
    // integral and longest stretch can be balanced: some feasible slope whose
    // line's mean signed error against the input is within kBalance * band (a
    // slope within 2 * kBalance * band / dz of the balanced one), whose end
    // is within as much of the input there (inputV), and which, when the
    // longest stretch is a plateau, passes within as much of the input where
    // that stretch ends (plateauEndSlopes()).
    template <int C>
    bool balanced(const SlopeWindow* w, const double* twiceIntegral, const LongestStretch& longest,
                  const double* inputV, float z) const {
        const double dz = static_cast<double>(z) - originZ_;
        const double margin = kBalance * band_;
        bool ok = true;
        forEachChannel<C>([&](int c) {
            const double o = originV_[c];
            double lo, hi;
            w[c].feasibleSlopes(o, dz, lo, hi);
            const double balanced = balancedSlope(c, twiceIntegral[c], dz), spread = 2.0 * margin / dz;
            double lowest = std::max({lo, balanced - spread, (inputV[c] - margin - o) / dz});
            double highest = std::min({hi, balanced + spread, (inputV[c] + margin - o) / dz});
            plateauEndSlopes(c, longest, dz, lowest, highest);
            ok &= lowest <= highest;
        });
        return ok;
    }

    // When the longest stretch is a plateau of a segment to depth dz,
    // narrows [lowest, highest] to the slopes whose line passes within
    // kBalance * band of the input where that stretch ends: a receiver behind
    // a plateau reads it there, and a segment that runs on into the next
    // surface's fall can be balanced on average by tilting along the plateau,
    // too dark at its end.
    void plateauEndSlopes(int c, const LongestStretch& longest, double dz, double& lowest, double& highest) const {
        if (!detail::isPlateau(longest.length, dz)) return;
        const double margin = kBalance * band_, atEnd = longest.endV[c] - originV_[c];
        lowest = std::max(lowest, (atEnd - margin) / longest.endDz);
        highest = std::min(highest, (atEnd + margin) / longest.endDz);
    }

    // After a vertex joins the open segment: a segment that can be balanced
    // ending there keeps it as its balanced point; otherwise the vertex waits
    // in pending_, to be taken again from the balanced point should the
    // segment not be balanced when it closes.
    template <int C, typename T>
    void noteBalance(const SlopeWindow* w, const double* twiceIntegral, const LongestStretch& longest,
                     const double* inputV, float z, const T* v, std::uint32_t count, double band,
                     std::uint64_t segmentCount) {
        notePoint<C>(balanced<C>(w, twiceIntegral, longest, inputV, z), w, twiceIntegral, longest, inputV, z, v,
                     count, band, segmentCount);
    }

    // noteBalance() with the balance worked out (`w` is read only when
    // the segment is balanced).
    template <int C, typename T>
    void notePoint(bool isBalanced, const SlopeWindow* w, const double* twiceIntegral, const LongestStretch& longest,
                   const double* inputV, float z, const T* v, std::uint32_t count, double band,
                   std::uint64_t segmentCount) {
        if (isBalanced) {
            BalancedPoint& b = balancedPoint_;
            b.valid = true;
            b.z = z;
            b.segmentCount = segmentCount;
            b.longest = longest;
            forEachChannel<C>([&](int c) {
                b.window[c] = w[c];
                b.twiceIntegral[c] = twiceIntegral[c];
                b.inputV[c] = inputV[c];
            });
            pending_.clear();
        } else {
            noteUnbalanced<C>(&z, v, &count, 1, band);
        }
    }

    // notePoint() of n vertices in a row at none of which the segment is
    // balanced (counts null for counts of 0; each of band bands[i], or all
    // of `band` when bands is null): each waits in pending_ while the
    // segment has a balanced point.
    template <int C, typename T>
    void noteUnbalanced(const float* z, const T* v, const std::uint32_t* counts, std::size_t n, double band,
                        const double* bands = nullptr) {
        if (!balancedPoint_.valid || n == 0) return;
        if (pending_.size() + n > kMostPending) {
            // Too far past it: the segment closes where its window does, so
            // that taking vertices again stays within a bounded share of the
            // work.
            balancedPoint_.valid = false;
            pending_.clear();
            return;
        }
        pending_.pushBack<C>(z, v, counts, n, band, bands);
    }

    // The centred end slope within [lo, hi]: of the slopes whose mean error
    // is within kBalance * band (and whose line passes within as much of a
    // plateau's end), the one whose line passes nearest the input where the
    // plateau ends, when the segment takes one in (a receiver behind it reads
    // it there), otherwise the one that ends nearest the input (so that the
    // next segment starts on it); without such a slope, the feasible one
    // nearest the balanced slope.
    double centredSlope(int c, double lo, double hi, double dz) const {
        const double balanced = balancedSlope(c, twiceIntegral_[c], dz), spread = 2.0 * kBalance * band_ / dz;
        double lowest = std::max(lo, balanced - spread), highest = std::min(hi, balanced + spread);
        plateauEndSlopes(c, longest_, dz, lowest, highest);
        if (lowest > highest) return std::clamp(balanced, lo, hi);
        if (detail::isPlateau(longest_.length, dz))
            return std::clamp((longest_.endV[c] - originV_[c]) / longest_.endDz, lowest, highest);
        return std::clamp((inputV_[c] - originV_[c]) / dz, lowest, highest);
    }

    // The slope of the line from the origin whose signed error against the
    // input (twice its integral over dz given) averages to zero: the line's
    // integral is origin * dz + slope * dz^2 / 2.
    double balancedSlope(int c, double twiceIntegral, double dz) const {
        return (twiceIntegral - 2.0 * originV_[c] * dz) / (dz * dz);
    }

    // Emits the segment from the origin to the last accepted input vertex and
    // makes its end the new origin. Centred, a segment that cannot be
    // balanced there but could at an earlier vertex (its balanced point) ends
    // at that vertex instead (`backtrack`: backtracks(), or true where the
    // vertices after it stay with the caller), and the vertices after it in
    // pending_ are handed to replay(): returns `backtrack`. Otherwise this is
    // Lokovic & Veach's greedy segment with their midpoint slope.
    //
    // Why centred: the greedy rule extends a segment as far as some line stays
    // within the band, so a segment along a plateau (behind a semi-transparent
    // surface) takes in the first steps of the fall that ends it (the next
    // surface), and its line tilts down along the whole plateau to reach them.
    // Ending at the plateau's last balanced vertex keeps the plateau level and
    // gives the fall its own segment.
    template <int C>
    bool closeSegment(bool backtrack) {
        if (backtrack) {
            const BalancedPoint& b = balancedPoint_;
            lastZ_ = b.z;
            segmentCount_ = b.segmentCount;
            longest_ = b.longest;
            for (int c = 0; c < C; ++c) {
                window_[c] = b.window[c];
                twiceIntegral_[c] = b.twiceIntegral[c];
                inputV_[c] = b.inputV[c];
            }
        }
        const double dz = static_cast<double>(lastZ_) - originZ_;
        float end[kMaxChannels];
        bool flat = true;
        for (int c = 0; c < C; ++c) {
            // The window the data itself defines, then moved into the feasible
            // range (no rising, no end below 0).
            const SlopeWindow& w = window_[c];
            double lo, hi;
            w.feasibleSlopes(originV_[c], dz, lo, hi);
            const double slope = centred_ ? centredSlope(c, lo, hi, dz)
                                          // Lokovic & Veach's midpoint, taken on the window the data
                                          // defines: clipping at V = 1 or at slope 0 first would tilt
                                          // flat runs (lit space) by eps / 2.
                                          : std::clamp(0.5 * (w.lo() + w.hi()), lo, hi);
            const double ideal = originV_[c] + slope * dz;
            end[c] = std::clamp(static_cast<float>(ideal), 0.0f, static_cast<float>(originV_[c]));
            if (end[c] != static_cast<float>(originV_[c])) flat = false;
        }
        open_ = false;
        balancedPoint_.valid = false;
        if (!originStored_ && flat) {
            // Still V = 1 throughout: slide the virtual origin forward.
            originZ_ = lastZ_;
            originCount_ += segmentCount_;
            segmentCount_ = 0;
        } else {
            if (!originStored_) storeOrigin();
            out_.append(lastZ_, end, 0);
            out_.addToLastCount(segmentCount_);
            segmentCount_ = 0;
            originZ_ = lastZ_;
            for (int c = 0; c < C; ++c) originV_[c] = end[c];
            originStored_ = true;
            originIsStep_ = false;
        }
        if (backtrack) toReplay_.pushFront<C>(pending_);
        pending_.clear();
        return backtrack;
    }

    bool backtracks() const { return balancedPoint_.valid && !pending_.empty(); }

    // Takes the vertices handed back by closeSegment() again, in order, in a
    // loop rather than by recursion: a replay that closes a segment early
    // hands back vertices of its own, which go first. While a segment is
    // open, the next vertices of one band are taken as a run (extendRun(),
    // the result of extendOne() on each in turn), and the vertex that stops
    // the run goes through pushBeyondOne(), as push() would take them.
    template <int C>
    void replay() {
        while (!toReplay_.empty()) {
            if (open_) {
                const std::size_t runLength = toReplay_.sameBand(kReplayRun);
                const std::size_t taken = extendRun<C>(toReplay_.depths(), toReplay_.values<C>(), toReplay_.counts(),
                                                       runLength, toReplay_.bands()[0]);
                toReplay_.dropFront(taken);
                if (taken == runLength) continue;
            }
            const float z = toReplay_.depths()[0];
            double v[kMaxChannels];
            std::copy(toReplay_.values<C>(), toReplay_.values<C>() + C, v);
            const std::uint32_t count = toReplay_.counts()[0];
            const double band = toReplay_.bands()[0];
            toReplay_.dropFront(1);
            if (open_)
                pushBeyondOne<C>(z, v, count, band);
            else
                pushOne<C>(z, v, count, band);
        }
    }

    int channels_;
    bool centred_;
    bool keepCounts_;
    double band_;
    VisibilityFunction out_;

    bool started_ = false;       // the layer has seen input
    float originZ_ = 0.0f;
    double originV_[kMaxChannels] = {1.0, 1.0, 1.0};
    bool originStored_ = false;  // origin is a stored vertex (else virtual V = 1)
    bool originIsStep_ = false;  // origin is a step vertex that a deeper value at its depth may replace
    std::uint64_t originCount_ = 0;  // counts waiting for the first stored vertex

    bool open_ = false;  // a segment has accepted at least one vertex beyond the origin
    SlopeWindow window_[kMaxChannels] = {};
    float lastZ_ = 0.0f;
    std::uint64_t segmentCount_ = 0;
    double inputV_[kMaxChannels] = {1.0, 1.0, 1.0};  // the input's value at lastZ_
    double twiceIntegral_[kMaxChannels] = {};        // twice the input's integral from originZ_ to lastZ_
    LongestStretch longest_;                         // of the open segment

    // The open segment's last vertex at which it could be closed balanced
    // (noteBalance()), and the vertices it took after that one.
    struct BalancedPoint {
        bool valid = false;
        float z = 0.0f;
        std::uint64_t segmentCount = 0;
        LongestStretch longest;
        SlopeWindow window[kMaxChannels] = {};
        double twiceIntegral[kMaxChannels] = {};
        double inputV[kMaxChannels] = {};
    } balancedPoint_;
    detail::VertexQueue pending_;
    detail::VertexQueue toReplay_;  // vertices to take again, the next one first
};

}  // namespace

struct Compressor::Impl {
    explicit Impl(const CompressorOptions& o)
        : options(o), grey(greyAtStart(o)), greedy(grey ? 1 : o.channels, o.tolerance, o.keepCounts, o.centred) {
        resetsLeft = std::max(o.maxLayers, 1) - 1;
    }

    // RGB input that may be stored monochrome starts as one channel, the
    // channels' mid-range, and widens to RGB when they disagree.
    static bool greyAtStart(const CompressorOptions& o) { return o.channels == kMaxChannels && o.allowMonochrome; }

    void reset() {
        grey = greyAtStart(options);
        greedy.restart(grey ? 1 : options.channels);
        resetsLeft = std::max(options.maxLayers, 1) - 1;
        layerEnding = false;
        layerClosed = false;
        layers = 0;
        inputIndex = 0;
        previousZ = 0.0f;
        haveLayerInput = false;
    }

    // The input checks, one test per check and a single branch for valid
    // input; throwInvalid() names the first violation.
    void validate(float z, const double* v) {
        bool valid = std::isfinite(z) & (z >= 0.0f) & ((inputIndex == 0) | (z >= previousZ));
        for (int c = 0; c < options.channels; ++c)
            valid &= (v[c] >= 0.0) & (v[c] <= 1.0) & (!haveLayerInput | (v[c] <= previousV[c]));
        if (!valid) throwInvalid(z, v);
        ++inputIndex;
        previousZ = z;
        for (int c = 0; c < options.channels; ++c) previousV[c] = v[c];
        haveLayerInput = true;
    }

    [[noreturn]] void throwInvalid(float z, const double* v) const {
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
        throw Error(ErrorCode::internal, detail::concat("compressor: input vertex ", index, " failed a check"));
    }

    template <bool check>
    bool push(float z, const double* values, std::uint32_t count) {
        if (layerEnding && z > layerEndZ) {
            // All light is blocked at layerEndZ: end the layer and refuse this
            // vertex, so the producer restarts behind that depth.
            endLayer(true);
            layerEnding = false;
            layerClosed = true;
            return false;
        }
        if (layerClosed || layers == 0) {
            layerClosed = false;
            startLayer();
        }
        if (check) validate(z, values);

        if (options.channels == 1)
            greedy.push<1>(z, values, count, greedy.window());
        else if (grey)
            pushGrey(z, values, count);
        else
            greedy.push<3>(z, values, count, greedy.window());

        if (resetsLeft > 0 && !layerEnding) {
            bool blocked = true;
            for (int c = 0; c < options.channels; ++c)
                if (values[c] > options.tolerance) blocked = false;
            if (blocked) {
                layerEnding = true;
                layerEndZ = z;
                --resetsLeft;
            }
        }
        return true;
    }

    // push<false>() over a run of vertices; vertices that extend the open
    // segment take the short path. Returns how many were taken.
    template <typename T>
    std::size_t pushRun(const float* z, const T* v, const std::uint32_t* counts, std::size_t n) {
        const std::size_t nc = static_cast<std::size_t>(options.channels);
        std::size_t i = 0;
        GreyTargets targets;
        while (i < n) {
            // Layer ends are decided vertex by vertex.
            const bool plain = kTrustValidInput && resetsLeft == 0 && !layerEnding && !layerClosed && layers > 0;
            if (plain && !grey) {
                i += options.channels == 1
                         ? greedy.extendRun<1>(z + i, v + i, counts ? counts + i : nullptr, n - i, greedy.window())
                         : greedy.extendRun<3>(z + i, v + i * nc, counts ? counts + i : nullptr, n - i,
                                                   greedy.window());
                if (i == n) break;
            } else if (plain && greyRuns()) {
                i = pushGreyRun(z, v, counts, n, i, targets);
                if (i == n) break;
            }
            double values[kMaxChannels];
            for (std::size_t c = 0; c < nc; ++c) values[c] = static_cast<double>(v[i * nc + c]);
            const std::uint32_t count = counts ? counts[i] : 0u;
            if (plain && !grey && greedy.segmentOpen()) {
                // The vertex ends the open segment (push() would try it again first).
                if (options.channels == 1)
                    greedy.pushBeyond<1>(z[i], values, count, greedy.window());
                else
                    greedy.pushBeyond<3>(z[i], values, count, greedy.window());
            } else if (!push<!kTrustValidInput>(z[i], values, count)) {
                break;
            }
            ++i;
        }
        return i;
    }

    // Whether grey input goes through pushGreyRun(): with a band > 0 for
    // every grey vertex (a tolerance above 2^-24; see greyTarget()).
    bool greyRuns() const { return grey && greedy.window() > 0.0; }

    // What decides grey targets: the tolerance, whether it leaves no room
    // for a spread (at most 4 kStoreRounding), and the window.
    struct GreyLimits {
        double tolerance;
        bool noSpread;
        double window;
    };
    GreyLimits greyLimits() const {
        return {options.tolerance, options.tolerance < 4.0 * kStoreRounding, greedy.window()};
    }

    // The channels' mid-range and its band for grey input; false when the
    // channels are too far apart to stand for one (the builder then widens
    // to RGB). The limits come as a copy: stores of targets cannot then
    // make the compiler read them again for each vertex.
    static bool greyTarget(double r, double g, double b, GreyLimits limits, double& mid, double& band) {
        const double lo = std::min(std::min(r, g), b), hi = std::max(std::max(r, g), b);
        const double spread = hi - lo;
        if (spread > limits.tolerance || (spread > 0.0 && limits.noSpread)) return false;
        mid = 0.5 * (lo + hi);
        band = limits.window - 0.5 * spread;
        return true;
    }

    // Run indices [begin, end) whose grey targets greyMids and greyBands hold
    // (from their index 0), within one pushRun().
    struct GreyTargets {
        std::size_t begin = 0, end = 0;
    };

    // The grey vertices of a run from i on that extend the open segment,
    // taken as a run of their mid-ranges, each with its band: what pushGrey()
    // would do vertex by vertex. Returns the index of the first vertex it did
    // not take: one that ends the segment (centred: or the first after the
    // balanced point at which the segment closed) or whose channels disagree
    // (push() takes those). Targets are worked out a chunk ahead and kept in
    // `targets`, so that the next segment's vertices reuse them.
    template <typename T>
    std::size_t pushGreyRun(const float* z, const T* v, const std::uint32_t* counts, std::size_t n, std::size_t i,
                            GreyTargets& targets) {
        constexpr std::size_t kChunk = 256;
        if (greyMids.size() < kChunk) {
            greyMids.resize(kChunk);
            greyBands.resize(kChunk);
        }
        while (i < n) {
            if (i < targets.begin || i >= targets.end) {
                const GreyLimits limits = greyLimits();
                double* mids = greyMids.data();
                double* bands = greyBands.data();
                const std::size_t end = std::min(n, i + kChunk);
                std::size_t k = i;
                for (; k < end; ++k) {
                    const T* c = v + k * kMaxChannels;
                    if (!greyTarget(static_cast<double>(c[0]), static_cast<double>(c[1]), static_cast<double>(c[2]),
                                    limits, mids[k - i], bands[k - i]))
                        break;
                }
                targets = {i, k};
                if (k == i) break;  // the channels disagree at i
            }
            const std::size_t from = i - targets.begin, available = targets.end - i;
            const std::size_t taken = greedy.extendGreyRun(z + i, greyMids.data() + from, greyBands.data() + from,
                                                           counts ? counts + i : nullptr, available);
            i += taken;
            if (taken < available) break;  // the segment ends at i
        }
        return i;
    }

    // The mid-range m of the channels stands for all three while their spread
    // s stays within the tolerance: its target window m +- (window - s / 2)
    // keeps every channel within the full window.
    void pushGrey(float z, const double* values, std::uint32_t count) {
        double mid, band;
        if (!greyTarget(values[0], values[1], values[2], greyLimits(), mid, band)) {
            grey = false;
            greedy.widen();
            greedy.push<3>(z, values, count, greedy.window());
            return;
        }
        greedy.push<1>(z, &mid, count, band);
    }

    void startLayer() {
        greedy.beginLayer();
        ++layers;
        haveLayerInput = false;
    }

    void endLayer(bool recordEnd) { greedy.finishLayer(recordEnd); }

    CompressorOptions options;
    bool grey;  // the greedy builder runs on the channels' mid-range
    Greedy greedy;
    std::vector<double> greyMids, greyBands;  // pushGreyRun()'s targets, kept from run to run
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
    return impl_->push<true>(z, values, count);
}

bool Compressor::pushValid(float z, const double* values, std::uint32_t count) {
    return impl_->push<!kTrustValidInput>(z, values, count);
}

std::size_t Compressor::pushValid(const float* z, const float* values, const std::uint32_t* counts, std::size_t n) {
    return impl_->pushRun(z, values, counts, n);
}

std::size_t Compressor::pushValid(const float* z, const double* values, const std::uint32_t* counts,
                                  std::size_t n) {
    return impl_->pushRun(z, values, counts, n);
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
    VisibilityFunction result;
    finish(result);
    return result;
}

void Compressor::finish(VisibilityFunction& out) {
    Impl& s = *impl_;
    // A layer after the first keeps at least one vertex even when its input
    // stayed at V = 1 within tolerance: an empty last layer is not valid.
    if (!s.layerClosed) s.endLayer(s.layerEnding || s.layers > 1);
    s.greedy.take(out);
    s.reset();
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
