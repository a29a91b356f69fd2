// Large arrays on huge pages (internal). A build touches tens of megabytes
// afresh: the scene's primitives, the tiles' buckets, a tile's crossings. With
// 4 KiB pages each page costs a fault when first written (on a virtual machine
// several microseconds, a tenth of a 256² build) and the primitives, read in
// bucket order, miss the TLB. Linux backs a range with 2 MiB pages when asked
// (madvise(MADV_HUGEPAGE); the default "madvise" mode of transparent huge
// pages gives them to no one else), so arrays of 2 MiB or more are allocated
// aligned to 2 MiB and marked before they are written. Smaller ones, and every
// array elsewhere than Linux, come from operator new as before.
#pragma once

#include <cstddef>
#include <cstdlib>
#include <limits>
#include <new>
#include <type_traits>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace dsm::detail {

inline constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;

inline void* allocateLarge(std::size_t bytes) {
    if (bytes < kHugePageBytes) return ::operator new(bytes);
    // No object is larger than PTRDIFF_MAX bytes, and the rounding must not wrap.
    if (bytes > static_cast<std::size_t>(std::numeric_limits<std::ptrdiff_t>::max()) - kHugePageBytes)
        throw std::bad_alloc();
    const std::size_t rounded = (bytes + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
    void* p = std::aligned_alloc(kHugePageBytes, rounded);
    if (p == nullptr) throw std::bad_alloc();
#if defined(MADV_HUGEPAGE)
    // Advice only: where the kernel has no huge pages to give, the range
    // stays on ordinary pages.
    (void)madvise(p, rounded, MADV_HUGEPAGE);
#endif
    return p;
}

/// `bytes` is the size allocateLarge() was given for `p`.
inline void freeLarge(void* p, std::size_t bytes) noexcept {
    if (bytes < kHugePageBytes) ::operator delete(p);
    else std::free(p);
}

/// A std::allocator for the arrays above. Stateless: any two compare equal.
template <class T>
struct HugePageAllocator {
    static_assert(alignof(T) <= __STDCPP_DEFAULT_NEW_ALIGNMENT__, "over-aligned types need their own allocator");
    using value_type = T;
    HugePageAllocator() noexcept = default;
    template <class U>
    HugePageAllocator(const HugePageAllocator<U>&) noexcept {}
    T* allocate(std::size_t n) {
        if (n > std::numeric_limits<std::size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
        return static_cast<T*>(allocateLarge(n * sizeof(T)));
    }
    void deallocate(T* p, std::size_t n) noexcept { freeLarge(p, n * sizeof(T)); }
    friend bool operator==(const HugePageAllocator&, const HugePageAllocator&) noexcept { return true; }
};

/// A vector whose storage, once it reaches 2 MiB, lies on huge pages.
template <class T>
using LargeVector = std::vector<T, HugePageAllocator<T>>;

/// HugePageAllocator whose elements made without a value are default-
/// initialised: resize() leaves those of trivial types unwritten. Elements
/// made from values are constructed as std::allocator_traits does by default.
template <class T>
struct HugePageAllocatorForOverwrite : HugePageAllocator<T> {
    HugePageAllocatorForOverwrite() noexcept = default;
    template <class U>
    HugePageAllocatorForOverwrite(const HugePageAllocatorForOverwrite<U>&) noexcept {}
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;
    }
};

/// A LargeVector for arrays whose every element is written before it is
/// read, as make_unique_for_overwrite: resizing writes nothing, so that
/// threads filling parts of the array in parallel are the first to write
/// their pages (on a virtual machine, a first write of a page is its costly
/// part), not one thread zeroing it all beforehand.
template <class T>
using LargeVectorForOverwrite = std::vector<T, HugePageAllocatorForOverwrite<T>>;

}  // namespace dsm::detail
