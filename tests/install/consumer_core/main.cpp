// A renderer's read side on the installed dsm::core: opens a map, looks up
// 1,000 world-space points (written to POINTS_OUT, for dsm-lookup to answer
// the same) and prints V as dsm-lookup does (CSV, %.9g).
#include <dsm/dsm.h>

#include <array>
#include <cstdint>
#include <cstdio>
#include <memory>

namespace {

// Deterministic points over the example scenes' extent (y up, ground at 0).
class Points {
public:
    std::array<double, 3> next() { return {-1.0 + 2.0 * uniform(), 1.6 * uniform(), -1.0 + 2.0 * uniform()}; }

private:
    double uniform() {
        state_ = state_ * 6364136223846793005ull + 1442695040888963407ull;
        return static_cast<double>(state_ >> 11) * 0x1p-53;
    }
    std::uint64_t state_ = 1;
};

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: dsm_consumer_core MAP POINTS_OUT\n");
        return 2;
    }
    try {
        const std::shared_ptr<const dsm::DeepShadowMap> map = dsm::DeepShadowMap::open(argv[1]);
        dsm::LookupContext lookup(map);
        std::FILE* out = std::fopen(argv[2], "w");
        if (!out) {
            std::fprintf(stderr, "dsm_consumer_core: cannot write '%s'\n", argv[2]);
            return 1;
        }
        Points points;
        for (int i = 0; i < 1000; ++i) {
            const std::array<double, 3> p = points.next();
            std::fprintf(out, "%.17g %.17g %.17g\n", p[0], p[1], p[2]);
            const dsm::LookupResult r = lookup.world(p);
            if (r.channels == 1)
                std::printf("%.9g\n", r.v[0]);
            else
                std::printf("%.9g,%.9g,%.9g\n", r.v[0], r.v[1], r.v[2]);
        }
        return std::fclose(out) == 0 ? 0 : 1;
    } catch (const dsm::Error& e) {
        std::fprintf(stderr, "dsm_consumer_core: %s\n", e.what());
        return 1;
    }
}
