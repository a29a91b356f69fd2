// Links against an installed libdsm and compresses one function.
#include <dsm/dsm.h>

#include <cstdio>

int main() {
    dsm::VisibilityFunction f;
    for (int i = 0; i <= 100; ++i) f.append(static_cast<float>(i), 1.0f - static_cast<float>(i) / 100.0f);
    const dsm::VisibilityFunction g = dsm::compress(f, 0.01);
    std::printf("compressed %zu vertices to %zu\n", f.size(), g.size());
    return g.size() == 2 ? 0 : 1;
}
