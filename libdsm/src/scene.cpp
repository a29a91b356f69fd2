// Scene files (spec/scene.md): JSON parsing with precise messages, the light
// camera, OBJ meshes, Cem Yuksel's .hair files and procedural hair balls.
#include "dsm/scene.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <set>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <tiny_obj_loader.h>

#include "density.h"
#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN
namespace {

using json = nlohmann::json;

constexpr double kPi = 3.14159265358979323846;
constexpr std::uint32_t kMaxResolution = 1u << 17;  // the reader's default limit

// ---------------------------------------------------------------------------
// Small vector helpers.

Vec3 add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 mul(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double length(const Vec3& a) { return std::sqrt(dot(a, a)); }
Vec3 normalized(const Vec3& a) { return mul(a, 1.0 / length(a)); }

using Mat4 = std::array<double, 16>;
constexpr Mat4 kIdentity{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

Mat4 multiply(const Mat4& a, const Mat4& b) {
    Mat4 c{};
    for (std::size_t r = 0; r < 4; ++r)
        for (std::size_t k = 0; k < 4; ++k)
            for (std::size_t j = 0; j < 4; ++j) c[4 * r + j] += a[4 * r + k] * b[4 * k + j];
    return c;
}

// ---------------------------------------------------------------------------
// Deterministic random numbers: SplitMix64 and an explicit mapping to doubles,
// so generated content is the same with every standard library.

std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

class SplitMix64 {
public:
    explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
    std::uint64_t next() { return mix64(state_ += 0x9E3779B97F4A7C15ull); }
    /// Uniform in [0, 1): the top 53 bits as a binary fraction.
    double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
    /// Uniform on the unit sphere, by rejection from the cube (no libm calls
    /// but sqrt, which IEEE 754 rounds exactly).
    Vec3 unitVector() {
        for (;;) {
            const Vec3 v{2.0 * uniform() - 1.0, 2.0 * uniform() - 1.0, 2.0 * uniform() - 1.0};
            const double s = dot(v, v);
            if (s > 1e-6 && s <= 1.0) return mul(v, 1.0 / std::sqrt(s));
        }
    }

private:
    std::uint64_t state_;
};

// ---------------------------------------------------------------------------
// JSON helpers. Every message names the scene and a JSON pointer.

std::string describe(const json& v) {
    std::string s = v.dump(-1, ' ', false, json::error_handler_t::replace);
    if (s.size() > 60) s = s.substr(0, 57) + "...";
    return s;
}

std::string formatNumber(double x) { return detail::concat(x); }

struct Range {
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    bool loOpen = false;
    bool hiOpen = false;

    bool contains(double x) const { return (loOpen ? x > lo : x >= lo) && (hiOpen ? x < hi : x <= hi); }
    std::string text() const {
        const bool hasLo = std::isfinite(lo), hasHi = std::isfinite(hi);
        if (hasLo && hasHi)
            return std::string(loOpen ? "(" : "[") + formatNumber(lo) + ", " + formatNumber(hi) + (hiOpen ? ")" : "]");
        if (hasLo) return std::string(loOpen ? "> " : ">= ") + formatNumber(lo);
        if (hasHi) return std::string(hiOpen ? "< " : "<= ") + formatNumber(hi);
        return "";
    }
};
const Range kAny{};
const Range kPositive{0.0, std::numeric_limits<double>::infinity(), true, false};
const Range kNonNegative{0.0, std::numeric_limits<double>::infinity(), false, false};
const Range kUnit{0.0, 1.0, false, false};

class Parser {
public:
    Parser(std::string name, std::string baseDirectory) : name_(std::move(name)), base_(std::move(baseDirectory)) {}

    [[noreturn]] void fail(const std::string& path, const std::string& message) const {
        throw Error(detail::concat("scene '", name_, "': ", path.empty() ? std::string() : path + ": ", message));
    }
    [[noreturn]] void expected(const std::string& path, const std::string& what, const json& got) const {
        fail(path, "expected " + what + ", got " + describe(got));
    }

    std::string resolve(const std::string& file) const {
        const std::filesystem::path p(file);
        if (p.is_absolute() || base_.empty()) return p.lexically_normal().string();
        return (std::filesystem::path(base_) / p).lexically_normal().string();
    }

    void requireObject(const json& v, const std::string& path, const char* what) const {
        if (!v.is_object()) expected(path, what, v);
    }

    /// Rejects keys not in `allowed`; keys starting with '_' are comments.
    void checkKeys(const json& object, const std::string& path, const std::vector<std::string_view>& allowed,
                   const std::string& context = "") const {
        for (auto it = object.begin(); it != object.end(); ++it) {
            const std::string& key = it.key();
            if (!key.empty() && key[0] == '_') continue;
            if (std::find(allowed.begin(), allowed.end(), key) != allowed.end()) continue;
            std::string list;
            for (std::string_view a : allowed) {
                if (!list.empty()) list += ", ";
                list += a;
            }
            fail(path + "/" + key, "unknown key \"" + key + "\"" + context + " (allowed here: " + list + ")");
        }
    }

    static const json* find(const json& object, const char* key) {
        const auto it = object.find(key);
        return it == object.end() ? nullptr : &*it;
    }
    const json& require(const json& object, const std::string& path, const char* key) const {
        const json* v = find(object, key);
        if (!v) fail(path, std::string("missing required key \"") + key + "\"");
        return *v;
    }

    double number(const json& v, const std::string& path, const Range& range = kAny) const {
        const std::string what = range.text().empty() ? "a number" : "a number " + inText(range);
        if (!v.is_number()) expected(path, what, v);
        const double x = v.get<double>();
        if (!std::isfinite(x) || !range.contains(x)) expected(path, what, v);
        return x;
    }
    double number(const json& object, const std::string& path, const char* key, double fallback,
                  const Range& range = kAny) const {
        const json* v = find(object, key);
        return v ? number(*v, path + "/" + key, range) : fallback;
    }
    double requiredNumber(const json& object, const std::string& path, const char* key,
                          const Range& range = kAny) const {
        return number(require(object, path, key), path + "/" + key, range);
    }

    std::uint64_t integer(const json& v, const std::string& path, std::uint64_t lo, std::uint64_t hi) const {
        const std::string what = detail::concat("an integer in [", lo, ", ", hi, "]");
        if (!v.is_number()) expected(path, what, v);
        if (v.is_number_unsigned()) {
            const std::uint64_t x = v.get<std::uint64_t>();
            if (x < lo || x > hi) expected(path, what, v);
            return x;
        }
        if (v.is_number_integer()) {
            const std::int64_t x = v.get<std::int64_t>();
            if (x < 0 || static_cast<std::uint64_t>(x) < lo || static_cast<std::uint64_t>(x) > hi)
                expected(path, what, v);
            return static_cast<std::uint64_t>(x);
        }
        const double x = v.get<double>();  // e.g. 1e4
        if (!std::isfinite(x) || x != std::floor(x) || x < static_cast<double>(lo) || x > static_cast<double>(hi))
            expected(path, what, v);
        return static_cast<std::uint64_t>(x);
    }
    std::uint64_t integer(const json& object, const std::string& path, const char* key, std::uint64_t fallback,
                          std::uint64_t lo, std::uint64_t hi) const {
        const json* v = find(object, key);
        return v ? integer(*v, path + "/" + key, lo, hi) : fallback;
    }

    std::string string(const json& v, const std::string& path) const {
        if (!v.is_string()) expected(path, "a string", v);
        return v.get<std::string>();
    }
    std::string nonEmptyString(const json& v, const std::string& path) const {
        if (!v.is_string() || v.get_ref<const std::string&>().empty()) expected(path, "a non-empty string", v);
        return v.get<std::string>();
    }

    Vec3 vec3(const json& v, const std::string& path, const Range& range = kAny) const {
        const std::string what = range.text().empty() ? "[x, y, z] (3 numbers)" : "3 numbers " + inText(range);
        if (!v.is_array() || v.size() != 3) expected(path, what, v);
        Vec3 out{};
        for (std::size_t i = 0; i < 3; ++i) {
            if (!v[i].is_number()) expected(path, what, v);
            out[i] = v[i].get<double>();
            if (!std::isfinite(out[i]) || !range.contains(out[i])) expected(path, what, v);
        }
        return out;
    }
    Vec3 vec3(const json& object, const std::string& path, const char* key, const Vec3& fallback) const {
        const json* v = find(object, key);
        return v ? vec3(*v, path + "/" + key) : fallback;
    }
    Vec3 nonZeroVec3(const json& v, const std::string& path) const {
        const Vec3 out = vec3(v, path);
        if (!(length(out) > 0.0) || !std::isfinite(length(out))) expected(path, "a non-zero vector [x, y, z]", v);
        return out;
    }

    /// An array of [x, y, z] points, stored as floats.
    std::vector<std::array<float, 3>> points(const json& v, const std::string& path) const {
        if (!v.is_array()) expected(path, "an array of [x, y, z] points", v);
        std::vector<std::array<float, 3>> out;
        out.reserve(v.size());
        for (std::size_t i = 0; i < v.size(); ++i) {
            const Vec3 p = vec3(v[i], detail::concat(path, "/", i));
            const std::array<float, 3> f{static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
            if (!std::isfinite(f[0]) || !std::isfinite(f[1]) || !std::isfinite(f[2]))
                expected(detail::concat(path, "/", i), "coordinates within float range", v[i]);
            out.push_back(f);
        }
        return out;
    }

    const std::string& name() const { return name_; }

private:
    static std::string inText(const Range& range) {
        const std::string t = range.text();
        return (t[0] == '[' || t[0] == '(') ? "in " + t : t;
    }

    std::string name_;
    std::string base_;
};

// ---------------------------------------------------------------------------
// The light.

std::uint32_t narrowU32(std::uint64_t x) { return static_cast<std::uint32_t>(x); }

LightDescription parseLight(const Parser& p, const json& v) {
    const std::string path = "/light";
    p.requireObject(v, path, "an object");
    const std::string type = p.string(p.require(v, path, "type"), path + "/type");
    LightDescription light;
    if (type == "spot") {
        light.projection = Projection::Perspective;
        p.checkKeys(v, path,
                    {"type", "position", "direction", "look_at", "up", "fov", "resolution", "near", "area_radius"});
    } else if (type == "distant") {
        light.projection = Projection::Orthographic;
        if (Parser::find(v, "area_radius"))
            p.fail(path + "/area_radius", "applies only to spot lights (a distant light has no position to push back)");
        p.checkKeys(v, path, {"type", "position", "direction", "look_at", "up", "extent", "resolution", "near"});
    } else {
        p.expected(path + "/type", "\"spot\" or \"distant\"", v["type"]);
    }

    light.position = p.vec3(p.require(v, path, "position"), path + "/position");
    const json* direction = Parser::find(v, "direction");
    const json* lookAt = Parser::find(v, "look_at");
    if (direction && lookAt) p.fail(path, "give either \"direction\" or \"look_at\", not both");
    if (!direction && !lookAt) p.fail(path, "missing required key \"direction\" (or \"look_at\")");
    if (direction) {
        light.direction = normalized(p.nonZeroVec3(*direction, path + "/direction"));
    } else {
        const Vec3 target = p.vec3(*lookAt, path + "/look_at");
        const Vec3 d = sub(target, light.position);
        if (!(length(d) > 0.0)) p.fail(path + "/look_at", "is the light's position: the direction is undefined");
        light.direction = normalized(d);
    }
    if (const json* up = Parser::find(v, "up")) {
        light.up = normalized(p.nonZeroVec3(*up, path + "/up"));
        if (length(cross(light.direction, light.up)) < 1e-9)
            p.fail(path + "/up", "is parallel to the light's direction");
    } else {
        light.up = {0.0, 1.0, 0.0};
        if (length(cross(light.direction, light.up)) < 1e-9)
            p.fail(path, "the light looks along the default \"up\" [0, 1, 0]; give another \"up\"");
    }

    if (light.projection == Projection::Perspective) {
        light.fieldOfViewDegrees = p.number(v, path, "fov", 45.0, Range{0.0, 180.0, true, true});
        light.areaLightRadius = p.number(v, path, "area_radius", 0.0, kNonNegative);
    } else {
        light.extent = p.requiredNumber(v, path, "extent", kPositive);
    }

    light.width = light.height = 512;
    if (const json* r = Parser::find(v, "resolution")) {
        const std::string rpath = path + "/resolution";
        if (r->is_number()) {
            light.width = light.height = narrowU32(p.integer(*r, rpath, 1, kMaxResolution));
        } else if (r->is_array() && r->size() == 2) {
            light.width = narrowU32(p.integer((*r)[0], rpath + "/0", 1, kMaxResolution));
            light.height = narrowU32(p.integer((*r)[1], rpath + "/1", 1, kMaxResolution));
        } else {
            p.expected(rpath, detail::concat("[width, height] or one size, integers in [1, ", kMaxResolution, "]"), *r);
        }
    }
    light.nearPlane = p.number(v, path, "near", 0.0, kNonNegative);
    return light;
}

// ---------------------------------------------------------------------------
// Transforms: a 16-number row-major matrix, a {scale, rotate, translate}
// object (M = T R S), or an array of such objects applied in order.

Mat4 rotation(const Vec3& axisIn, double degrees) {
    const Vec3 a = normalized(axisIn);
    const double t = degrees * kPi / 180.0, c = std::cos(t), s = std::sin(t), k = 1.0 - c;
    // clang-format off
    return {c + a[0] * a[0] * k,        a[0] * a[1] * k - a[2] * s, a[0] * a[2] * k + a[1] * s, 0,
            a[1] * a[0] * k + a[2] * s, c + a[1] * a[1] * k,        a[1] * a[2] * k - a[0] * s, 0,
            a[2] * a[0] * k - a[1] * s, a[2] * a[1] * k + a[0] * s, c + a[2] * a[2] * k,        0,
            0,                          0,                          0,                          1};
    // clang-format on
}

Mat4 parseTrs(const Parser& p, const json& v, const std::string& path) {
    p.requireObject(v, path, "a transform object {\"scale\", \"rotate\", \"translate\"}");
    p.checkKeys(v, path, {"scale", "rotate", "translate"});
    Mat4 s = kIdentity, r = kIdentity, t = kIdentity;
    if (const json* sv = Parser::find(v, "scale")) {
        const std::string spath = path + "/scale";
        Vec3 f{};
        if (sv->is_number()) {
            const double x = p.number(*sv, spath);
            f = {x, x, x};
        } else {
            f = p.vec3(*sv, spath);
        }
        if (f[0] == 0.0 || f[1] == 0.0 || f[2] == 0.0) p.expected(spath, "non-zero scale factors", *sv);
        s[0] = f[0];
        s[5] = f[1];
        s[10] = f[2];
    }
    if (const json* rv = Parser::find(v, "rotate")) {
        const std::string rpath = path + "/rotate";
        p.requireObject(*rv, rpath, "{\"axis\": [x, y, z], \"angle\": degrees}");
        p.checkKeys(*rv, rpath, {"axis", "angle"});
        const Vec3 axis = p.nonZeroVec3(p.require(*rv, rpath, "axis"), rpath + "/axis");
        const double angle = p.requiredNumber(*rv, rpath, "angle");
        r = rotation(axis, angle);
    }
    if (const json* tv = Parser::find(v, "translate")) {
        const Vec3 d = p.vec3(*tv, path + "/translate");
        t[3] = d[0];
        t[7] = d[1];
        t[11] = d[2];
    }
    return multiply(t, multiply(r, s));
}

Mat4 parseTransform(const Parser& p, const json& v, const std::string& path) {
    const char* what =
        "16 numbers (a row-major matrix), a {\"scale\", \"rotate\", \"translate\"} object or an array of them";
    if (v.is_object()) return parseTrs(p, v, path);
    if (!v.is_array()) p.expected(path, what, v);
    if (!v.empty() && v[0].is_number()) {
        if (v.size() != 16) p.expected(path, what, v);
        Mat4 m{};
        for (std::size_t i = 0; i < 16; ++i) m[i] = p.number(v[i], detail::concat(path, "/", i));
        if (m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || m[15] != 1.0)
            p.fail(path, "the last row must be [0, 0, 0, 1] (affine transforms only)");
        const double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                           m[2] * (m[4] * m[9] - m[5] * m[8]);
        if (!(std::abs(det) > 0.0)) p.fail(path, "the matrix is singular");
        return m;
    }
    Mat4 m = kIdentity;
    for (std::size_t i = 0; i < v.size(); ++i) m = multiply(parseTrs(p, v[i], detail::concat(path, "/", i)), m);
    return m;
}

// ---------------------------------------------------------------------------
// Geometry.

TriangleMesh loadObj(const Parser& p, const std::string& file, const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec))
        p.fail(path, "OBJ file '" + file + "' does not exist or is not a file");
    tinyobj::ObjReaderConfig config;
    config.triangulate = true;
    config.vertex_color = false;
    config.mtl_search_path = std::filesystem::path(file).parent_path().string();
    tinyobj::ObjReader reader;
    if (!reader.ParseFromFile(file, config)) {
        std::string message = reader.Error();
        while (!message.empty() && (message.back() == '\n' || message.back() == '\r')) message.pop_back();
        std::replace(message.begin(), message.end(), '\n', ' ');
        p.fail(path, "cannot read OBJ file '" + file + "': " + message);
    }
    const auto& attrib = reader.GetAttrib();
    TriangleMesh mesh;
    const std::size_t vertexCount = attrib.vertices.size() / 3;
    mesh.positions.reserve(vertexCount);
    for (std::size_t i = 0; i < vertexCount; ++i) {
        const std::array<float, 3> q{attrib.vertices[3 * i], attrib.vertices[3 * i + 1], attrib.vertices[3 * i + 2]};
        if (!std::isfinite(q[0]) || !std::isfinite(q[1]) || !std::isfinite(q[2]))
            p.fail(path, detail::concat("OBJ file '", file, "': vertex ", i + 1, " is not finite"));
        mesh.positions.push_back(q);
    }
    for (const auto& shape : reader.GetShapes()) {
        std::size_t offset = 0;
        for (std::size_t f = 0; f < shape.mesh.num_face_vertices.size(); ++f) {
            const std::size_t n = shape.mesh.num_face_vertices[f];
            if (n == 3) {
                std::array<std::uint32_t, 3> t{};
                for (std::size_t k = 0; k < 3; ++k) {
                    const int index = shape.mesh.indices[offset + k].vertex_index;
                    if (index < 0 || static_cast<std::size_t>(index) >= vertexCount)
                        p.fail(path, detail::concat("OBJ file '", file, "': shape '", shape.name, "' face ", f,
                                                    " refers to vertex ", index + 1, " of ", vertexCount));
                    t[k] = static_cast<std::uint32_t>(index);
                }
                mesh.triangles.push_back(t);
            }
            offset += n;
        }
    }
    if (mesh.triangles.empty()) p.fail(path, "OBJ file '" + file + "' has no faces");
    return mesh;
}

TriangleMesh parseMesh(const Parser& p, const json& v, const std::string& path) {
    const json* file = Parser::find(v, "file");
    const json* positions = Parser::find(v, "positions");
    const json* triangles = Parser::find(v, "triangles");
    if (file && (positions || triangles))
        p.fail(path, "give either \"file\" or \"positions\" and \"triangles\", not both");
    if (file) return loadObj(p, p.resolve(p.nonEmptyString(*file, path + "/file")), path + "/file");
    if (!positions && !triangles) p.fail(path, "missing required key \"file\" (or \"positions\" and \"triangles\")");
    TriangleMesh mesh;
    mesh.positions = p.points(p.require(v, path, "positions"), path + "/positions");
    const json& t = p.require(v, path, "triangles");
    const std::string tpath = path + "/triangles";
    if (!t.is_array() || t.empty()) p.expected(tpath, "a non-empty array of [i, j, k] vertex indices", t);
    const std::uint64_t maxIndex = mesh.positions.empty() ? 0 : mesh.positions.size() - 1;
    for (std::size_t i = 0; i < t.size(); ++i) {
        const std::string ipath = detail::concat(tpath, "/", i);
        if (!t[i].is_array() || t[i].size() != 3) p.expected(ipath, "[i, j, k] (3 vertex indices)", t[i]);
        if (mesh.positions.empty()) p.fail(ipath, "refers to a vertex but \"positions\" is empty");
        std::array<std::uint32_t, 3> tri{};
        for (std::size_t k = 0; k < 3; ++k)
            tri[k] = narrowU32(p.integer(t[i][k], detail::concat(ipath, "/", k), 0, maxIndex));
        mesh.triangles.push_back(tri);
    }
    return mesh;
}

Quad parsePlane(const Parser& p, const json& v, const std::string& path) {
    Quad q;
    q.center = p.vec3(v, path, "center", {0.0, 0.0, 0.0});
    const Vec3 n = normalized(p.nonZeroVec3(p.require(v, path, "normal"), path + "/normal"));
    const json& size = p.require(v, path, "size");
    double su = 0.0, sv = 0.0;
    if (size.is_number()) {
        su = sv = p.number(size, path + "/size", kPositive);
    } else if (size.is_array() && size.size() == 2) {
        su = p.number(size[0], path + "/size/0", kPositive);
        sv = p.number(size[1], path + "/size/1", kPositive);
    } else {
        p.expected(path + "/size", "a side length > 0 or [u, v] side lengths", size);
    }
    const Vec3 a = std::abs(n[1]) < 0.9 ? Vec3{0.0, 1.0, 0.0} : Vec3{1.0, 0.0, 0.0};
    const Vec3 u = normalized(cross(a, n));
    const Vec3 w = cross(n, u);
    q.halfU = mul(u, 0.5 * su);
    q.halfV = mul(w, 0.5 * sv);
    return q;
}

Quad parseQuad(const Parser& p, const json& v, const std::string& path) {
    Quad q;
    q.center = p.vec3(v, path, "center", {0.0, 0.0, 0.0});
    q.halfU = p.nonZeroVec3(p.require(v, path, "u"), path + "/u");
    q.halfV = p.nonZeroVec3(p.require(v, path, "v"), path + "/v");
    if (!(std::abs(dot(q.halfU, q.halfV)) <= 1e-6 * length(q.halfU) * length(q.halfV)))
        p.fail(path + "/v", "is not perpendicular to \"u\": a quad is a rectangle");
    return q;
}

Curves parseHair(const Parser& p, const json& v, const std::string& path) {
    const json* file = Parser::find(v, "file");
    const json* ball = Parser::find(v, "hairball");
    if (file && ball) p.fail(path, "give either \"file\" or \"hairball\", not both");
    if (!file && !ball) p.fail(path, "missing required key \"file\" (or \"hairball\")");
    if (file) {
        const std::string fpath = path + "/file";
        const std::string resolved = p.resolve(p.nonEmptyString(*file, fpath));
        Curves curves;
        try {
            curves = loadHairFile(resolved);
        } catch (const Error& e) {
            p.fail(fpath, e.what());
        }
        if (Parser::find(v, "width"))
            curves.widths = {static_cast<float>(p.number(v["width"], path + "/width", kPositive))};
        return curves;
    }
    if (Parser::find(v, "width"))
        p.fail(path + "/width", "applies only to hair files (a hair ball has its own \"width\")");
    const std::string bpath = path + "/hairball";
    p.requireObject(*ball, bpath, "an object");
    p.checkKeys(*ball, bpath, {"center", "radius", "count", "length", "curl", "width", "segments", "seed"});
    HairBallParameters h;
    h.center = p.vec3(*ball, bpath, "center", h.center);
    h.radius = p.number(*ball, bpath, "radius", h.radius, kPositive);
    h.count = narrowU32(p.integer(*ball, bpath, "count", h.count, 1, 10'000'000));
    h.length = p.number(*ball, bpath, "length", h.length, kPositive);
    h.curl = p.number(*ball, bpath, "curl", h.curl, kNonNegative);
    h.width = p.number(*ball, bpath, "width", h.width, kPositive);
    h.segments = narrowU32(p.integer(*ball, bpath, "segments", h.segments, 1, 1000));
    h.seed = narrowU32(p.integer(*ball, bpath, "seed", h.seed, 0, 0xFFFFFFFFull));
    if (static_cast<std::uint64_t>(h.count) * (h.segments + 1ull) > 100'000'000ull)
        p.fail(bpath, "count * (segments + 1) exceeds 100,000,000 points");
    return generateHairBall(h);
}

Curves parseCurves(const Parser& p, const json& v, const std::string& path) {
    Curves c;
    const json& counts = p.require(v, path, "points_per_curve");
    const std::string cpath = path + "/points_per_curve";
    if (!counts.is_array() || counts.empty())
        p.expected(cpath, "a non-empty array of point counts (each >= 2)", counts);
    std::uint64_t total = 0;
    for (std::size_t i = 0; i < counts.size(); ++i) {
        const std::uint64_t n = p.integer(counts[i], detail::concat(cpath, "/", i), 2, 0xFFFFFFFFull);
        c.pointsPerCurve.push_back(narrowU32(n));
        total += n;
    }
    c.points = p.points(p.require(v, path, "points"), path + "/points");
    if (c.points.size() != total)
        p.fail(path + "/points",
               detail::concat("has ", c.points.size(), " points but \"points_per_curve\" adds up to ", total));
    const json& w = p.require(v, path, "width");
    const std::string wpath = path + "/width";
    if (w.is_number()) {
        c.widths = {static_cast<float>(p.number(w, wpath, kPositive))};
    } else if (w.is_array()) {
        if (w.size() != total)
            p.expected(wpath, detail::concat("one width > 0 or an array of ", total, " (one per point)"), w);
        c.widths.clear();
        for (std::size_t i = 0; i < w.size(); ++i)
            c.widths.push_back(static_cast<float>(p.number(w[i], detail::concat(wpath, "/", i), kPositive)));
    } else {
        p.expected(wpath, "a width > 0 or an array of widths (one per point)", w);
    }
    return c;
}

Volume parseVolume(const Parser& p, const json& v, const std::string& path) {
    Volume vol;
    const json& d = p.require(v, path, "density");
    const std::string dpath = path + "/density";
    p.requireObject(d, dpath, "a density object with a \"type\"");
    const std::string type = p.string(p.require(d, dpath, "type"), dpath + "/type");
    if (type == "homogeneous") {
        p.checkKeys(d, dpath, {"type", "value"});
        vol.density = HomogeneousDensity{p.requiredNumber(d, dpath, "value", kNonNegative)};
    } else if (type == "noise") {
        p.checkKeys(d, dpath, {"type", "density", "frequency", "octaves", "seed", "falloff"});
        NoiseCloudDensity n;
        n.density = p.number(d, dpath, "density", n.density, kNonNegative);
        n.frequency = p.number(d, dpath, "frequency", n.frequency, kPositive);
        n.octaves = static_cast<int>(p.integer(d, dpath, "octaves", static_cast<std::uint64_t>(n.octaves), 1, 16));
        n.seed = narrowU32(p.integer(d, dpath, "seed", n.seed, 0, 0xFFFFFFFFull));
        n.falloff = p.number(d, dpath, "falloff", n.falloff, kUnit);
        vol.density = n;
    } else if (type == "vdb") {
        p.checkKeys(d, dpath, {"type", "file", "grid"});
        VdbDensity g;
        g.file = p.resolve(p.nonEmptyString(p.require(d, dpath, "file"), dpath + "/file"));
        if (const json* grid = Parser::find(d, "grid")) g.grid = p.nonEmptyString(*grid, dpath + "/grid");
        std::error_code ec;
        if (!std::filesystem::is_regular_file(g.file, ec))
            p.fail(dpath + "/file", "VDB file '" + g.file + "' does not exist or is not a file");
        vol.density = g;
    } else {
        p.expected(dpath + "/type", "\"homogeneous\", \"noise\" or \"vdb\"", d["type"]);
    }

    if (const json* b = Parser::find(v, "bounds")) {
        const std::string bpath = path + "/bounds";
        if (!b->is_array() || b->size() != 2) p.expected(bpath, "[[xmin, ymin, zmin], [xmax, ymax, zmax]]", *b);
        vol.boundsMin = p.vec3((*b)[0], bpath + "/0");
        vol.boundsMax = p.vec3((*b)[1], bpath + "/1");
        for (std::size_t i = 0; i < 3; ++i)
            if (!(vol.boundsMin[i] < vol.boundsMax[i]))
                p.fail(bpath, "the minimum must be below the maximum on every axis");
    } else if (const auto* g = std::get_if<VdbDensity>(&vol.density)) {
        try {
            vdbBounds(*g, vol.boundsMin, vol.boundsMax);
        } catch (const Error& e) {
            p.fail(dpath + "/file", e.what());
        }
    } else {
        p.fail(path, "missing required key \"bounds\"");
    }
    vol.scale = p.number(v, path, "scale", 1.0, kNonNegative);
    double shortest = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < 3; ++i) shortest = std::min(shortest, vol.boundsMax[i] - vol.boundsMin[i]);
    vol.step = p.number(v, path, "step", shortest / 64.0, kPositive);
    return vol;
}

Rgb parseOpacity(const Parser& p, const json& v, const std::string& path) {
    const char* what = "a number or [r, g, b] in [0, 1]";
    if (v.is_number()) {
        const double x = v.get<double>();
        if (!kUnit.contains(x)) p.expected(path, what, v);
        return {static_cast<float>(x), static_cast<float>(x), static_cast<float>(x)};
    }
    if (!v.is_array() || v.size() != 3) p.expected(path, what, v);
    Rgb out{};
    for (std::size_t i = 0; i < 3; ++i) {
        if (!v[i].is_number() || !kUnit.contains(v[i].get<double>())) p.expected(path, what, v);
        out[i] = static_cast<float>(v[i].get<double>());
    }
    return out;
}

SceneObject parseObject(const Parser& p, const json& v, std::size_t index) {
    const std::string path = detail::concat("/objects/", index);
    p.requireObject(v, path, "an object with a \"type\"");
    const std::string type = p.string(p.require(v, path, "type"), path + "/type");
    SceneObject o;
    o.name = detail::concat(type, "#", index);
    // Keys every object has, then the type's own.
    auto keys = [&](std::initializer_list<std::string_view> own) {
        if (type == "volume" && Parser::find(v, "opacity"))
            p.fail(path + "/opacity", "does not apply to volumes (their extinction is density * scale)");
        std::vector<std::string_view> all{"type", "name", "opacity", "transform", "motion"};
        if (type == "volume") all.erase(all.begin() + 2);
        all.insert(all.end(), own.begin(), own.end());
        p.checkKeys(v, path, all, " for a " + type);
    };
    if (type == "mesh") {
        keys({"file", "positions", "triangles"});
        o.geometry = parseMesh(p, v, path);
    } else if (type == "sphere") {
        keys({"center", "radius"});
        Sphere s;
        s.center = p.vec3(v, path, "center", s.center);
        s.radius = p.requiredNumber(v, path, "radius", kPositive);
        o.geometry = s;
    } else if (type == "quad") {
        keys({"center", "u", "v"});
        o.geometry = parseQuad(p, v, path);
    } else if (type == "plane") {
        keys({"center", "normal", "size"});
        o.geometry = parsePlane(p, v, path);
    } else if (type == "hair") {
        keys({"file", "hairball", "width"});
        o.geometry = parseHair(p, v, path);
    } else if (type == "curves") {
        keys({"points_per_curve", "points", "width"});
        o.geometry = parseCurves(p, v, path);
    } else if (type == "volume") {
        keys({"bounds", "density", "scale", "step"});
        o.geometry = parseVolume(p, v, path);
    } else {
        p.expected(path + "/type", "\"mesh\", \"sphere\", \"quad\", \"plane\", \"hair\", \"curves\" or \"volume\"",
                   v["type"]);
    }
    if (const json* n = Parser::find(v, "name")) o.name = p.string(*n, path + "/name");
    if (const json* op = Parser::find(v, "opacity")) o.opacity = parseOpacity(p, *op, path + "/opacity");
    if (const json* t = Parser::find(v, "transform")) o.objectToWorld = parseTransform(p, *t, path + "/transform");
    o.motion = p.vec3(v, path, "motion", o.motion);
    return o;
}

// Rejects duplicate keys in any object while parsing (nlohmann keeps the last
// one silently, which hides typos and merge accidents).
json parseJson(const Parser& p, const std::string& text) {
    std::vector<std::set<std::string>> keys;
    std::string duplicate;
    const json::parser_callback_t callback = [&](int, json::parse_event_t event, json& parsed) {
        switch (event) {
            case json::parse_event_t::object_start: keys.emplace_back(); break;
            case json::parse_event_t::object_end:
                if (!keys.empty()) keys.pop_back();
                break;
            case json::parse_event_t::key:
                if (!keys.empty() && !keys.back().insert(parsed.get<std::string>()).second && duplicate.empty())
                    duplicate = parsed.get<std::string>();
                break;
            default: break;
        }
        return true;
    };
    json doc;
    try {
        doc = json::parse(text, callback);
    } catch (const json::parse_error& e) {
        std::string message = e.what();
        const auto close = message.find("] ");
        if (message.rfind("[json.exception", 0) == 0 && close != std::string::npos) message = message.substr(close + 2);
        p.fail("", "invalid JSON: " + message);
    }
    if (!duplicate.empty()) p.fail("", "key \"" + duplicate + "\" appears twice in one object");
    return doc;
}

// ---------------------------------------------------------------------------
// .hair files: little-endian, a 128-byte header then the arrays.

std::uint32_t readU32(const unsigned char* b) {
    return static_cast<std::uint32_t>(b[0]) | static_cast<std::uint32_t>(b[1]) << 8 |
           static_cast<std::uint32_t>(b[2]) << 16 | static_cast<std::uint32_t>(b[3]) << 24;
}
float readF32(const unsigned char* b) {
    const std::uint32_t bits = readU32(b);
    float f;
    std::memcpy(&f, &bits, sizeof f);
    return f;
}

}  // namespace

// ---------------------------------------------------------------------------

bool Scene::isColoured() const {
    for (const SceneObject& o : objects) {
        if (std::holds_alternative<Volume>(o.geometry)) continue;
        if (o.opacity[0] != o.opacity[1] || o.opacity[1] != o.opacity[2]) return true;
    }
    return false;
}

LightCamera lightCamera(const LightDescription& light) {
    auto fail = [](const std::string& m) -> void { throw Error("light: " + m); };
    const Vec3 f = normalized(light.direction);
    if (!std::isfinite(f[0]) || !std::isfinite(f[1]) || !std::isfinite(f[2]))
        fail("the direction is zero or not finite");
    const Vec3 rc = cross(f, light.up);
    if (!(length(rc) > 1e-9 * length(light.up)) || !std::isfinite(length(rc)))
        fail("\"up\" is zero, not finite or parallel to the direction");
    const Vec3 r = normalized(rc);
    const Vec3 u = cross(r, f);
    if (light.width == 0 || light.height == 0) fail("the resolution is empty");

    // The wider side spans the full field of view (or extent); the other is
    // scaled by the aspect ratio so pixels are square.
    double ax = 1.0, ay = 1.0;
    if (light.width >= light.height)
        ay = static_cast<double>(light.height) / light.width;
    else
        ax = static_cast<double>(light.width) / light.height;

    LightCamera camera;
    camera.projection = light.projection;
    Vec3 eye = light.position;
    double halfSize = 0.0;
    camera.nearPlane = light.nearPlane;
    if (light.projection == Projection::Perspective) {
        if (!(light.fieldOfViewDegrees > 0.0 && light.fieldOfViewDegrees < 180.0))
            fail(detail::concat("field of view ", light.fieldOfViewDegrees, " is not in (0, 180) degrees"));
        halfSize = std::tan(0.5 * light.fieldOfViewDegrees * kPi / 180.0);
        if (!(light.areaLightRadius >= 0.0) || !std::isfinite(light.areaLightRadius))
            fail(detail::concat("area light radius ", light.areaLightRadius, " is not a finite value >= 0"));
        if (light.areaLightRadius > 0.0) {
            // Xie et al. 2007, eq. 4, with the narrower half-angle so the
            // pushed-back frustum contains every point's frustum on both axes.
            const double d = light.areaLightRadius / (halfSize * std::min(ax, ay));
            eye = sub(eye, mul(f, d));
            camera.nearPlane += d;
        }
    } else {
        if (!(light.extent > 0.0) || !std::isfinite(light.extent))
            fail(detail::concat("extent ", light.extent, " is not a finite value > 0"));
        halfSize = light.extent;
    }
    camera.screenWindow = {-halfSize * ax, halfSize * ax, -halfSize * ay, halfSize * ay};
    const Vec3 rows[3] = {r, u, f};
    for (std::size_t i = 0; i < 3; ++i) {
        camera.worldToLight[4 * i + 0] = rows[i][0];
        camera.worldToLight[4 * i + 1] = rows[i][1];
        camera.worldToLight[4 * i + 2] = rows[i][2];
        camera.worldToLight[4 * i + 3] = -dot(rows[i], eye);
    }
    camera.worldToLight[12] = camera.worldToLight[13] = camera.worldToLight[14] = 0.0;
    camera.worldToLight[15] = 1.0;
    camera.validate();
    return camera;
}

Curves generateHairBall(const HairBallParameters& h) {
    Curves curves;
    const std::uint32_t segments = std::max<std::uint32_t>(h.segments, 1);
    curves.pointsPerCurve.assign(h.count, segments + 1);
    curves.points.reserve(static_cast<std::size_t>(h.count) * (segments + 1));
    curves.widths = {static_cast<float>(h.width)};
    const double step = h.length / segments;
    auto toFloat = [](const Vec3& q) {
        return std::array<float, 3>{static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2])};
    };
    for (std::uint32_t i = 0; i < h.count; ++i) {
        // One independent stream per hair: hair i is the same whatever the count.
        SplitMix64 rng(mix64((static_cast<std::uint64_t>(h.seed) << 32) | i));
        const Vec3 normal = rng.unitVector();
        Vec3 point = add(h.center, mul(normal, h.radius));
        // Outwards, tilted by up to ~24 degrees.
        Vec3 direction = normalized(add(normal, mul(rng.unitVector(), 0.4)));
        // A unit vector perpendicular to the direction, from v (or a new random one).
        auto perpendicular = [&](Vec3 v) {
            for (;;) {
                const Vec3 w = sub(v, mul(direction, dot(v, direction)));
                if (length(w) > 1e-3) return normalized(w);
                v = rng.unitVector();
            }
        };
        Vec3 axis = perpendicular(rng.unitVector());
        curves.points.push_back(toFloat(point));
        for (std::uint32_t s = 0; s < segments; ++s) {
            // Turn about a slowly wandering axis by about curl * step radians.
            const double turn = h.curl * step * (0.5 + rng.uniform());
            axis = perpendicular(add(axis, mul(rng.unitVector(), 0.5)));
            direction = normalized(add(direction, mul(cross(axis, direction), turn)));
            point = add(point, mul(direction, step));
            curves.points.push_back(toFloat(point));
        }
    }
    return curves;
}

Curves loadHairFile(const std::string& path) {
    auto fail = [&](const std::string& m) -> void { throw Error("hair file '" + path + "': " + m); };
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) fail("does not exist or is not a file");
    std::ifstream in(path, std::ios::binary);
    if (!in) fail(std::string("cannot open: ") + std::strerror(errno));
    const std::vector<unsigned char> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    if (in.bad()) fail("read error");
    constexpr std::size_t kHeader = 128;
    if (bytes.size() < kHeader) fail(detail::concat("is ", bytes.size(), " bytes, shorter than the 128-byte header"));
    if (std::memcmp(bytes.data(), "HAIR", 4) != 0) fail("does not start with \"HAIR\"");
    const std::uint64_t hairCount = readU32(&bytes[4]);
    const std::uint64_t pointCount = readU32(&bytes[8]);
    const std::uint32_t flags = readU32(&bytes[12]);
    const std::uint32_t defaultSegments = readU32(&bytes[16]);
    const float defaultThickness = readF32(&bytes[20]);
    constexpr std::uint32_t kSegments = 1, kPoints = 2, kThickness = 4, kTransparency = 8, kColor = 16;
    if (flags & ~0x1Fu) fail(detail::concat("unknown array flags 0x", std::hex, flags));
    if (!(flags & kPoints)) fail("has no points array (flag bit 1 not set)");

    std::uint64_t expected = kHeader;
    if (flags & kSegments) expected += 2 * hairCount;
    expected += 12 * pointCount;
    if (flags & kThickness) expected += 4 * pointCount;
    if (flags & kTransparency) expected += 4 * pointCount;
    if (flags & kColor) expected += 12 * pointCount;
    if (bytes.size() != expected)
        fail(detail::concat("is ", bytes.size(), " bytes, but its header (", hairCount, " hairs, ", pointCount,
                            " points, flags 0x", std::hex, flags, std::dec, ") implies ", expected,
                            bytes.size() < expected ? " (truncated)" : ""));

    Curves curves;
    std::size_t offset = kHeader;
    curves.pointsPerCurve.resize(hairCount);
    std::uint64_t total = 0;
    for (std::uint64_t i = 0; i < hairCount; ++i) {
        std::uint32_t segments = defaultSegments;
        if (flags & kSegments) {
            segments = static_cast<std::uint32_t>(bytes[offset] | bytes[offset + 1] << 8);
            offset += 2;
        }
        if (segments == 0) fail(detail::concat("hair ", i, " has 0 segments"));
        curves.pointsPerCurve[i] = segments + 1;
        total += segments + 1ull;
    }
    if (total != pointCount)
        fail(detail::concat("the hairs' segments add up to ", total, " points but the header says ", pointCount));
    curves.points.resize(pointCount);
    for (std::uint64_t i = 0; i < pointCount; ++i, offset += 12) {
        curves.points[i] = {readF32(&bytes[offset]), readF32(&bytes[offset + 4]), readF32(&bytes[offset + 8])};
        for (float c : curves.points[i])
            if (!std::isfinite(c)) fail(detail::concat("point ", i, " is not finite"));
    }
    if (flags & kThickness) {
        curves.widths.resize(pointCount);
        for (std::uint64_t i = 0; i < pointCount; ++i, offset += 4) {
            curves.widths[i] = readF32(&bytes[offset]);
            if (!std::isfinite(curves.widths[i]) || curves.widths[i] < 0.0f)
                fail(detail::concat("thickness of point ", i, " is ", curves.widths[i]));
        }
    } else {
        if (!std::isfinite(defaultThickness) || !(defaultThickness > 0.0f))
            fail(detail::concat("default thickness ", defaultThickness, " is not > 0 and there is no thickness array"));
        curves.widths = {defaultThickness};
    }
    // Transparency and colour arrays are skipped: the scene's opacity applies.
    return curves;
}

Scene parseScene(const std::string& jsonText, const std::string& baseDirectory, const std::string& name) {
    const Parser p(name, baseDirectory);
    const json doc = parseJson(p, jsonText);
    p.requireObject(doc, "", "a JSON object {\"light\": ..., \"objects\": [...]} at the top level");
    p.checkKeys(doc, "", {"light", "objects"});
    Scene scene;
    scene.source = jsonText;
    scene.path = name;
    scene.light = parseLight(p, p.require(doc, "", "light"));
    const json& objects = p.require(doc, "", "objects");
    if (!objects.is_array()) p.expected("/objects", "an array of objects", objects);
    scene.objects.reserve(objects.size());
    for (std::size_t i = 0; i < objects.size(); ++i) scene.objects.push_back(parseObject(p, objects[i], i));
    return scene;
}

Scene loadScene(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec))
        throw Error("scene '" + path + "': does not exist or is not a file");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error("scene '" + path + "': cannot open: " + std::strerror(errno));
    const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    if (in.bad()) throw Error("scene '" + path + "': read error");
    return parseScene(text, std::filesystem::path(path).parent_path().string(), path);
}

DSM_NAMESPACE_END
