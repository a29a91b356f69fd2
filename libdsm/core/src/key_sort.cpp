#include "key_sort.h"

namespace dsm::detail {

#ifdef DSM_KEY_SORT_AVX512
void sortKeysAvx512(std::uint64_t* keys, std::size_t n);  // key_sort_avx512.cpp
#endif

VectorKeySort avx512KeySort() {
#ifdef DSM_KEY_SORT_AVX512
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f")) return &sortKeysAvx512;
#endif
    return nullptr;
}

}  // namespace dsm::detail
