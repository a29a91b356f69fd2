// A contiguous read or write view for the public API: std::span's subset that
// libdsm's interfaces use, so that the headers compile as C++17 as well. In a
// C++20 program it converts to and from std::span (it is a contiguous,
// borrowed range, which std::span's range constructor takes).
#pragma once

#include <cstddef>
#include <iterator>
#include <type_traits>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// `size()` elements of type T at `data()`, owned elsewhere: valid while the
/// viewed storage is. Made from a pointer and a size, a C array, or any
/// contiguous container with data() and size() (std::vector, std::array,
/// std::span, another Span). Cheap to copy; not bounds-checked, like std::span.
/// Thread safety: that of the viewed elements (a Span of const elements may be
/// read from any number of threads while nobody writes them).
template <class T>
class Span {
    template <class Container>
    using DataOf = std::remove_pointer_t<decltype(std::data(std::declval<Container&>()))>;
    template <class Container>
    using IfCompatible = std::enable_if_t<
        !std::is_same_v<std::remove_cv_t<std::remove_reference_t<Container>>, Span> &&
        std::is_convertible_v<DataOf<Container> (*)[], T (*)[]>>;

public:
    using element_type = T;
    using value_type = std::remove_cv_t<T>;
    using size_type = std::size_t;
    using difference_type = std::ptrdiff_t;
    using pointer = T*;
    using reference = T&;
    using iterator = T*;
    using const_iterator = T*;

    constexpr Span() noexcept = default;
    constexpr Span(T* data, std::size_t size) noexcept : data_(data), size_(size) {}
    template <std::size_t N>
    constexpr Span(T (&array)[N]) noexcept : data_(array), size_(N) {}
    template <class Container, class = IfCompatible<Container>>
    constexpr Span(Container&& container) noexcept(noexcept(std::data(container)) && noexcept(std::size(container)))
        : data_(std::data(container)), size_(static_cast<std::size_t>(std::size(container))) {}

    constexpr T* data() const noexcept { return data_; }
    constexpr std::size_t size() const noexcept { return size_; }
    constexpr std::size_t size_bytes() const noexcept { return size_ * sizeof(T); }
    constexpr bool empty() const noexcept { return size_ == 0; }
    constexpr T& operator[](std::size_t i) const noexcept { return data_[i]; }
    constexpr T& front() const noexcept { return data_[0]; }
    constexpr T& back() const noexcept { return data_[size_ - 1]; }
    constexpr T* begin() const noexcept { return data_; }
    constexpr T* end() const noexcept { return data_ + size_; }

    /// The first / last `count` elements, and `count` elements from `offset`
    /// (to the end when count is npos). Arguments must lie within the view.
    static constexpr std::size_t npos = static_cast<std::size_t>(-1);
    constexpr Span first(std::size_t count) const noexcept { return Span(data_, count); }
    constexpr Span last(std::size_t count) const noexcept { return Span(data_ + (size_ - count), count); }
    constexpr Span subspan(std::size_t offset, std::size_t count = npos) const noexcept {
        return Span(data_ + offset, count == npos ? size_ - offset : count);
    }

private:
    T* data_ = nullptr;
    std::size_t size_ = 0;
};

DSM_NAMESPACE_END

#if defined(__cpp_lib_ranges)
#include <ranges>
// A Span never owns what it views: ranges algorithms may return its iterators.
template <class T>
inline constexpr bool std::ranges::enable_borrowed_range<dsm::Span<T>> = true;
#endif
