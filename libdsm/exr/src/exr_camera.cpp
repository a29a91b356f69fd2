// The light camera of a deep EXR: OpenEXR's standard camera attributes, our
// exact dsm:* attributes, or a width given by the caller (spec/exr-interop.md
// "Camera attributes" and "Camera").
#include "exr_camera.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>

#include <ImathMatrix.h>
#include <ImfDoubleAttribute.h>
#include <ImfMatrixAttribute.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <ImfVecAttribute.h>

#include "dsm/error.h"
#include "dsm/names.h"
#include "exr_common.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

// ---------------------------------------------------------------------------
// Camera matrices

namespace {

using Matrix4 = std::array<std::array<double, 4>, 4>;

Matrix4 multiply(const Matrix4& a, const Matrix4& b) {
    Matrix4 r{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) r[i][j] += a[i][k] * b[k][j];
    return r;
}

Matrix4 transpose(const Matrix4& a) {
    Matrix4 r{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) r[i][j] = a[j][i];
    return r;
}

/// Gauss-Jordan with partial pivoting; false when singular.
bool invert(Matrix4 a, Matrix4& inverse) {
    Matrix4 r{};
    for (int i = 0; i < 4; ++i) r[i][i] = 1.0;
    for (int col = 0; col < 4; ++col) {
        int pivot = col;
        for (int row = col + 1; row < 4; ++row)
            if (std::abs(a[row][col]) > std::abs(a[pivot][col])) pivot = row;
        if (!(std::abs(a[pivot][col]) > 1e-300)) return false;
        std::swap(a[col], a[pivot]);
        std::swap(r[col], r[pivot]);
        const double scale = 1.0 / a[col][col];
        for (int j = 0; j < 4; ++j) a[col][j] *= scale, r[col][j] *= scale;
        for (int row = 0; row < 4; ++row) {
            if (row == col) continue;
            const double f = a[row][col];
            for (int j = 0; j < 4; ++j) a[row][j] -= f * a[col][j], r[row][j] -= f * r[col][j];
        }
    }
    inverse = r;
    return true;
}

Matrix4 worldToLightMatrix(const LightCamera& camera) {
    Matrix4 m{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) m[i][j] = camera.worldToLight[std::size_t(4 * i + j)];
    return m;
}

/// Light space to NDC, column-vector convention (spec/exr-interop.md).
Matrix4 projectionMatrix(const LightCamera& camera) {
    const auto& w = camera.screenWindow;
    const double dx = w[1] - w[0], dy = w[3] - w[2];
    if (camera.projection == Projection::Perspective)
        return {{{1 / dx, 0, -w[0] / dx, 0}, {0, -1 / dy, w[3] / dy, 0}, {0, 0, 0, 1}, {0, 0, 1, 0}}};
    return {{{1 / dx, 0, 0, -w[0] / dx}, {0, -1 / dy, 0, w[3] / dy}, {0, 0, 1, 0}, {0, 0, 0, 1}}};
}

std::array<std::array<float, 4>, 4> toFloat(const Matrix4& m) {
    std::array<std::array<float, 4>, 4> r{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) r[i][j] = static_cast<float>(m[i][j]);
    return r;
}

}  // namespace

StandardCameraMatrices standardCameraMatrices(const LightCamera& camera) {
    const Matrix4 w = worldToLightMatrix(camera);
    StandardCameraMatrices out;
    out.worldToCamera = toFloat(transpose(w));
    out.worldToNDC = toFloat(transpose(multiply(projectionMatrix(camera), w)));
    return out;
}

LightCamera cameraFromStandardMatrices(const Matrix4& worldToCamera, const Matrix4& worldToNDC) {
    const Matrix4 w = transpose(worldToCamera);
    Matrix4 wInverse;
    if (!invert(w, wInverse)) throw Error(ErrorCode::corrupt, "worldToCamera is singular");
    const Matrix4 p = multiply(transpose(worldToNDC), wInverse);
    double scale = 0.0;
    for (const auto& row : p)
        for (double v : row) scale = std::max(scale, std::abs(v));
    const double eps = 1e-5 * scale;
    auto zero = [&](double v) { return std::abs(v) <= eps; };
    auto notProjection = [] {
        return Error(ErrorCode::corrupt,
                     "worldToNDC is not a perspective or orthographic projection along the camera's z axis");
    };
    if (!(scale > 0.0) || !std::isfinite(scale)) throw notProjection();

    LightCamera camera;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) camera.worldToLight[std::size_t(4 * i + j)] = w[i][j];
    // NDC x = (a s + c), y = (b t + d) with (s, t) the screen coordinates.
    double a, c, b, d;
    if (!zero(p[3][2]) && zero(p[3][0]) && zero(p[3][1]) && zero(p[3][3])) {
        camera.projection = Projection::Perspective;
        if (!zero(p[0][1]) || !zero(p[0][3]) || !zero(p[1][0]) || !zero(p[1][3])) throw notProjection();
        a = p[0][0] / p[3][2], c = p[0][2] / p[3][2], b = p[1][1] / p[3][2], d = p[1][2] / p[3][2];
    } else if (!zero(p[3][3]) && zero(p[3][0]) && zero(p[3][1]) && zero(p[3][2])) {
        camera.projection = Projection::Orthographic;
        if (!zero(p[0][1]) || !zero(p[0][2]) || !zero(p[1][0]) || !zero(p[1][2])) throw notProjection();
        a = p[0][0] / p[3][3], c = p[0][3] / p[3][3], b = p[1][1] / p[3][3], d = p[1][3] / p[3][3];
    } else {
        throw notProjection();
    }
    if (zero(a) || zero(b)) throw notProjection();
    camera.screenWindow = {-c / a, (1.0 - c) / a, (1.0 - d) / b, -d / b};
    camera.validate();
    return camera;
}


namespace {

/// The camera from our exact attributes, or nothing when they are absent.
std::optional<LightCamera> cameraFromDsmAttributes(const Imf::Header& h) {
    const auto* m = exr::findAttribute<Imf::M44dAttribute>(h, "dsm:worldToLight");
    const auto* p = exr::findAttribute<Imf::StringAttribute>(h, "dsm:projection");
    const auto* lo = exr::findAttribute<Imf::V2dAttribute>(h, "dsm:screenWindowMin");
    const auto* hi = exr::findAttribute<Imf::V2dAttribute>(h, "dsm:screenWindowMax");
    if (!m || !p || !lo || !hi) return std::nullopt;
    LightCamera cam;
    if (p->value() == "perspective") cam.projection = Projection::Perspective;
    else if (p->value() == "orthographic") cam.projection = Projection::Orthographic;
    else
        throw Error(ErrorCode::corrupt,
                    concat("dsm:projection '", p->value(), "' is neither perspective nor orthographic"));
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) cam.worldToLight[std::size_t(4 * j + i)] = m->value()[i][j];
    cam.screenWindow = {lo->value().x, hi->value().x, lo->value().y, hi->value().y};
    if (const auto* n = exr::findAttribute<Imf::DoubleAttribute>(h, "dsm:nearPlane")) cam.nearPlane = n->value();
    cam.validate();
    return cam;
}

std::optional<LightCamera> cameraFromStandardAttributes(const Imf::Header& h) {
    if (!Imf::hasWorldToCamera(h) || !Imf::hasWorldToNDC(h)) return std::nullopt;
    Matrix4 c{}, n{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) c[i][j] = Imf::worldToCamera(h)[i][j], n[i][j] = Imf::worldToNDC(h)[i][j];
    return cameraFromStandardMatrices(c, n);
}

/// A centred light of the given width (field of view or orthographic window)
/// with square pixels, placed by the file's worldToCamera when it has one.
LightCamera cameraFromWidth(const Imf::Header& h, const ExrImportOptions& options, std::uint32_t width,
                            std::uint32_t height) {
    LightCamera cam;
    double half = 0.0;
    if (options.fieldOfView) {
        const double degrees = *options.fieldOfView;
        if (!(degrees > 0.0 && degrees < 180.0))
            throw Error(ErrorCode::argument, concat("field of view ", degrees, " is not in (0, 180) degrees"));
        cam.projection = Projection::Perspective;
        half = std::tan(degrees * std::numbers::pi / 360.0);
    } else {
        const double width = options.orthoWidth.value_or(0.0);
        if (!std::isfinite(width) || !(width > 0.0))
            throw Error(ErrorCode::argument, concat("the orthographic width ", width, " is not a finite value > 0"));
        cam.projection = Projection::Orthographic;
        half = width / 2.0;
    }
    const double halfHeight = half * double(height) / double(width);
    cam.screenWindow = {-half, half, -halfHeight, halfHeight};
    if (Imf::hasWorldToCamera(h))
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) cam.worldToLight[std::size_t(4 * j + i)] = Imf::worldToCamera(h)[i][j];
    cam.validate();
    return cam;
}

}  // namespace

LightCamera exr::lightCamera(const Imf::Header& h, const ExrImportOptions& options, std::uint32_t width,
                             std::uint32_t height, std::string& source) {
    if (options.camera) {
        source = "option";
        return *options.camera;
    }
    if (options.fieldOfView || options.orthoWidth) {
        source = options.fieldOfView ? "field of view" : "orthographic width";
        return cameraFromWidth(h, options, width, height);
    }
    std::optional<LightCamera> cam;
    try {
        if ((cam = cameraFromDsmAttributes(h))) source = "dsm attributes";
        else if ((cam = cameraFromStandardAttributes(h))) source = "standard attributes";
    } catch (const Error& e) {
        throw Error(ErrorCode::corrupt, concat("light camera: ", e.what()));
    }
    if (!cam)
        throw Error(ErrorCode::argument,
                    "no light camera: neither dsm:* nor worldToCamera and worldToNDC attributes; give one with "
                    "--fov DEG, --ortho-width W or --camera-from MAP.dsm (ExrImportOptions::fieldOfView, "
                    "orthoWidth or camera)");
    return *cam;
}

DSM_NAMESPACE_END
