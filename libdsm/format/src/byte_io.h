// Little-endian encoding of the file format's basic types, in one place
// (internal). Independent of the host's byte order.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "varint_groups.h"

namespace dsm::detail {

/// Appends little-endian values to a byte vector.
class ByteWriter {
public:
    explicit ByteWriter(std::vector<std::uint8_t>& out) : out_(out) {}
    void u8(std::uint8_t v) { out_.push_back(v); }
    void u16(std::uint16_t v) { put(v, 2); }
    void u32(std::uint32_t v) { put(v, 4); }
    void u64(std::uint64_t v) { put(v, 8); }
    void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
    void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }
    void zeros(std::size_t n) { out_.insert(out_.end(), n, 0); }
    /// Unsigned LEB128: 7 bits a byte, low bits first, high bit set on every
    /// byte but the last (1 to 5 bytes for a u32).
    void varint(std::uint32_t v) {
        while (v >= 0x80) {
            out_.push_back(static_cast<std::uint8_t>(v | 0x80));
            v >>= 7;
        }
        out_.push_back(static_cast<std::uint8_t>(v));
    }
    std::size_t size() const { return out_.size(); }

private:
    void put(std::uint64_t v, int bytes) {
        for (int i = 0; i < bytes; ++i) out_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
    }
    std::vector<std::uint8_t>& out_;
};

/// Reads little-endian values from a byte range. Reading past the end sets
/// a flag and yields zeros instead of touching memory out of range; callers
/// check ok() (or use need()) before trusting what they read.
class ByteReader {
public:
    ByteReader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
    std::uint8_t u8() { return static_cast<std::uint8_t>(get(1)); }
    std::uint16_t u16() { return static_cast<std::uint16_t>(get(2)); }
    std::uint32_t u32() { return static_cast<std::uint32_t>(get(4)); }
    std::uint64_t u64() { return get(8); }
    float f32() { return std::bit_cast<float>(u32()); }
    double f64() { return std::bit_cast<double>(u64()); }
    void skip(std::size_t n) {
        if (n > size_ - pos_) {
            overrun_ = true;
            pos_ = size_;
        } else {
            pos_ += n;
        }
    }
    bool need(std::size_t n) const { return n <= size_ - pos_; }
    bool ok() const { return !overrun_; }
    std::size_t position() const { return pos_; }
    std::size_t remaining() const { return size_ - pos_; }
    void seek(std::size_t pos) { pos_ = pos <= size_ ? pos : size_; }

private:
    std::uint64_t get(int bytes) {
        if (static_cast<std::size_t>(bytes) > size_ - pos_) {
            overrun_ = true;
            pos_ = size_;
            return 0;
        }
        std::uint64_t v = 0;
        for (int i = 0; i < bytes; ++i) v |= static_cast<std::uint64_t>(data_[pos_ + static_cast<std::size_t>(i)]) << (8 * i);
        pos_ += static_cast<std::size_t>(bytes);
        return v;
    }
    const std::uint8_t* data_;
    std::size_t size_;
    std::size_t pos_ = 0;
    bool overrun_ = false;
};

/// Reads unsigned LEB128 values (ByteWriter::varint) from a byte range. A
/// value running past the end or beyond 32 bits sets a flag and yields 0;
/// callers check ok().
class VarintReader {
public:
    VarintReader(const std::uint8_t* begin, const std::uint8_t* end) : at_(begin), end_(end) {}
    std::uint32_t next() {
        if (end_ - at_ >= 5) return nextUnchecked();
        return nextChecked();
    }
    /// Calls `f(i, value)` for each of the next `count` (< 2^60) values, i
    /// from 0: the bounds checked once for the run when it cannot reach the
    /// end (5 bytes a value at most), else value by value. The hot path of
    /// tile decoding.
    template <class F>
    void forEach(std::size_t count, F&& f) {
        if (5 * count <= remaining()) {
#pragma GCC unroll 4
            for (std::size_t i = 0; i < count; ++i) f(i, nextUnchecked());
        } else {
            for (std::size_t i = 0; i < count; ++i) f(i, next());
        }
    }
    /// Reads the next `count` values into out[0..count): the same values,
    /// flag and position as `count` calls of next(). For long runs whose
    /// lengths vary in no order a predictor learns (a tile's depths): four
    /// values at a time where the processor allows (readVarintGroups), each
    /// value that stops a group read by next().
    void readInto(std::uint32_t* out, std::size_t count) {
        std::size_t i = 0;
        if (varintGroupsSupported()) {
            for (;;) {
                i += readVarintGroups(at_, end_, out + i, count - i);
                if (count - i < 4 || remaining() < kVarintGroupBytes) break;
                out[i++] = next();
            }
        }
        for (; i < count; ++i) out[i] = next();
    }
    /// When the next `count` (<= 8) values are each one byte (below 128) and
    /// 8 bytes remain: moves past them and sets `values` to those bytes, the
    /// first lowest; otherwise false, and nothing moves.
    bool singleBytes(std::size_t count, std::uint64_t& values) {
        if (remaining() < 8) return false;
        std::uint64_t word;
        if constexpr (std::endian::native == std::endian::little) {
            std::memcpy(&word, at_, 8);
        } else {
            word = 0;
            for (int i = 0; i < 8; ++i) word |= static_cast<std::uint64_t>(at_[i]) << (8 * i);
        }
        const std::uint64_t mask = count >= 8 ? ~std::uint64_t(0) : (std::uint64_t(1) << (8 * count)) - 1;
        if (word & mask & 0x8080808080808080u) return false;
        values = word & mask;
        at_ += count;
        return true;
    }
    std::uint8_t byte() {
        if (at_ == end_) {
            bad_ = true;
            return 0;
        }
        return *at_++;
    }
    /// The next `count` bytes, or null (and the flag set) when fewer remain.
    const std::uint8_t* bytes(std::size_t count) {
        if (count > remaining()) {
            bad_ = true;
            at_ = end_;
            return nullptr;
        }
        const std::uint8_t* begin = at_;
        at_ += count;
        return begin;
    }
    bool ok() const { return !bad_; }
    bool atEnd() const { return at_ == end_; }
    std::size_t remaining() const { return static_cast<std::size_t>(end_ - at_); }

private:
    // At least 5 bytes left: no bounds check per byte. Unrolled, each byte
    // added with its continuation bit, which the next byte's step takes away
    // again (exact: the value fits in 32 bits). A value beyond 32 bits sets
    // the flag and moves on by 5 bytes, so that a run checked for 5 bytes a
    // value stays in range.
    std::uint32_t nextUnchecked() {
        const std::uint8_t* const p = at_;
        std::uint32_t v = p[0];
        if (v < 0x80) {
            at_ = p + 1;
            return v;
        }
        std::uint32_t b = p[1];
        v += (b << 7) - 0x80u;
        if (b < 0x80) {
            at_ = p + 2;
            return v;
        }
        b = p[2];
        v += (b << 14) - (0x80u << 7);
        if (b < 0x80) {
            at_ = p + 3;
            return v;
        }
        b = p[3];
        v += (b << 21) - (0x80u << 14);
        if (b < 0x80) {
            at_ = p + 4;
            return v;
        }
        b = p[4];
        at_ = p + 5;
        if (b > 0x0F) {  // more than 32 bits
            bad_ = true;
            return 0;
        }
        return v + (b << 28) - (0x80u << 21);
    }
    std::uint32_t nextChecked() {
        std::uint32_t v = 0;
        for (int shift = 0; shift < 35; shift += 7) {
            if (at_ == end_) break;
            const std::uint8_t b = *at_++;
            if (shift == 28 && b > 0x0F) break;  // more than 32 bits
            v |= static_cast<std::uint32_t>(b & 0x7F) << shift;
            if (b < 0x80) return v;
        }
        bad_ = true;
        at_ = end_;
        return 0;
    }

    const std::uint8_t* at_;
    const std::uint8_t* end_;
    bool bad_ = false;
};

}  // namespace dsm::detail
