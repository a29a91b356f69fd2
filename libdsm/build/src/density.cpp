// Density fields of volumes: homogeneous, a procedural noise cloud, and
// OpenVDB float grids (spec/scene.md, "volume").
#include "density.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>

#include "dsm/error.h"
#include "splitmix64.h"
#include "text.h"
#if DSM_WITH_OPENVDB
#include "vdb_module_loader.h"
#endif

DSM_NAMESPACE_BEGIN
namespace {

/// A field that is 0 outside its closed box.
class BoxedField : public DensityField {
public:
    explicit BoxedField(const Volume& v) : min_(v.boundsMin), max_(v.boundsMax) {}

protected:
    bool inside(const Vec3& p) const {
        return p[0] >= min_[0] && p[0] <= max_[0] && p[1] >= min_[1] && p[1] <= max_[1] && p[2] >= min_[2] &&
               p[2] <= max_[2];
    }
    Vec3 min_, max_;
};

class HomogeneousField final : public BoxedField {
public:
    HomogeneousField(const Volume& v, const HomogeneousDensity& d) : BoxedField(v), density_(d.density) {}
    double density(const Vec3& p) const override { return inside(p) ? density_ : 0.0; }

private:
    double density_;
};

// ---------------------------------------------------------------------------
// Noise cloud: Perlin's improved gradient noise over a permutation table
// shuffled from the seed with SplitMix64 (the same on every platform), summed
// in octaves (fBm), shaped by a smooth falloff inside the box's inscribed
// ellipsoid.

using detail::mix64;
using detail::SplitMix64;

double fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }
double lerp(double t, double a, double b) { return a + t * (b - a); }
double smoothstep(double e0, double e1, double x) {
    const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// Perlin's 12 edge gradients (4 repeated), dotted with (x, y, z).
double grad(unsigned hash, double x, double y, double z) {
    switch (hash & 15u) {
        case 0: return x + y;
        case 1: return -x + y;
        case 2: return x - y;
        case 3: return -x - y;
        case 4: return x + z;
        case 5: return -x + z;
        case 6: return x - z;
        case 7: return -x - z;
        case 8: return y + z;
        case 9: return -y + z;
        case 10: return y - z;
        case 11: return -y - z;
        case 12: return x + y;
        case 13: return -x + y;
        case 14: return -y + z;
        default: return -y - z;
    }
}

class NoiseCloudField final : public BoxedField {
public:
    NoiseCloudField(const Volume& v, const NoiseCloudDensity& d)
        : BoxedField(v),
          peak_(d.density),
          frequency_(d.frequency),
          octaves_(std::clamp(d.octaves, 1, kMaxOctaves)),
          falloff_(std::clamp(d.falloff, 0.0, 1.0)) {
        SplitMix64 rng(mix64(0x636C6F7564ull ^ (static_cast<std::uint64_t>(d.seed) << 20)));
        for (unsigned i = 0; i < 256; ++i) perm_[i] = static_cast<std::uint8_t>(i);
        for (unsigned i = 255; i > 0; --i) std::swap(perm_[i], perm_[rng.next() % (i + 1)]);
        for (unsigned i = 0; i < 256; ++i) perm_[256 + i] = perm_[i];
        for (auto& o : offsets_)
            for (double& c : o) c = 256.0 * rng.uniform();
        for (int i = 0; i < 3; ++i) {
            centre_[static_cast<std::size_t>(i)] =
                0.5 * (min_[static_cast<std::size_t>(i)] + max_[static_cast<std::size_t>(i)]);
            halfSize_[static_cast<std::size_t>(i)] =
                0.5 * (max_[static_cast<std::size_t>(i)] - min_[static_cast<std::size_t>(i)]);
        }
    }

    double density(const Vec3& p) const override {
        if (!inside(p)) return 0.0;
        double r2 = 0.0;
        for (std::size_t i = 0; i < 3; ++i) {
            const double q = (p[i] - centre_[i]) / halfSize_[i];
            r2 += q * q;
        }
        if (!(r2 < 1.0)) return 0.0;
        const double shape = falloff_ > 0.0 ? 1.0 - smoothstep(1.0 - falloff_, 1.0, std::sqrt(r2)) : 1.0;
        if (shape <= 0.0) return 0.0;
        double sum = 0.0, amplitude = 1.0, norm = 0.0, f = frequency_;
        for (int o = 0; o < octaves_; ++o) {
            const auto& off = offsets_[static_cast<std::size_t>(o)];
            sum += amplitude * noise(p[0] * f + off[0], p[1] * f + off[1], p[2] * f + off[2]);
            norm += amplitude;
            amplitude *= 0.5;
            f *= 2.0;
        }
        const double coverage = std::clamp(0.5 + kGain * sum / norm, 0.0, 1.0);
        return peak_ * shape * coverage;
    }

    static constexpr int kMaxOctaves = 16;
    static constexpr double kGain = 2.0;

private:
    double noise(double x, double y, double z) const {
        const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
        // Wrap the lattice to the 256-periodic table; the casts stay in range
        // because the coordinates are finite and reduced modulo 256 first.
        const unsigned X = static_cast<unsigned>(static_cast<std::int64_t>(std::fmod(fx, 256.0) + 256.0)) & 255u;
        const unsigned Y = static_cast<unsigned>(static_cast<std::int64_t>(std::fmod(fy, 256.0) + 256.0)) & 255u;
        const unsigned Z = static_cast<unsigned>(static_cast<std::int64_t>(std::fmod(fz, 256.0) + 256.0)) & 255u;
        x -= fx;
        y -= fy;
        z -= fz;
        const double u = fade(x), v = fade(y), w = fade(z);
        const unsigned A = perm_[X] + Y, AA = perm_[A] + Z, AB = perm_[A + 1] + Z;
        const unsigned B = perm_[X + 1] + Y, BA = perm_[B] + Z, BB = perm_[B + 1] + Z;
        return lerp(w,
                    lerp(v, lerp(u, grad(perm_[AA], x, y, z), grad(perm_[BA], x - 1, y, z)),
                         lerp(u, grad(perm_[AB], x, y - 1, z), grad(perm_[BB], x - 1, y - 1, z))),
                    lerp(v, lerp(u, grad(perm_[AA + 1], x, y, z - 1), grad(perm_[BA + 1], x - 1, y, z - 1)),
                         lerp(u, grad(perm_[AB + 1], x, y - 1, z - 1), grad(perm_[BB + 1], x - 1, y - 1, z - 1))));
    }

    double peak_, frequency_;
    int octaves_;
    double falloff_;
    Vec3 centre_{}, halfSize_{};
    std::array<std::uint8_t, 512> perm_{};
    std::array<std::array<double, 3>, kMaxOctaves> offsets_{};
};

// ---------------------------------------------------------------------------
// OpenVDB grids, through the module that links OpenVDB (vdb_module.h), when
// built with it (DSM_WITH_OPENVDB).
#if DSM_WITH_OPENVDB

std::string vdbWhere(const VdbDensity& vdb) { return "VDB file '" + detail::clip(vdb.file, detail::kMaxQuotedPath) + "'"; }

// A grid read by the module, with the module that released it.
struct VdbGrid {
    const DsmVdbModule* module;
    std::unique_ptr<DsmVdbGrid, void (*)(DsmVdbGrid*)> grid;
};

VdbGrid loadFloatGrid(const VdbDensity& vdb) {
    const std::string where = vdbWhere(vdb);
    std::error_code ec;
    if (!std::filesystem::is_regular_file(vdb.file, ec))
        throw Error(ErrorCode::io, where + ": does not exist or is not a file", vdb.file);
    const DsmVdbModule& module = vdbModule(where, vdb.file);
    int code = 0;
    char message[1024];
    DsmVdbGrid* grid = module.readGrid(vdb.file.c_str(), vdb.grid.c_str(), &code, message, sizeof message);
    if (!grid) throw Error(static_cast<ErrorCode>(code), where + ": " + message, vdb.file);
    return {&module, {grid, module.release}};
}

class VdbField final : public BoxedField {
public:
    VdbField(const Volume& v, VdbGrid grid) : BoxedField(v), grid_(std::move(grid)) {}

    double density(const Vec3& p) const override {
        if (!inside(p)) return 0.0;
        const float value = grid_.module->sample(grid_.grid.get(), p.data());
        return std::isfinite(value) && value > 0.0f ? static_cast<double>(value) : 0.0;
    }

private:
    VdbGrid grid_;
};
#else
[[noreturn]] void noOpenVdb(const VdbDensity& vdb) {
    throw Error(ErrorCode::unsupported, "VDB file '" + vdb.file + "': this libdsm was built without OpenVDB",
                vdb.file);
}
#endif

}  // namespace

std::unique_ptr<DensityField> makeDensityField(const Volume& volume) {
    for (std::size_t i = 0; i < 3; ++i)
        if (!(volume.boundsMin[i] < volume.boundsMax[i]) || !std::isfinite(volume.boundsMin[i]) ||
            !std::isfinite(volume.boundsMax[i]))
            throw Error(ErrorCode::scene, detail::concat("volume: bounds [", volume.boundsMin[i], ", ",
                                                         volume.boundsMax[i], "] on axis ", i,
                                                         " are empty or not finite"));
    if (const auto* h = std::get_if<HomogeneousDensity>(&volume.density))
        return std::make_unique<HomogeneousField>(volume, *h);
    if (const auto* n = std::get_if<NoiseCloudDensity>(&volume.density))
        return std::make_unique<NoiseCloudField>(volume, *n);
    const auto& vdb = std::get<VdbDensity>(volume.density);
#if DSM_WITH_OPENVDB
    return std::make_unique<VdbField>(volume, loadFloatGrid(vdb));
#else
    noOpenVdb(vdb);
#endif
}

void vdbBounds(const VdbDensity& vdb, Vec3& boundsMin, Vec3& boundsMax) {
#if !DSM_WITH_OPENVDB
    (void)boundsMin;
    (void)boundsMax;
    noOpenVdb(vdb);
#else
    const VdbGrid grid = loadFloatGrid(vdb);
    const int found = grid.module->activeBounds(grid.grid.get(), boundsMin.data(), boundsMax.data());
    if (found < 0)
        throw Error(ErrorCode::limit, vdbWhere(vdb) + ": out of memory finding the grid's active voxels", vdb.file);
    if (found == 0)
        throw Error(ErrorCode::scene, vdbWhere(vdb) + ": grid '" + detail::clip(vdb.grid) + "' has no active voxels",
                    vdb.file);
#endif
}

DSM_NAMESPACE_END
