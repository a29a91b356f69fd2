// The build's large arrays (detail::LargeVector): those of 2 MiB or more lie
// aligned to 2 MiB in a range marked for huge pages; arrays that grow and
// shrink across that size keep their contents and free what they allocated
// the way they allocated it (AddressSanitizer checks the pairing in
// scripts/test). Arrays for overwrite (detail::LargeVectorForOverwrite) leave
// their pages unwritten until their elements are.
#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

#include "huge_pages.h"

namespace {

using dsm::detail::kHugePageBytes;
using dsm::detail::LargeVector;
using dsm::detail::LargeVectorForOverwrite;

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

#if defined(__linux__)
// How many of the pages under [data, data + bytes) are resident.
std::size_t residentPages(const void* data, std::size_t bytes, std::size_t& pages) {
    const auto page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
    const auto begin = reinterpret_cast<std::uintptr_t>(data) & ~(page - 1);
    const auto end = (reinterpret_cast<std::uintptr_t>(data) + bytes + page - 1) & ~(page - 1);
    pages = (end - begin) / page;
    std::vector<unsigned char> resident(pages);
    if (mincore(reinterpret_cast<void*>(begin), end - begin, resident.data()) != 0) return pages;
    std::size_t n = 0;
    for (unsigned char r : resident) n += r & 1u;
    return n;
}
#endif

TEST(HugePages, ArraysForOverwriteLeaveTheirPagesUnwrittenUntilTheirElementsAre) {
    const std::size_t n = 16 * kHugePageBytes / sizeof(std::uint64_t);  // 32 MiB
    LargeVectorForOverwrite<std::uint64_t> v;
    v.resize(n);
    ASSERT_EQ(v.size(), n);
#if defined(__linux__)
    std::size_t pages = 0;
    // A sanitizer's allocator may fill an allocation's first bytes, and a
    // huge page is resident whole: at most one of the sixteen.
    const std::size_t unwritten = residentPages(v.data(), n * sizeof(std::uint64_t), pages);
    ASSERT_GE(pages, 16u);
    EXPECT_LE(unwritten, pages / 16);
    // The same resize of an ordinary large array writes every element.
    LargeVector<std::uint64_t> zeroed;
    zeroed.resize(n);
    const std::size_t written = residentPages(zeroed.data(), n * sizeof(std::uint64_t), pages);
    EXPECT_EQ(written, pages);
#endif
    for (std::size_t i = 0; i < n; ++i) v[i] = i * 3;
    v.resize(n + 1, 5);  // a value given is written
    v.push_back(9);
    for (std::size_t i = 0; i < n; i += 4099) ASSERT_EQ(v[i], i * 3) << i;
    EXPECT_EQ(v[n], 5u);
    EXPECT_EQ(v[n + 1], 9u);
    // Types with a constructor are still constructed.
    LargeVectorForOverwrite<std::string> named(3);
    EXPECT_TRUE(named[2].empty());
}

}  // namespace
