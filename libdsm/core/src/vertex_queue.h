// Input vertices a centred segment took past its balanced point, kept to be
// taken again (internal; compressor.cpp). They are held in order, as arrays
// of depths, values (C a vertex), counts and bands, so that the compressor
// can take a stretch of them as a run of vertices, as it takes its input;
// vertices go in at the back or, ahead of the rest, at the front. All the
// vertices a queue holds at once have the same number of values, C (1 or 3).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "dsm/visibility.h"

namespace dsm::detail {

class VertexQueue {
public:
    bool empty() const { return head_ == end_; }
    std::size_t size() const { return end_ - head_; }
    // How many vertices it has room for, at both ends and between.
    std::size_t capacity() const { return z_.size(); }
    // Empty, with its room kept on both sides.
    void clear() { head_ = end_ = z_.size() / 2; }

    // The vertices in order, from the next one: depth, values (C each),
    // count and band.
    const float* depths() const { return z_.data() + head_; }
    template <int C>
    const double* values() const {
        return v_.data() + head_ * static_cast<std::size_t>(C);
    }
    const std::uint32_t* counts() const { return counts_.data() + head_; }
    const double* bands() const { return bands_.data() + head_; }

    // How many vertices from the next one share its band, up to `most`.
    std::size_t sameBand(std::size_t most) const {
        const std::size_t last = head_ + std::min(most, size());
        std::size_t i = head_;
        while (i < last && bands_[i] == bands_[head_]) ++i;
        return i - head_;
    }

    void dropFront(std::size_t n) { head_ += n; }

    // Puts n vertices (values C each; counts null for counts of 0) after the
    // others, each of band bands[i], or all of `band` when bands is null.
    template <int C, typename T>
    void pushBack(const float* z, const T* v, const std::uint32_t* counts, std::size_t n, double band,
                  const double* bands = nullptr) {
        while (z_.size() - end_ < n) grow(C, 0);
        for (std::size_t i = 0; i < n; ++i)
            put<C>(end_ + i, z[i], v + i * static_cast<std::size_t>(C), counts ? counts[i] : 0u,
                   bands ? bands[i] : band);
        end_ += n;
    }

    // Puts one vertex ahead of the others.
    template <int C>
    void pushFront(float z, const double* v, std::uint32_t count, double band) {
        if (head_ == 0) grow(C, 1);
        put<C>(--head_, z, v, count, band);
    }

    // Puts the vertices of `other`, in their order, ahead of these.
    template <int C>
    void pushFront(const VertexQueue& other) {
        const std::size_t n = other.size();
        if (head_ < n) grow(C, n);
        head_ -= n;
        constexpr std::size_t nc = C;
        std::copy(other.depths(), other.depths() + n, z_.begin() + static_cast<std::ptrdiff_t>(head_));
        std::copy(other.values<C>(), other.values<C>() + n * nc, v_.begin() + static_cast<std::ptrdiff_t>(head_ * nc));
        std::copy(other.counts(), other.counts() + n, counts_.begin() + static_cast<std::ptrdiff_t>(head_));
        std::copy(other.bands(), other.bands() + n, bands_.begin() + static_cast<std::ptrdiff_t>(head_));
    }

private:
    template <int C, typename T>
    void put(std::size_t i, float z, const T* v, std::uint32_t count, double band) {
        z_[i] = z;
        for (std::size_t c = 0; c < static_cast<std::size_t>(C); ++c)
            v_[i * static_cast<std::size_t>(C) + c] = static_cast<double>(v[c]);
        counts_[i] = count;
        bands_[i] = band;
    }

    // Makes room for at least one more vertex at the back and `front` at
    // the front, keeping the vertices in order (values C a vertex; room for
    // kMaxChannels a vertex, whatever C). The room to spare is split between
    // the two ends: a queue that grows at one end keeps growing there, and
    // room at the other alone would leave it to grow again at once.
    void grow(int C, std::size_t front) {
        const std::size_t n = size(), nc = static_cast<std::size_t>(C);
        const std::size_t needed = front + n + 1;
        const std::size_t capacity = std::max(2 * z_.size(), 2 * needed + 32);
        const std::size_t newHead = front + (capacity - needed) / 2;
        std::vector<float> z(capacity);
        std::vector<double> v(capacity * static_cast<std::size_t>(kMaxChannels));
        std::vector<std::uint32_t> counts(capacity);
        std::vector<double> bands(capacity);
        // The vertices' elements of `from` (stride a vertex) into `to` from newHead on.
        const auto moveInto = [&](const auto& from, auto& to, std::size_t stride) {
            std::copy(from.begin() + static_cast<std::ptrdiff_t>(head_ * stride),
                      from.begin() + static_cast<std::ptrdiff_t>(end_ * stride),
                      to.begin() + static_cast<std::ptrdiff_t>(newHead * stride));
        };
        moveInto(z_, z, 1);
        moveInto(v_, v, nc);
        moveInto(counts_, counts, 1);
        moveInto(bands_, bands, 1);
        z_.swap(z);
        v_.swap(v);
        counts_.swap(counts);
        bands_.swap(bands);
        head_ = newHead;
        end_ = newHead + n;
    }

    std::vector<float> z_;
    std::vector<double> v_;
    std::vector<std::uint32_t> counts_;
    std::vector<double> bands_;
    std::size_t head_ = 0, end_ = 0;  // the vertices are [head_, end_)
};

}  // namespace dsm::detail
