// SplitMix64 (internal): the library's one small deterministic generator and
// 64-bit mixing function. Its output is the same on every platform, so sample
// positions, jitter and generated scene content depend only on their seeds.
#pragma once

#include <cstdint>

namespace dsm::detail {

/// SplitMix64's finaliser: a bijective mix of 64 bits (also a good hash).
constexpr std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

class SplitMix64 {
public:
    explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
    std::uint64_t next() { return mix64(state_ += 0x9E3779B97F4A7C15ull); }
    /// Uniform in [0, 1): the top 53 bits as a binary fraction.
    double uniform() { return static_cast<double>(next() >> 11) * 0x1p-53; }

private:
    std::uint64_t state_;
};

}  // namespace dsm::detail
