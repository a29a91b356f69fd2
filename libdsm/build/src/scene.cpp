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
#include <istream>
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
#include "splitmix64.h"
#include "text.h"
#include "vec3_math.h"

DSM_NAMESPACE_BEGIN
namespace {

using json = nlohmann::json;

constexpr double kPi = 3.14159265358979323846;
constexpr std::uint32_t kMaxResolution = 1u << 17;  // the reader's default limit

using detail::add;
using detail::cross;
using detail::dot;
using detail::length;
using detail::normalized;
using detail::scale;
using detail::sub;

// The ranges of spec/scene.md §1.1. They are far wider than any real scene
// needs and narrow enough that every sum, product and square the ray caster
// forms from them stays finite, and that float storage keeps them.
constexpr double kMaxCoordinate = 1e12;  // positions, points, lengths, translations
constexpr double kMinLength = 1e-12;     // the shortest positive length
constexpr double kMaxLinear = 1e6;       // scale factors, entries of a transform's 3x3 part
constexpr double kMinDeterminant = 1e-18;  // of a transform's 3x3 part: factors >= 1e-6
constexpr double kMaxAngle = 1e6;          // degrees
constexpr double kMaxDensity = 1e12;       // densities and extinction scales
constexpr double kMaxCurl = 1e6;           // radians per unit length
constexpr double kMaxFrequency = 1e6;      // noise features per unit length
constexpr double kMinFieldOfView = 1e-3;   // degrees
/// Samples a ray may take across one volume's box (its longest diagonal / step).
constexpr double kMaxVolumeSamples = 1e6;
constexpr std::uint64_t kMaxHairBallCount = 10'000'000;
constexpr std::uint64_t kMaxHairBallSegments = 1000;
constexpr std::uint64_t kMaxHairBallPoints = 100'000'000;

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

class SceneRandom : public detail::SplitMix64 {
public:
    using SplitMix64::SplitMix64;
    /// Uniform on the unit sphere, by rejection from the cube (no libm calls
    /// but sqrt, which IEEE 754 rounds exactly). A draw is accepted with
    /// probability ~0.52; the bound on draws (never reached: 0.48^1000) keeps
    /// the loop finite whatever the generator does.
    Vec3 unitVector() {
        for (int draw = 0; draw < kMaxDraws; ++draw) {
            const Vec3 v{2.0 * uniform() - 1.0, 2.0 * uniform() - 1.0, 2.0 * uniform() - 1.0};
            const double s = dot(v, v);
            if (s > 1e-6 && s <= 1.0) return scale(v, 1.0 / std::sqrt(s));
        }
        return {0.0, 0.0, 1.0};
    }

    static constexpr int kMaxDraws = 1000;
};

// ---------------------------------------------------------------------------
// JSON helpers. Every message names the scene and a JSON pointer.

// One token of a JSON pointer (RFC 6901: "~" is "~0", "/" is "~1"), clipped
// for messages.
std::string pointerToken(std::string_view key) {
    std::string token;
    for (const char c : key.substr(0, 2 * detail::kMaxQuotedChars)) {
        if (c == '~') token += "~0";
        else if (c == '/') token += "~1";
        else token += c;
    }
    return detail::clip(key.size() > 2 * detail::kMaxQuotedChars ? token + "..." : token);
}

// Appends a compact rendering of v (as json::dump writes it) to out, stopping
// soon after out passes `limit` characters: a 100 MB value costs no more than
// a short one.
void describeInto(const json& v, std::string& out, std::size_t limit) {
    if (v.is_string()) {
        out += json(detail::clip(v.get_ref<const std::string&>(), limit)).dump(-1, ' ', false,
                                                                               json::error_handler_t::replace);
    } else if (v.is_array() || v.is_object()) {
        out += v.is_array() ? '[' : '{';
        bool first = true;
        for (auto it = v.begin(); it != v.end(); ++it) {
            if (out.size() > limit) return;
            if (!first) out += ',';
            first = false;
            if (v.is_object()) out += json(detail::clip(it.key(), limit)).dump(-1, ' ', false,
                                                                             json::error_handler_t::replace) + ":";
            describeInto(*it, out, limit);  // depth is bounded by kMaxSceneNesting
        }
        out += v.is_array() ? ']' : '}';
    } else {
        out += v.dump();
    }
}

std::string describe(const json& v) {
    std::string s;
    describeInto(v, s, detail::kMaxQuotedChars);
    return detail::clip(s);
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
const Range kCoordinate{-kMaxCoordinate, kMaxCoordinate};
const Range kLength{kMinLength, kMaxCoordinate};
const Range kNonNegativeLength{0.0, kMaxCoordinate};
const Range kUnit{0.0, 1.0};
const Range kDensityRange{0.0, kMaxDensity};
const Range kAngle{-kMaxAngle, kMaxAngle};
const Range kLinear{-kMaxLinear, kMaxLinear};
const Range kCurl{0.0, kMaxCurl};
const Range kFrequency{kMinLength, kMaxFrequency};
const Range kFieldOfView{kMinFieldOfView, 180.0, false, true};

std::string inText(const Range& range) {
    const std::string t = range.text();
    return (t[0] == '[' || t[0] == '(') ? "in " + t : t;
}

class Parser {
public:
    Parser(std::string name, std::string baseDirectory, std::uint64_t maxHairPoints)
        : name_(std::move(name)), base_(std::move(baseDirectory)), maxHairPoints_(maxHairPoints) {}

    /// Counts `points` more generated hair points against
    /// SceneReadOptions::maxHairPoints before they are generated.
    void addHairPoints(const std::string& path, std::uint64_t points) const {
        if (points > maxHairPoints_ - std::min(hairPoints_, maxHairPoints_))
            fail(path, detail::concat(points, " hair points would bring the scene's hair balls to ",
                                      hairPoints_ + points, ", more than the limit of ", maxHairPoints_),
                 ErrorCode::limit);
        hairPoints_ += points;
    }

    [[noreturn]] void fail(const std::string& path, const std::string& message,
                           ErrorCode code = ErrorCode::scene) const {
        // A pointer through 64 levels of long keys could still be long: it
        // is cut like any other quoted text.
        throw Error(code, detail::concat(
                              "scene '", detail::clip(name_, detail::kMaxQuotedPath),
                              "': ", path.empty() ? std::string() : detail::clip(path, detail::kMaxQuotedPath) + ": ",
                              message),
                    name_);
    }
    [[noreturn]] void expected(const std::string& path, const std::string& what, const json& got) const {
        fail(path, "expected " + what + ", got " + describe(got));
    }

    /// The path of a file the scene names, recorded in files().
    std::string resolve(const std::string& file) const {
        const std::filesystem::path p(file);
        std::string resolved = p.is_absolute() || base_.empty() ? p.lexically_normal().string()
                                                                : (std::filesystem::path(base_) / p).lexically_normal().string();
        files_.push_back(resolved);
        return resolved;
    }
    const std::vector<std::string>& files() const { return files_; }

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
            fail(path + "/" + pointerToken(key),
                 "unknown key \"" + detail::clip(key) + "\"" + context + " (allowed here: " + list + ")");
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

    double number(const json& v, const std::string& path, const Range& range) const {
        const std::string what = "a number " + inText(range);
        if (!v.is_number()) expected(path, what, v);
        const double x = v.get<double>();
        if (!std::isfinite(x) || !range.contains(x)) expected(path, what, v);
        return x;
    }
    double number(const json& object, const std::string& path, const char* key, double fallback,
                  const Range& range) const {
        const json* v = find(object, key);
        return v ? number(*v, path + "/" + key, range) : fallback;
    }
    double requiredNumber(const json& object, const std::string& path, const char* key, const Range& range) const {
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

    Vec3 vec3(const json& v, const std::string& path, const Range& range = kCoordinate) const {
        const std::string what = "[x, y, z] (3 numbers " + inText(range) + ")";
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
    /// A direction or half-axis: coordinates in range and a length of at least
    /// kMinLength, so that normalising it is exact enough and finite.
    Vec3 nonZeroVec3(const json& v, const std::string& path) const {
        const Vec3 out = vec3(v, path);
        if (!(length(out) >= kMinLength))
            expected(path, "a non-zero vector [x, y, z] (length >= " + formatNumber(kMinLength) + ")", v);
        return out;
    }

    /// An array of [x, y, z] points, stored as floats.
    std::vector<std::array<float, 3>> points(const json& v, const std::string& path) const {
        if (!v.is_array()) expected(path, "an array of [x, y, z] points", v);
        std::vector<std::array<float, 3>> out;
        out.reserve(v.size());
        for (std::size_t i = 0; i < v.size(); ++i) {
            const Vec3 p = vec3(v[i], detail::concat(path, "/", i));
            out.push_back({static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])});
        }
        return out;
    }

    const std::string& name() const { return name_; }

private:
    std::string name_;
    std::string base_;
    std::uint64_t maxHairPoints_;
    /// Points the hair balls parsed so far generate (the parser is const).
    mutable std::uint64_t hairPoints_ = 0;
    /// Every file the scene names, as resolved (the parser is const).
    mutable std::vector<std::string> files_;
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
        light.fieldOfViewDegrees = p.number(v, path, "fov", 45.0, kFieldOfView);
        light.areaLightRadius = p.number(v, path, "area_radius", 0.0, kNonNegativeLength);
    } else {
        light.extent = p.requiredNumber(v, path, "extent", kLength);
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
    light.nearPlane = p.number(v, path, "near", 0.0, kNonNegativeLength);
    // The ranges above keep the camera finite; this catches what they miss.
    try {
        lightCamera(light);
    } catch (const Error& e) {
        p.fail(path, e.what());
    }
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
            const double x = p.number(*sv, spath, kLinear);
            f = {x, x, x};
        } else {
            f = p.vec3(*sv, spath, kLinear);
        }
        const double smallest = std::min({std::abs(f[0]), std::abs(f[1]), std::abs(f[2])});
        if (!(smallest >= 1.0 / kMaxLinear))
            p.expected(spath,
                       "scale factors with magnitudes in [" + formatNumber(1.0 / kMaxLinear) + ", " +
                           formatNumber(kMaxLinear) + "] (negative factors mirror)",
                       *sv);
        s[0] = f[0];
        s[5] = f[1];
        s[10] = f[2];
    }
    if (const json* rv = Parser::find(v, "rotate")) {
        const std::string rpath = path + "/rotate";
        p.requireObject(*rv, rpath, "{\"axis\": [x, y, z], \"angle\": degrees}");
        p.checkKeys(*rv, rpath, {"axis", "angle"});
        const Vec3 axis = p.nonZeroVec3(p.require(*rv, rpath, "axis"), rpath + "/axis");
        const double angle = p.requiredNumber(*rv, rpath, "angle", kAngle);
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

// The bounds of spec/scene.md §4.3 on a whole transform: the 3x3 part's
// entries and determinant and the translation, so that objects, their
// inverse transforms and the world stay finite.
void checkTransform(const Parser& p, const Mat4& m, const std::string& path) {
    for (std::size_t r = 0; r < 3; ++r) {
        for (std::size_t c = 0; c < 3; ++c)
            if (!(std::abs(m[4 * r + c]) <= kMaxLinear))
                p.fail(path, detail::concat("the transform's 3x3 part has an entry ", m[4 * r + c], " beyond +-",
                                            kMaxLinear));
        if (!(std::abs(m[4 * r + 3]) <= kMaxCoordinate))
            p.fail(path, detail::concat("the transform translates by ", m[4 * r + 3], ", beyond +-", kMaxCoordinate));
    }
    const double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                       m[2] * (m[4] * m[9] - m[5] * m[8]);
    if (!(std::abs(det) >= kMinDeterminant))
        p.fail(path, detail::concat("the transform is singular or nearly so (the determinant of its 3x3 part is ",
                                    detail::exactNumber(det), "; at least ", kMinDeterminant,
                                    " in magnitude is needed)"));
}

Mat4 parseTransform(const Parser& p, const json& v, const std::string& path) {
    const char* what =
        "16 numbers (a row-major matrix), a {\"scale\", \"rotate\", \"translate\"} object or an array of them";
    Mat4 m = kIdentity;
    if (v.is_object()) {
        m = parseTrs(p, v, path);
    } else if (!v.is_array()) {
        p.expected(path, what, v);
    } else if (!v.empty() && v[0].is_number()) {
        if (v.size() != 16) p.expected(path, what, v);
        for (std::size_t i = 0; i < 16; ++i)
            m[i] = p.number(v[i], detail::concat(path, "/", i), i % 4 == 3 ? kCoordinate : kLinear);
        if (m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || m[15] != 1.0)
            p.fail(path, "the last row must be [0, 0, 0, 1] (affine transforms only)");
    } else {
        for (std::size_t i = 0; i < v.size(); ++i) m = multiply(parseTrs(p, v[i], detail::concat(path, "/", i)), m);
    }
    checkTransform(p, m, path);
    return m;
}

// ---------------------------------------------------------------------------
// Geometry.

TriangleMesh loadObj(const Parser& p, const std::string& file, const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec))
        p.fail(path, "OBJ file '" + detail::clip(file, detail::kMaxQuotedPath) + "' does not exist or is not a file");
    tinyobj::ObjReaderConfig config;
    config.triangulate = true;
    config.vertex_color = false;
    config.mtl_search_path = std::filesystem::path(file).parent_path().string();
    tinyobj::ObjReader reader;
    if (!reader.ParseFromFile(file, config)) {
        std::string message = reader.Error();
        while (!message.empty() && (message.back() == '\n' || message.back() == '\r')) message.pop_back();
        std::replace(message.begin(), message.end(), '\n', ' ');
        p.fail(path,
               "cannot read OBJ file '" + detail::clip(file, detail::kMaxQuotedPath) + "': " + detail::clip(message));
    }
    const auto& attrib = reader.GetAttrib();
    TriangleMesh mesh;
    const std::size_t vertexCount = attrib.vertices.size() / 3;
    mesh.positions.reserve(vertexCount);
    for (std::size_t i = 0; i < vertexCount; ++i) {
        const std::array<float, 3> q{attrib.vertices[3 * i], attrib.vertices[3 * i + 1], attrib.vertices[3 * i + 2]};
        for (const float c : q)
            if (!kCoordinate.contains(c))
                p.fail(path,
                       detail::concat("OBJ file '", detail::clip(file, detail::kMaxQuotedPath), "': vertex ", i + 1,
                                      " has a coordinate ", c, " that is not finite or not ", inText(kCoordinate)));
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
                        p.fail(path, detail::concat("OBJ file '", detail::clip(file, detail::kMaxQuotedPath),
                                                    "': shape '", detail::clip(shape.name), "' face ", f,
                                                    " refers to vertex ", index + 1, " of ", vertexCount));
                    t[k] = static_cast<std::uint32_t>(index);
                }
                mesh.triangles.push_back(t);
            }
            offset += n;
        }
    }
    if (mesh.triangles.empty())
        p.fail(path, "OBJ file '" + detail::clip(file, detail::kMaxQuotedPath) + "' has no faces");
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
        su = sv = p.number(size, path + "/size", kLength);
    } else if (size.is_array() && size.size() == 2) {
        su = p.number(size[0], path + "/size/0", kLength);
        sv = p.number(size[1], path + "/size/1", kLength);
    } else {
        p.expected(path + "/size", "a side length " + inText(kLength) + " or [u, v] side lengths", size);
    }
    const Vec3 a = std::abs(n[1]) < 0.9 ? Vec3{0.0, 1.0, 0.0} : Vec3{1.0, 0.0, 0.0};
    const Vec3 u = normalized(cross(a, n));
    const Vec3 w = cross(n, u);
    q.halfU = scale(u, 0.5 * su);
    q.halfV = scale(w, 0.5 * sv);
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
            p.fail(fpath, e.what(), e.code());
        }
        if (Parser::find(v, "width"))
            curves.widths = {static_cast<float>(p.number(v["width"], path + "/width", kLength))};
        return curves;
    }
    if (Parser::find(v, "width"))
        p.fail(path + "/width", "applies only to hair files (a hair ball has its own \"width\")");
    const std::string bpath = path + "/hairball";
    p.requireObject(*ball, bpath, "an object");
    p.checkKeys(*ball, bpath, {"center", "radius", "count", "length", "curl", "width", "segments", "seed"});
    HairBallParameters h;
    h.center = p.vec3(*ball, bpath, "center", h.center);
    h.radius = p.number(*ball, bpath, "radius", h.radius, kLength);
    h.count = narrowU32(p.integer(*ball, bpath, "count", h.count, 1, kMaxHairBallCount));
    h.length = p.number(*ball, bpath, "length", h.length, kLength);
    h.curl = p.number(*ball, bpath, "curl", h.curl, kCurl);
    h.width = p.number(*ball, bpath, "width", h.width, kLength);
    h.segments = narrowU32(p.integer(*ball, bpath, "segments", h.segments, 1, kMaxHairBallSegments));
    h.seed = narrowU32(p.integer(*ball, bpath, "seed", h.seed, 0, 0xFFFFFFFFull));
    if (static_cast<std::uint64_t>(h.count) * (h.segments + 1ull) > kMaxHairBallPoints)
        p.fail(bpath, detail::concat("count * (segments + 1) exceeds ", kMaxHairBallPoints, " points"),
               ErrorCode::limit);
    p.addHairPoints(bpath, static_cast<std::uint64_t>(h.count) * (h.segments + 1ull));
    try {
        return generateHairBall(h);
    } catch (const Error& e) {
        p.fail(bpath, e.what());  // the checks above make this unreachable
    }
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
        c.widths = {static_cast<float>(p.number(w, wpath, kLength))};
    } else if (w.is_array()) {
        if (w.size() != total)
            p.expected(wpath,
                       detail::concat("one width ", inText(kLength), " or an array of ", total, " (one per point)"), w);
        c.widths.clear();
        for (std::size_t i = 0; i < w.size(); ++i)
            c.widths.push_back(static_cast<float>(p.number(w[i], detail::concat(wpath, "/", i), kLength)));
    } else {
        p.expected(wpath, "a width " + inText(kLength) + " or an array of widths (one per point)", w);
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
        vol.density = HomogeneousDensity{p.requiredNumber(d, dpath, "value", kDensityRange)};
    } else if (type == "noise") {
        p.checkKeys(d, dpath, {"type", "density", "frequency", "octaves", "seed", "falloff"});
        NoiseCloudDensity n;
        n.density = p.number(d, dpath, "density", n.density, kDensityRange);
        n.frequency = p.number(d, dpath, "frequency", n.frequency, kFrequency);
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
            p.fail(dpath + "/file",
                   "VDB file '" + detail::clip(g.file, detail::kMaxQuotedPath) + "' does not exist or is not a file");
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
            p.fail(dpath + "/file", e.what(), e.code());
        }
        for (std::size_t i = 0; i < 3; ++i)
            if (!kCoordinate.contains(vol.boundsMin[i]) || !kCoordinate.contains(vol.boundsMax[i]))
                p.fail(dpath + "/file", detail::concat("the grid's bounds on axis ", i, ", [", vol.boundsMin[i], ", ",
                                                       vol.boundsMax[i], "], are not ", inText(kCoordinate),
                                                       "; give \"bounds\""));
    } else {
        p.fail(path, "missing required key \"bounds\"");
    }
    vol.scale = p.number(v, path, "scale", 1.0, kDensityRange);
    double shortest = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < 3; ++i) shortest = std::min(shortest, vol.boundsMax[i] - vol.boundsMin[i]);
    vol.step = p.number(v, path, "step", shortest / 64.0, kLength);
    return vol;
}

// Bounds the samples a ray takes across the volume's box: the longest chord
// of the transformed box is one of its four diagonals (|sum s_i e_i| is convex
// in s, so it is largest at a corner of [-1, 1]^3).
void checkVolumeSamples(const Parser& p, const Volume& volume, const Mat4& objectToWorld, const json& v,
                        const std::string& path) {
    const Vec3 e = sub(volume.boundsMax, volume.boundsMin);
    double diameter = 0.0;
    for (const double sy : {-1.0, 1.0})
        for (const double sz : {-1.0, 1.0}) {
            const Vec3 d{e[0], sy * e[1], sz * e[2]};
            Vec3 w{};
            for (std::size_t r = 0; r < 3; ++r)
                w[r] = objectToWorld[4 * r] * d[0] + objectToWorld[4 * r + 1] * d[1] + objectToWorld[4 * r + 2] * d[2];
            diameter = std::max(diameter, length(w));
        }
    const double samples = diameter / volume.step;
    if (samples <= kMaxVolumeSamples) return;
    const bool given = Parser::find(v, "step") != nullptr;
    p.fail(given ? path + "/step" : path,
           detail::concat(given ? "a step of " : "the default step (shortest side / 64) of ", volume.step, " takes ",
                          std::ceil(samples), " samples across the volume's box (", diameter,
                          " world units across); at most ", kMaxVolumeSamples, " are allowed: ",
                          given ? "raise the step" : "give a larger \"step\""),
           ErrorCode::limit);
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
        s.radius = p.requiredNumber(v, path, "radius", kLength);
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
    if (const auto* volume = std::get_if<Volume>(&o.geometry)) checkVolumeSamples(p, *volume, o.objectToWorld, v, path);
    return o;
}

// Parses JSON text, following where the parser is as a JSON pointer so that
// every failure names its place: a syntax error, a number beyond the double
// range (1e400), a key that appears twice in one object (nlohmann keeps the
// last one silently, which hides typos and merge accidents), and nesting
// deeper than kMaxSceneNesting. The depth is checked as each array or object
// opens: nlohmann's parser and destructor do not recurse, but everything that
// walks the document afterwards (dump, comparisons, the checks here) does.
json parseJson(const Parser& p, const std::string& text) {
    struct Level {
        bool isArray = false;
        std::size_t index = 0;  // arrays: the element being read
        std::string key;        // objects: the key whose value is being read
        bool inMember = false;  // objects: between a key and the end of its value
        std::set<std::string> keys;
    };
    std::vector<Level> levels;
    auto pointer = [&] {
        std::string out;
        for (const Level& level : levels) {
            if (!level.isArray && !level.inMember) continue;
            out += '/';
            out += level.isArray ? std::to_string(level.index) : pointerToken(level.key);
        }
        return out;
    };
    auto elementDone = [&] {
        if (levels.empty()) return;
        if (levels.back().isArray) ++levels.back().index;
        else levels.back().inMember = false;
    };
    const json::parser_callback_t callback = [&](int, json::parse_event_t event, json& parsed) {
        switch (event) {
            case json::parse_event_t::object_start:
            case json::parse_event_t::array_start:
                if (levels.size() >= kMaxSceneNesting)
                    p.fail(pointer(), detail::concat("nested deeper than ", kMaxSceneNesting, " levels"),
                           ErrorCode::limit);
                levels.push_back({event == json::parse_event_t::array_start, 0, {}, false, {}});
                break;
            case json::parse_event_t::object_end:
            case json::parse_event_t::array_end:
                if (!levels.empty()) levels.pop_back();
                elementDone();
                break;
            case json::parse_event_t::key:
                if (!levels.empty()) {
                    Level& level = levels.back();
                    level.key = parsed.get<std::string>();
                    level.inMember = true;
                    if (!level.keys.insert(level.key).second)
                        p.fail(pointer(), "key \"" + detail::clip(level.key) + "\" appears twice in one object");
                }
                break;
            case json::parse_event_t::value: elementDone(); break;
        }
        return true;
    };
    try {
        return json::parse(text, callback);
    } catch (const json::exception& e) {
        // "[json.exception.parse_error.101] parse error at line 1, ...": keep
        // what follows the bracket; the lexer may quote a long token.
        std::string message = e.what();
        const auto close = message.find("] ");
        if (message.rfind("[json.exception", 0) == 0 && close != std::string::npos) message = message.substr(close + 2);
        p.fail(pointer(), "invalid JSON: " + detail::clip(message, 2 * detail::kMaxQuotedChars));
    }
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
    auto fail = [](const std::string& m) -> void { throw Error(ErrorCode::argument, "light: " + m); };
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
            eye = sub(eye, scale(f, d));
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
    // The ranges of spec/scene.md §5.5 keep every direction finite (a turn of
    // curl * length / segments at most 1e18 radians, squared 1e36).
    auto check = [](const char* name, double value, const Range& range) {
        if (!std::isfinite(value) || !range.contains(value))
            throw Error(ErrorCode::argument,
                        detail::concat("hair ball: ", name, " ", value, " is not ", inText(range)));
    };
    for (const double c : h.center) check("centre coordinate", c, kCoordinate);
    check("radius", h.radius, kLength);
    check("length", h.length, kLength);
    check("curl", h.curl, kCurl);
    check("width", h.width, kLength);
    check("count", h.count, Range{1.0, static_cast<double>(kMaxHairBallCount)});
    check("segments", h.segments, Range{1.0, static_cast<double>(kMaxHairBallSegments)});
    if (static_cast<std::uint64_t>(h.count) * (h.segments + 1ull) > kMaxHairBallPoints)
        throw Error(ErrorCode::limit, detail::concat("hair ball: count * (segments + 1) exceeds ", kMaxHairBallPoints,
                                                     " points"));

    Curves curves;
    const std::uint32_t segments = h.segments;
    curves.pointsPerCurve.assign(h.count, segments + 1);
    curves.points.reserve(static_cast<std::size_t>(h.count) * (segments + 1));
    curves.widths = {static_cast<float>(h.width)};
    const double step = h.length / segments;
    auto toFloat = [](const Vec3& q) {
        return std::array<float, 3>{static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2])};
    };
    for (std::uint32_t i = 0; i < h.count; ++i) {
        // One independent stream per hair: hair i is the same whatever the count.
        SceneRandom rng(detail::mix64((static_cast<std::uint64_t>(h.seed) << 32) | i));
        const Vec3 normal = rng.unitVector();
        Vec3 point = add(h.center, scale(normal, h.radius));
        // Outwards, tilted by up to ~24 degrees.
        Vec3 direction = normalized(add(normal, scale(rng.unitVector(), 0.4)));
        // A unit vector perpendicular to the direction, from v (or new random
        // ones). A random unit vector lies within 1e-3 of +-direction with
        // probability ~5e-7, so the fallback after kMaxDraws draws (the
        // coordinate axis least aligned with the direction) is never reached
        // in practice; it only keeps the loop finite.
        auto perpendicular = [&](Vec3 v) {
            for (int draw = 0; draw < SceneRandom::kMaxDraws; ++draw) {
                const Vec3 w = sub(v, scale(direction, dot(v, direction)));
                if (length(w) > 1e-3) return normalized(w);
                v = rng.unitVector();
            }
            std::size_t least = 0;
            for (std::size_t k = 1; k < 3; ++k)
                if (std::abs(direction[k]) < std::abs(direction[least])) least = k;
            Vec3 e{0.0, 0.0, 0.0};
            e[least] = 1.0;
            return normalized(sub(e, scale(direction, dot(e, direction))));
        };
        Vec3 axis = perpendicular(rng.unitVector());
        curves.points.push_back(toFloat(point));
        for (std::uint32_t s = 0; s < segments; ++s) {
            // Turn about a slowly wandering axis by about curl * step radians.
            const double turn = h.curl * step * (0.5 + rng.uniform());
            axis = perpendicular(add(axis, scale(rng.unitVector(), 0.5)));
            direction = normalized(add(direction, scale(cross(axis, direction), turn)));
            point = add(point, scale(direction, step));
            curves.points.push_back(toFloat(point));
        }
    }
    return curves;
}

Curves loadHairFile(const std::string& path) {
    auto fail = [&](ErrorCode code, const std::string& m) -> void {
        throw Error(code, "hair file '" + detail::clip(path, detail::kMaxQuotedPath) + "': " + m, path);
    };
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) fail(ErrorCode::io, "does not exist or is not a file");
    const std::uint64_t fileBytes = std::filesystem::file_size(path, ec);
    if (ec) fail(ErrorCode::io, "cannot read its size: " + ec.message());
    std::ifstream in(path, std::ios::binary);
    if (!in) fail(ErrorCode::io, std::string("cannot open: ") + std::strerror(errno));
    constexpr std::size_t kHeader = 128;
    if (fileBytes < kHeader)
        fail(ErrorCode::corrupt, detail::concat("is ", fileBytes, " bytes, shorter than the 128-byte header"));
    std::vector<unsigned char> bytes(kHeader);
    if (!in.read(reinterpret_cast<char*>(bytes.data()), kHeader)) fail(ErrorCode::io, "read error in the header");
    if (std::memcmp(bytes.data(), "HAIR", 4) != 0) fail(ErrorCode::format, "does not start with \"HAIR\"");
    const std::uint64_t hairCount = readU32(&bytes[4]);
    const std::uint64_t pointCount = readU32(&bytes[8]);
    const std::uint32_t flags = readU32(&bytes[12]);
    const std::uint32_t defaultSegments = readU32(&bytes[16]);
    const float defaultThickness = readF32(&bytes[20]);
    constexpr std::uint32_t kSegments = 1, kPoints = 2, kThickness = 4, kTransparency = 8, kColor = 16;
    if (flags & ~0x1Fu) fail(ErrorCode::corrupt, detail::concat("unknown array flags 0x", std::hex, flags));
    if (!(flags & kPoints)) fail(ErrorCode::corrupt, "has no points array (flag bit 1 not set)");
    // Sizes come from the header: check them against the file and the limit
    // before allocating anything they ask for.
    if (pointCount > kMaxHairBallPoints)
        fail(ErrorCode::limit, detail::concat("has ", pointCount, " points, more than the limit of ",
                                              kMaxHairBallPoints));

    std::uint64_t expected = kHeader;
    if (flags & kSegments) expected += 2 * hairCount;
    expected += 12 * pointCount;
    if (flags & kThickness) expected += 4 * pointCount;
    if (flags & kTransparency) expected += 4 * pointCount;
    if (flags & kColor) expected += 12 * pointCount;
    if (fileBytes != expected)
        fail(ErrorCode::corrupt,
             detail::concat("is ", fileBytes, " bytes, but its header (", hairCount, " hairs, ", pointCount,
                            " points, flags 0x", std::hex, flags, std::dec, ") implies ", expected,
                            fileBytes < expected ? " (truncated)" : ""));
    if (2 * hairCount > pointCount)
        fail(ErrorCode::corrupt, detail::concat("has ", hairCount, " hairs but only ", pointCount,
                                                " points (every hair has at least 2)"));
    bytes.resize(expected);
    if (!in.read(reinterpret_cast<char*>(bytes.data() + kHeader), static_cast<std::streamsize>(expected - kHeader)))
        fail(ErrorCode::io, "read error (the file shrank while being read?)");

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
        if (segments == 0) fail(ErrorCode::corrupt, detail::concat("hair ", i, " has 0 segments"));
        curves.pointsPerCurve[i] = segments + 1;
        total += segments + 1ull;
    }
    if (total != pointCount)
        fail(ErrorCode::corrupt,
             detail::concat("the hairs' segments add up to ", total, " points but the header says ", pointCount));
    curves.points.resize(pointCount);
    for (std::uint64_t i = 0; i < pointCount; ++i, offset += 12) {
        curves.points[i] = {readF32(&bytes[offset]), readF32(&bytes[offset + 4]), readF32(&bytes[offset + 8])};
        for (float c : curves.points[i])
            if (!kCoordinate.contains(c))
                fail(ErrorCode::corrupt, detail::concat("point ", i, " has a coordinate ", c,
                                                        " that is not finite or not ", inText(kCoordinate)));
    }
    if (flags & kThickness) {
        curves.widths.resize(pointCount);
        for (std::uint64_t i = 0; i < pointCount; ++i, offset += 4) {
            curves.widths[i] = readF32(&bytes[offset]);
            if (!kNonNegativeLength.contains(curves.widths[i]))
                fail(ErrorCode::corrupt, detail::concat("thickness of point ", i, " is ", curves.widths[i],
                                                        ", not ", inText(kNonNegativeLength)));
        }
    } else {
        if (!kLength.contains(defaultThickness))
            fail(ErrorCode::corrupt, detail::concat("default thickness ", defaultThickness, " is not ", inText(kLength),
                                                    " and there is no thickness array"));
        curves.widths = {defaultThickness};
    }
    // Transparency and colour arrays are skipped: the scene's opacity applies.
    return curves;
}

Scene parseScene(const std::string& jsonText, const std::string& baseDirectory, const std::string& name,
                 const SceneReadOptions& options) {
    const Parser p(name, baseDirectory, options.maxHairPoints);
    if (jsonText.size() > options.maxBytes)
        p.fail("", detail::concat("is ", jsonText.size(), " bytes, more than the limit of ", options.maxBytes),
               ErrorCode::limit);
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
    scene.files = p.files();
    return scene;
}

Scene readScene(std::istream& in, const std::string& baseDirectory, const std::string& name,
                const SceneReadOptions& options) {
    const std::string where = "scene '" + detail::clip(name, detail::kMaxQuotedPath) + "'";
    std::string text;
    std::vector<char> buffer(1 << 16);
    while (in) {
        in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
        const auto got = static_cast<std::size_t>(in.gcount());
        if (got > options.maxBytes - std::min<std::uint64_t>(text.size(), options.maxBytes))
            throw Error(ErrorCode::limit,
                        detail::concat(where, ": is more than the limit of ", options.maxBytes, " bytes"), name);
        text.append(buffer.data(), got);
    }
    if (in.bad()) throw Error(ErrorCode::io, where + ": read error", name);
    return parseScene(text, baseDirectory, name, options);
}

Scene loadScene(const std::string& path, const SceneReadOptions& options) {
    const std::string where = "scene '" + detail::clip(path, detail::kMaxQuotedPath) + "'";
    std::error_code ec;
    // Not opened unless it is a regular file: opening a FIFO would block.
    if (!std::filesystem::is_regular_file(path, ec))
        throw Error(ErrorCode::io, where + ": does not exist or is not a file", path);
    const std::uint64_t size = std::filesystem::file_size(path, ec);
    if (!ec && size > options.maxBytes)
        throw Error(ErrorCode::limit,
                    detail::concat(where, ": is ", size, " bytes, more than the limit of ", options.maxBytes), path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(ErrorCode::io, where + ": cannot open: " + std::strerror(errno), path);
    return readScene(in, std::filesystem::path(path).parent_path().string(), path, options);
}

DSM_NAMESPACE_END
