// Affine-matrix helpers (internal), shared by the area lights and the ray casters.
// An Affine holds rows 0..2 of a row-major 4x4 matrix (the bottom row is
// 0 0 0 1), as scene transforms and light cameras store them.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "dsm/error.h"
#include "dsm/vec3.h"
#include "text.h"
#include "vec3_math.h"

namespace dsm::detail {

using Affine = std::array<double, 12>;

inline Affine affineOf(const std::array<double, 16>& m) {
    Affine a{};
    std::copy(m.begin(), m.begin() + 12, a.begin());
    return a;
}

inline Vec3 transformPoint(const Affine& m, const Vec3& p) {
    return {m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3], m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
            m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11]};
}

/// The linear part only (directions).
inline Vec3 transformVector(const Affine& m, const Vec3& v) {
    return {m[0] * v[0] + m[1] * v[1] + m[2] * v[2], m[4] * v[0] + m[5] * v[1] + m[6] * v[2],
            m[8] * v[0] + m[9] * v[1] + m[10] * v[2]};
}

/// The transpose of m's linear part applied to v: with m = worldToObject, it
/// carries object-space normals to world space.
inline Vec3 transposedVector(const Affine& m, const Vec3& v) {
    return {m[0] * v[0] + m[4] * v[1] + m[8] * v[2], m[1] * v[0] + m[5] * v[1] + m[9] * v[2],
            m[2] * v[0] + m[6] * v[1] + m[10] * v[2]};
}

inline double determinant3(const Affine& m) {
    return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
           m[2] * (m[4] * m[9] - m[5] * m[8]);
}

/// The inverse transform. Throws dsm::Error "<what>: the transform is
/// singular" when it has none.
inline Affine inverseAffine(const Affine& m, const std::string& what) {
    const double det = determinant3(m);
    if (!(std::abs(det) > 1e-300) || !std::isfinite(det))
        throw Error(ErrorCode::argument, concat(what, ": the transform is singular"));
    const double id = 1.0 / det;
    Affine r{};
    r[0] = (m[5] * m[10] - m[6] * m[9]) * id;
    r[1] = (m[2] * m[9] - m[1] * m[10]) * id;
    r[2] = (m[1] * m[6] - m[2] * m[5]) * id;
    r[4] = (m[6] * m[8] - m[4] * m[10]) * id;
    r[5] = (m[0] * m[10] - m[2] * m[8]) * id;
    r[6] = (m[2] * m[4] - m[0] * m[6]) * id;
    r[8] = (m[4] * m[9] - m[5] * m[8]) * id;
    r[9] = (m[1] * m[8] - m[0] * m[9]) * id;
    r[10] = (m[0] * m[5] - m[1] * m[4]) * id;
    const Vec3 t = transformVector(r, {m[3], m[7], m[11]});
    r[3] = -t[0];
    r[7] = -t[1];
    r[11] = -t[2];
    return r;
}

}  // namespace dsm::detail
