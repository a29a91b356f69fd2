// Insertion sort of a short run (internal): where std::sort's setup or
// std::stable_sort's buffer would cost more than the sorting.
#pragma once

#include <cstddef>

namespace dsm::detail {

/// Sorts items[0, n) by `less`, stably: an item moves only past those it is
/// strictly less than, so equal items keep their order.
template <class T, class Less>
void insertionSort(T* items, std::size_t n, Less less) {
    for (std::size_t i = 1; i < n; ++i) {
        const T item = items[i];
        std::size_t j = i;
        for (; j > 0 && less(item, items[j - 1]); --j) items[j] = items[j - 1];
        items[j] = item;
    }
}

}  // namespace dsm::detail
