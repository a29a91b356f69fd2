// The build's large arrays (detail::LargeVector): those of 2 MiB or more lie
// aligned to 2 MiB in a range marked for huge pages; arrays that grow and
// shrink across that size keep their contents and free what they allocated
// the way they allocated it (AddressSanitizer checks the pairing in
// scripts/test).
#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>

#include "huge_pages.h"

namespace {

using dsm::detail::kHugePageBytes;
using dsm::detail::LargeVector;

// The VmFlags of the mapping holding `address`, from /proc/self/smaps; empty
// when there is no such file or mapping.
std::string vmFlagsAt(const void* address) {
    std::ifstream smaps("/proc/self/smaps");
    const auto at = reinterpret_cast<std::uintptr_t>(address);
    std::string line;
    bool inside = false;
    while (std::getline(smaps, line)) {
        std::uintptr_t begin = 0, end = 0;
        char dash = 0;
        std::istringstream head(line);
        if (head >> std::hex >> begin >> dash >> end && dash == '-') {
            inside = begin <= at && at < end;
            continue;
        }
        if (inside && line.rfind("VmFlags:", 0) == 0) return line;
    }
    return {};
}

TEST(HugePages, LargeArraysLieAlignedInARangeMarkedForHugePages) {
    LargeVector<std::uint64_t> large(3 * kHugePageBytes / 2 / sizeof(std::uint64_t), 7);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(large.data()) % kHugePageBytes, 0u);
    EXPECT_EQ(large.front(), 7u);
    EXPECT_EQ(large.back(), 7u);
#if defined(__linux__)
    if (!std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled"))
        GTEST_SKIP() << "this kernel has no transparent huge pages";
    const std::string flags = vmFlagsAt(large.data());
    ASSERT_FALSE(flags.empty()) << "no mapping holds the array in /proc/self/smaps";
    EXPECT_NE(flags.find(" hg"), std::string::npos) << flags;
#endif
}

TEST(HugePages, ArraysGrowingAndShrinkingAcrossTheSizeKeepTheirContents) {
    LargeVector<std::uint32_t> v;
    const std::size_t n = 2 * kHugePageBytes / sizeof(std::uint32_t) + 5;
    for (std::size_t i = 0; i < n; ++i) v.push_back(static_cast<std::uint32_t>(i * 2654435761u));
    for (std::size_t i = 0; i < n; i += 4099) ASSERT_EQ(v[i], static_cast<std::uint32_t>(i * 2654435761u)) << i;
    v.resize(100);
    v.shrink_to_fit();
    ASSERT_EQ(v.size(), 100u);
    for (std::size_t i = 0; i < v.size(); ++i) ASSERT_EQ(v[i], static_cast<std::uint32_t>(i * 2654435761u)) << i;
    LargeVector<std::uint32_t> copy = v;
    copy.resize(n);
    EXPECT_EQ(copy[99], v[99]);
    EXPECT_EQ(copy[n - 1], 0u);
}

}  // namespace
