// SHA-256 (FIPS 180-4), for the content hashes that farm parts record.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "tested_internal.h"

namespace dsm::detail {

class DSM_TESTED_INTERNAL Sha256 {
public:
    Sha256();
    void update(const void* data, std::size_t size);
    void update(std::string_view text) { update(text.data(), text.size()); }
    /// The digest as 64 lowercase hex digits; the object is spent afterwards.
    std::string hex();

private:
    void block(const std::uint8_t* p);
    std::array<std::uint32_t, 8> state_;
    std::array<std::uint8_t, 64> buffer_{};
    std::size_t buffered_ = 0;
    std::uint64_t length_ = 0;
};

/// SHA-256 of a file's bytes, hex; throws dsm::Error (io) naming the file.
std::string sha256OfFile(const std::string& path);

}  // namespace dsm::detail
