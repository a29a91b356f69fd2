// Scene files (spec/scene.md): every light and object type, the light camera,
// error messages with JSON paths, OBJ and .hair files, hair balls, density
// fields (noise and an OpenVDB round trip) and the shipped examples.
#include <gtest/gtest.h>

#include <dsm/error.h>
#include <dsm/scene.h>

#if DSM_WITH_OPENVDB
#include <openvdb/openvdb.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <ios>
#include <string>
#include <variant>
#include <vector>

#include "density.h"
#include "temp_dir.h"

namespace {

using dsm::Vec3;

constexpr double kPi = 3.14159265358979323846;

dsm::Scene parse(const std::string& json, const std::string& base = "") {
    return dsm::parseScene(json, base, "test.json");
}

// A scene with the given light and objects.
std::string sceneText(const std::string& objects,
                      const std::string& light = R"({"type": "spot", "position": [0, 0, 0], "direction": [0, 0, 1]})") {
    return R"({"light": )" + light + R"(, "objects": [)" + objects + "]}";
}

const dsm::SceneObject& only(const dsm::Scene& s) {
    EXPECT_EQ(s.objects.size(), 1u);
    return s.objects.at(0);
}

// The message of the dsm::Error that parsing `json` throws ("" if none).
std::string parseError(const std::string& json, const std::string& base = "") {
    try {
        parse(json, base);
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "";
}

#define EXPECT_CONTAINS(haystack, needle)                                                               \
    do {                                                                                                \
        const std::string h_ = (haystack);                                                              \
        EXPECT_NE(h_.find(needle), std::string::npos) << "message: " << h_ << "\nwanted: " << (needle); \
    } while (0)

Vec3 apply(const std::array<double, 16>& m, const Vec3& p) {
    Vec3 out{};
    for (std::size_t r = 0; r < 3; ++r)
        out[r] = m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3];
    return out;
}

void expectNear(const Vec3& a, const Vec3& b, double tolerance = 1e-9) {
    for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(a[i], b[i], tolerance) << "component " << i;
}

// Raster position and depth of a world point.
struct Raster {
    bool ok;
    double x, y, z;
};
Raster toRaster(const dsm::LightCamera& c, const dsm::LightDescription& l, const Vec3& world) {
    Raster r{};
    r.ok = c.lightToRaster(c.worldToLightSpace(world), static_cast<int>(l.width), static_cast<int>(l.height), r.x, r.y,
                           r.z);
    return r;
}

void writeFile(const std::filesystem::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary);
    out << text;
}

// --- .hair files, written here from the layout in spec/scene.md -----------

void putU32(std::vector<unsigned char>& b, std::size_t at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<unsigned char>(v >> (8 * i));
}
void appendU32(std::vector<unsigned char>& b, std::uint32_t v) {
    b.resize(b.size() + 4);
    putU32(b, b.size() - 4, v);
}
void appendF32(std::vector<unsigned char>& b, float f) {
    std::uint32_t bits;
    std::memcpy(&bits, &f, 4);
    appendU32(b, bits);
}

struct HairSpec {
    std::vector<std::uint16_t> segments;  // empty: no segments array
    std::uint32_t defaultSegments = 0;
    std::vector<std::array<float, 3>> points;
    std::vector<float> thickness;  // empty: no thickness array
    float defaultThickness = 0.0f;
    bool transparencyAndColour = false;
    std::uint32_t hairCount = 0;
};

std::vector<unsigned char> hairBytes(const HairSpec& h) {
    std::vector<unsigned char> b(128, 0);
    std::memcpy(b.data(), "HAIR", 4);
    putU32(b, 4, h.hairCount);
    putU32(b, 8, static_cast<std::uint32_t>(h.points.size()));
    std::uint32_t flags = 2;
    if (!h.segments.empty()) flags |= 1;
    if (!h.thickness.empty()) flags |= 4;
    if (h.transparencyAndColour) flags |= 8 | 16;
    putU32(b, 12, flags);
    putU32(b, 16, h.defaultSegments);
    float f = h.defaultThickness;
    std::memcpy(&b[20], &f, 4);
    const char info[] = "written by test_scene";
    std::memcpy(&b[40], info, sizeof info);
    for (std::uint16_t s : h.segments) {
        b.push_back(static_cast<unsigned char>(s & 0xFF));
        b.push_back(static_cast<unsigned char>(s >> 8));
    }
    for (const auto& p : h.points)
        for (float c : p) appendF32(b, c);
    for (float t : h.thickness) appendF32(b, t);
    if (h.transparencyAndColour) {
        for (std::size_t i = 0; i < h.points.size(); ++i) appendF32(b, 0.5f);
        for (std::size_t i = 0; i < 3 * h.points.size(); ++i) appendF32(b, 0.25f);
    }
    return b;
}

void writeBytes(const std::filesystem::path& path, const std::vector<unsigned char>& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

std::string hairError(const std::string& path) {
    try {
        dsm::loadHairFile(path);
    } catch (const dsm::Error& e) {
        return e.what();
    }
    return "";
}

}  // namespace

// ---------------------------------------------------------------------------
// Lights and the light camera.

TEST(SceneLight, SpotDefaultsAndLookAt) {
    const auto s = parse(sceneText("", R"({"type": "spot", "position": [1, 2, 3], "look_at": [1, 2, 13]})"));
    const auto& l = s.light;
    EXPECT_EQ(l.projection, dsm::Projection::Perspective);
    expectNear(l.position, {1, 2, 3});
    expectNear(l.direction, {0, 0, 1});
    expectNear(l.up, {0, 1, 0});
    EXPECT_EQ(l.fieldOfViewDegrees, 45.0);
    EXPECT_EQ(l.width, 512u);
    EXPECT_EQ(l.height, 512u);
    EXPECT_EQ(l.nearPlane, 0.0);
    EXPECT_EQ(l.areaLightRadius, 0.0);
    EXPECT_TRUE(s.objects.empty());
    EXPECT_EQ(s.path, "test.json");
    EXPECT_FALSE(s.source.empty());
}

TEST(SceneLight, SpotAllFields) {
    const auto s = parse(sceneText("", R"({"type": "spot", "position": [0, 5, 0], "direction": [0, -2, 0],
        "up": [0, 0, 3], "fov": 60, "resolution": [640, 480], "near": 0.5, "area_radius": 0.25})"));
    const auto& l = s.light;
    expectNear(l.direction, {0, -1, 0});
    expectNear(l.up, {0, 0, 1});
    EXPECT_EQ(l.fieldOfViewDegrees, 60.0);
    EXPECT_EQ(l.width, 640u);
    EXPECT_EQ(l.height, 480u);
    EXPECT_EQ(l.nearPlane, 0.5);
    EXPECT_EQ(l.areaLightRadius, 0.25);
    const auto one =
        parse(sceneText("", R"({"type": "spot", "position": [0, 0, 0], "direction": [1, 0, 0], "resolution": 64})"));
    EXPECT_EQ(one.light.width, 64u);
    EXPECT_EQ(one.light.height, 64u);
}

TEST(SceneLight, Distant) {
    const auto s = parse(sceneText("", R"({"type": "distant", "position": [0, 10, 0], "direction": [0, -1, 0],
        "up": [0, 0, -1], "extent": 4, "resolution": [100, 50]})"));
    EXPECT_EQ(s.light.projection, dsm::Projection::Orthographic);
    EXPECT_EQ(s.light.extent, 4.0);
}

TEST(SceneLight, SpotCameraMapsAxisAndFieldOfViewEdges) {
    dsm::LightDescription l;
    l.position = {1, 2, 3};
    l.direction = {0, 0, 1};
    l.up = {0, 1, 0};
    l.fieldOfViewDegrees = 90.0;
    l.width = 200;
    l.height = 100;
    const dsm::LightCamera c = dsm::lightCamera(l);
    EXPECT_EQ(c.projection, dsm::Projection::Perspective);
    EXPECT_NEAR(c.screenWindow[0], -1.0, 1e-12);
    EXPECT_NEAR(c.screenWindow[1], 1.0, 1e-12);
    EXPECT_NEAR(c.screenWindow[2], -0.5, 1e-12);
    EXPECT_NEAR(c.screenWindow[3], 0.5, 1e-12);
    EXPECT_EQ(c.nearPlane, 0.0);
    EXPECT_NO_THROW(c.validate());

    // On the axis: the image centre, depth = distance along the axis.
    auto r = toRaster(c, l, {1, 2, 8});
    ASSERT_TRUE(r.ok);
    EXPECT_NEAR(r.x, 100.0, 1e-9);
    EXPECT_NEAR(r.y, 50.0, 1e-9);
    EXPECT_NEAR(r.z, 5.0, 1e-12);
    // Looking along +z with y up, light-space x (right) is world -x.
    r = toRaster(c, l, {1 - 5, 2, 8});
    EXPECT_NEAR(r.x, 200.0, 1e-9);  // right edge: 45 degrees off axis
    EXPECT_NEAR(r.y, 50.0, 1e-9);
    EXPECT_NEAR(r.z, 5.0, 1e-12);
    r = toRaster(c, l, {1 + 5, 2, 8});
    EXPECT_NEAR(r.x, 0.0, 1e-9);
    // Up by half the depth: the top edge (the narrower side is scaled).
    r = toRaster(c, l, {1, 2 + 2.5, 8});
    EXPECT_NEAR(r.x, 100.0, 1e-9);
    EXPECT_NEAR(r.y, 0.0, 1e-9);
    r = toRaster(c, l, {1, 2 - 2.5, 8});
    EXPECT_NEAR(r.y, 100.0, 1e-9);
    // Depth is light-space z, not distance: an off-axis point has the same z.
    r = toRaster(c, l, {1 - 3, 2 + 1, 8});
    EXPECT_NEAR(r.z, 5.0, 1e-12);
    // Behind the light: no raster position.
    EXPECT_FALSE(toRaster(c, l, {1, 2, 0}).ok);
}

TEST(SceneLight, TallImageSpansTheFieldOfViewVertically) {
    dsm::LightDescription l;
    l.direction = {0, 0, 1};
    l.fieldOfViewDegrees = 60.0;
    l.width = 50;
    l.height = 100;
    const auto c = dsm::lightCamera(l);
    const double t = std::tan(30.0 * kPi / 180.0);
    EXPECT_NEAR(c.screenWindow[3], t, 1e-12);
    EXPECT_NEAR(c.screenWindow[1], t / 2, 1e-12);
    const auto r = toRaster(c, l, {0, t * 10, 10});
    EXPECT_NEAR(r.y, 0.0, 1e-9);
}

TEST(SceneLight, WorldToLightIsRigidAndRightHandedInScreen) {
    dsm::LightDescription l;
    l.position = {3, -1, 2};
    l.direction = {1, -2, 0.5};
    l.up = {0, 0, 1};
    const auto c = dsm::lightCamera(l);
    const auto& m = c.worldToLight;
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
            double d = 0;
            for (int k = 0; k < 3; ++k)
                d += m[static_cast<std::size_t>(4 * a + k)] * m[static_cast<std::size_t>(4 * b + k)];
            EXPECT_NEAR(d, a == b ? 1.0 : 0.0, 1e-12);
        }
    EXPECT_EQ(m[12], 0.0);
    EXPECT_EQ(m[15], 1.0);
    // The light position maps to the origin; a point up along "up" is up.
    expectNear(c.worldToLightSpace(l.position), {0, 0, 0}, 1e-12);
    const auto up = c.worldToLightSpace({3, -1, 3});
    EXPECT_GT(up[1], 0.0);
}

TEST(SceneLight, AreaLightPushBackMovesDepthByD) {
    dsm::LightDescription l;
    l.position = {0, 0, 0};
    l.direction = {0, 0, 1};
    l.fieldOfViewDegrees = 90.0;
    l.width = l.height = 100;
    l.nearPlane = 0.25;
    const auto plain = dsm::lightCamera(l);
    l.areaLightRadius = 2.0;
    const auto pushed = dsm::lightCamera(l);
    const double d = 2.0 / std::tan(45.0 * kPi / 180.0);
    EXPECT_EQ(plain.screenWindow, pushed.screenWindow);
    EXPECT_NEAR(pushed.nearPlane, 0.25 + d, 1e-12);
    for (const Vec3& p : {Vec3{0, 0, 5}, Vec3{1, -2, 7}, Vec3{-3, 3, 4}}) {
        const auto a = toRaster(plain, l, p), b = toRaster(pushed, l, p);
        EXPECT_NEAR(b.z, a.z + d, 1e-12);
    }
    // On the axis still maps to the centre; the old frustum edge moves inwards.
    auto r = toRaster(pushed, l, {0, 0, 5});
    EXPECT_NEAR(r.x, 50.0, 1e-9);
    r = toRaster(pushed, l, {-5, 0, 5});
    EXPECT_NEAR(r.x, 50.0 + 50.0 * 5.0 / (5.0 + d), 1e-9);
    // A point seen by the edge of the area light (x = -2 in light space) at
    // the edge of its own field of view is inside the pushed-back frustum.
    r = toRaster(pushed, l, {2 + 5, 0, 5});  // light-space x = -7, 45 degrees from (-2, 0, 0)
    EXPECT_GE(r.x, -1e-9);
    // A non-square map pushes back by the narrower half-angle.
    l.width = 200;
    const auto wide = dsm::lightCamera(l);
    EXPECT_NEAR(wide.nearPlane, 0.25 + 2.0 / 0.5, 1e-12);
}

TEST(SceneLight, DistantCameraIsOrthographic) {
    dsm::LightDescription l;
    l.projection = dsm::Projection::Orthographic;
    l.position = {0, 10, 0};
    l.direction = {0, -1, 0};
    l.up = {0, 0, -1};
    l.extent = 4.0;
    l.width = 100;
    l.height = 50;
    l.areaLightRadius = 3.0;  // ignored by orthographic lights
    const auto c = dsm::lightCamera(l);
    EXPECT_EQ(c.projection, dsm::Projection::Orthographic);
    EXPECT_EQ(c.screenWindow, (std::array<double, 4>{-4, 4, -2, 2}));
    EXPECT_EQ(c.nearPlane, 0.0);
    auto r = toRaster(c, l, {0, 0, 0});
    ASSERT_TRUE(r.ok);
    EXPECT_NEAR(r.x, 50.0, 1e-9);
    EXPECT_NEAR(r.y, 25.0, 1e-9);
    EXPECT_NEAR(r.z, 10.0, 1e-12);
    r = toRaster(c, l, {4, 3, 0});  // right edge (light x = world x here), depth 7
    EXPECT_NEAR(r.x, 100.0, 1e-9);
    EXPECT_NEAR(r.z, 7.0, 1e-12);
    r = toRaster(c, l, {0, 0, -2});  // light up = world -z: the top edge
    EXPECT_NEAR(r.y, 0.0, 1e-9);
    r = toRaster(c, l, {0, -5, 2});
    EXPECT_NEAR(r.y, 50.0, 1e-9);
    EXPECT_NEAR(r.z, 15.0, 1e-12);
}

TEST(SceneLight, CameraRejectsDegenerateLights) {
    dsm::LightDescription l;
    l.direction = {0, 1, 0};  // parallel to the default up
    EXPECT_THROW(dsm::lightCamera(l), dsm::Error);
    l.direction = {0, 0, 1};
    l.fieldOfViewDegrees = 180.0;
    EXPECT_THROW(dsm::lightCamera(l), dsm::Error);
}

// ---------------------------------------------------------------------------
// Objects.

TEST(SceneObjects, InlineMesh) {
    const auto s = parse(sceneText(R"({"type": "mesh", "name": "tri", "opacity": 0.5,
        "positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], "triangles": [[0, 1, 2], [1, 3, 2]]})"));
    const auto& o = only(s);
    EXPECT_EQ(o.name, "tri");
    EXPECT_EQ(o.opacity, (dsm::Rgb{0.5f, 0.5f, 0.5f}));
    const auto& m = std::get<dsm::TriangleMesh>(o.geometry);
    ASSERT_EQ(m.positions.size(), 4u);
    EXPECT_EQ(m.positions[3], (std::array<float, 3>{1, 1, 0}));
    ASSERT_EQ(m.triangles.size(), 2u);
    EXPECT_EQ(m.triangles[1], (std::array<std::uint32_t, 3>{1, 3, 2}));
    EXPECT_FALSE(s.isColoured());
}

TEST(SceneObjects, SphereQuadPlaneDefaults) {
    const auto s = parse(sceneText(R"({"type": "sphere", "center": [1, 2, 3], "radius": 0.5},
        {"type": "quad", "center": [0, -1, 0], "u": [2, 0, 0], "v": [0, 0, 3]},
        {"type": "plane", "normal": [0, 1, 0], "size": 10},
        {"type": "plane", "center": [0, 0, 5], "normal": [0, 0, -2], "size": [2, 4]})"));
    ASSERT_EQ(s.objects.size(), 4u);
    const auto& sp = std::get<dsm::Sphere>(s.objects[0].geometry);
    expectNear(sp.center, {1, 2, 3});
    EXPECT_EQ(sp.radius, 0.5);
    EXPECT_EQ(s.objects[0].name, "sphere#0");
    EXPECT_EQ(s.objects[0].opacity, (dsm::Rgb{1, 1, 1}));
    EXPECT_EQ(s.objects[0].objectToWorld, (std::array<double, 16>{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}));
    expectNear(s.objects[0].motion, {0, 0, 0});
    const auto& q = std::get<dsm::Quad>(s.objects[1].geometry);
    expectNear(q.center, {0, -1, 0});
    expectNear(q.halfU, {2, 0, 0});
    expectNear(q.halfV, {0, 0, 3});
    // A ground plane with normal +y: u = (1,0,0) x n = +z, v = n x u = +x.
    const auto& g = std::get<dsm::Quad>(s.objects[2].geometry);
    expectNear(g.center, {0, 0, 0});
    expectNear(g.halfU, {0, 0, 5});
    expectNear(g.halfV, {5, 0, 0});
    // Normal -z: u = (0,1,0) x n = -x, v = n x u = +y... scaled by the half sizes.
    const auto& w = std::get<dsm::Quad>(s.objects[3].geometry);
    expectNear(w.center, {0, 0, 5});
    expectNear(w.halfU, {-1, 0, 0});
    expectNear(w.halfV, {0, 2, 0});
}

TEST(SceneObjects, CurvesInline) {
    const auto s = parse(sceneText(R"({"type": "curves", "points_per_curve": [2, 3],
        "points": [[0,0,0],[0,1,0],[1,0,0],[1,1,0],[1,2,0]], "width": [1, 2, 3, 4, 5]},
        {"type": "curves", "points_per_curve": [2], "points": [[0,0,0],[0,0,1]], "width": 0.01})"));
    const auto& c = std::get<dsm::Curves>(s.objects[0].geometry);
    EXPECT_EQ(c.pointsPerCurve, (std::vector<std::uint32_t>{2, 3}));
    EXPECT_EQ(c.points.size(), 5u);
    EXPECT_EQ(c.widths, (std::vector<float>{1, 2, 3, 4, 5}));
    const auto& d = std::get<dsm::Curves>(s.objects[1].geometry);
    EXPECT_EQ(d.widths, (std::vector<float>{0.01f}));
}

TEST(SceneObjects, HairBallObject) {
    const auto s = parse(sceneText(R"({"type": "hair", "opacity": [0.2, 0.3, 0.4],
        "hairball": {"center": [0, 1, 0], "radius": 0.5, "count": 100, "length": 0.3, "curl": 2,
                     "width": 0.004, "segments": 4, "seed": 7}})"));
    const auto& c = std::get<dsm::Curves>(only(s).geometry);
    EXPECT_EQ(c.pointsPerCurve.size(), 100u);
    EXPECT_EQ(c.points.size(), 500u);
    EXPECT_EQ(c.widths, (std::vector<float>{0.004f}));
    EXPECT_TRUE(s.isColoured());
    dsm::HairBallParameters h;
    h.center = {0, 1, 0};
    h.radius = 0.5;
    h.count = 100;
    h.length = 0.3;
    h.curl = 2;
    h.width = 0.004;
    h.segments = 4;
    h.seed = 7;
    EXPECT_EQ(dsm::generateHairBall(h).points, c.points);
}

TEST(SceneObjects, Volumes) {
    const auto s = parse(sceneText(R"({"type": "volume", "bounds": [[-1, 0, -1], [1, 2, 3]],
            "density": {"type": "homogeneous", "value": 0.5}, "scale": 4, "step": 0.01},
        {"type": "volume", "bounds": [[0, 0, 0], [1, 1, 2]],
            "density": {"type": "noise", "density": 2, "frequency": 3, "octaves": 5, "seed": 9, "falloff": 0.5}},
        {"type": "volume", "bounds": [[0, 0, 0], [1, 1, 1]], "density": {"type": "noise"}})"));
    const auto& h = std::get<dsm::Volume>(s.objects[0].geometry);
    expectNear(h.boundsMin, {-1, 0, -1});
    expectNear(h.boundsMax, {1, 2, 3});
    EXPECT_EQ(std::get<dsm::HomogeneousDensity>(h.density).density, 0.5);
    EXPECT_EQ(h.scale, 4.0);
    EXPECT_EQ(h.step, 0.01);
    const auto& n = std::get<dsm::Volume>(s.objects[1].geometry);
    const auto& nd = std::get<dsm::NoiseCloudDensity>(n.density);
    EXPECT_EQ(nd.density, 2.0);
    EXPECT_EQ(nd.frequency, 3.0);
    EXPECT_EQ(nd.octaves, 5);
    EXPECT_EQ(nd.seed, 9u);
    EXPECT_EQ(nd.falloff, 0.5);
    EXPECT_EQ(n.scale, 1.0);
    EXPECT_DOUBLE_EQ(n.step, 1.0 / 64);  // default: shortest side / 64
    const auto& dflt = std::get<dsm::NoiseCloudDensity>(std::get<dsm::Volume>(s.objects[2].geometry).density);
    EXPECT_EQ(dflt.density, 1.0);
    EXPECT_EQ(dflt.frequency, 2.0);
    EXPECT_EQ(dflt.octaves, 4);
    EXPECT_EQ(dflt.seed, 1u);
    EXPECT_EQ(dflt.falloff, 1.0);
}

TEST(SceneObjects, OpacityAndMotion) {
    const auto s = parse(sceneText(R"({"type": "sphere", "radius": 1, "opacity": [1, 0.5, 0], "motion": [1, 2, 3]},
        {"type": "volume", "bounds": [[0,0,0],[1,1,1]], "density": {"type": "homogeneous", "value": 1}})"));
    EXPECT_EQ(s.objects[0].opacity, (dsm::Rgb{1.0f, 0.5f, 0.0f}));
    expectNear(s.objects[0].motion, {1, 2, 3});
    EXPECT_TRUE(s.isColoured());
    // Volumes are never coloured.
    EXPECT_FALSE(parse(sceneText(R"({"type": "volume", "bounds": [[0,0,0],[1,1,1]],
        "density": {"type": "homogeneous", "value": 1}})"))
                     .isColoured());
}

TEST(SceneObjects, Transforms) {
    // A row-major matrix as given.
    auto s = parse(sceneText(R"({"type": "sphere", "radius": 1,
        "transform": [2, 0, 0, 1,  0, 3, 0, 2,  0, 0, 4, 3,  0, 0, 0, 1]})"));
    expectNear(apply(only(s).objectToWorld, {1, 1, 1}), {3, 5, 7});
    // scale, then rotate, then translate.
    s = parse(sceneText(R"({"type": "sphere", "radius": 1,
        "transform": {"translate": [10, 0, 0], "rotate": {"axis": [0, 0, 1], "angle": 90}, "scale": 2}})"));
    expectNear(apply(only(s).objectToWorld, {1, 0, 0}), {10, 2, 0}, 1e-12);
    s = parse(sceneText(R"({"type": "sphere", "radius": 1, "transform": {"scale": [1, 2, 3]}})"));
    expectNear(apply(only(s).objectToWorld, {1, 1, 1}), {1, 2, 3});
    // A list is applied first to last: translate, then rotate about the origin.
    s = parse(sceneText(R"({"type": "sphere", "radius": 1,
        "transform": [{"translate": [1, 0, 0]}, {"rotate": {"axis": [0, 1, 0], "angle": 90}}]})"));
    // Rotating (1,0,0) by +90 degrees about +y (right-hand rule) gives (0,0,-1).
    expectNear(apply(only(s).objectToWorld, {0, 0, 0}), {0, 0, -1}, 1e-12);
}

// ---------------------------------------------------------------------------
// Errors: the scene, the JSON path and what was expected.

TEST(SceneErrors, WrongTypesNameThePath) {
    EXPECT_EQ(parseError(sceneText(R"({"type": "sphere", "radius": 1}, {"type": "sphere", "radius": 1},
        {"type": "sphere", "radius": 1, "opacity": "red"})")),
              "scene 'test.json': /objects/2/opacity: expected a number or [r, g, b] in [0, 1], got \"red\"");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "sphere", "radius": "big"})")),
                    "scene 'test.json': /objects/0/radius: expected a number in [1e-12, 1e+12], got \"big\"");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "sphere", "radius": 1, "center": [1, 2]})")),
                    "/objects/0/center: expected [x, y, z] (3 numbers in [-1e+12, 1e+12]), got [1,2]");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "cube"})")),
                    "/objects/0/type: expected \"mesh\", \"sphere\", \"quad\", \"plane\", \"hair\", \"curves\" or "
                    "\"volume\", got \"cube\"");
    EXPECT_CONTAINS(parseError(sceneText("", R"({"type": "point", "position": [0,0,0], "direction": [0,0,1]})")),
                    "/light/type: expected \"spot\" or \"distant\", got \"point\"");
    EXPECT_CONTAINS(
        parseError(R"({"light": {"type": "spot", "position": [0,0,0], "direction": [0,0,1]}, "objects": {}})"),
        "/objects: expected an array of objects, got {}");
    EXPECT_CONTAINS(parseError("[1, 2]"), "scene 'test.json': expected a JSON object");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "sphere", "radius": 1, "transform": [1, 2, 3]})")),
                    "/objects/0/transform: expected 16 numbers");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "mesh", "positions": [[0,0,0]], "triangles": [[0, 0, 1]]})")),
                    "/objects/0/triangles/0/2: expected an integer in [0, 0], got 1");
}

TEST(SceneErrors, OutOfRangeValues) {
    EXPECT_CONTAINS(
        parseError(sceneText("", R"({"type": "spot", "position": [0,0,0], "direction": [0,0,1], "fov": 180})")),
        "/light/fov: expected a number in [0.001, 180), got 180");
    EXPECT_CONTAINS(parseError(sceneText(
                        "", R"({"type": "spot", "position": [0,0,0], "direction": [0,0,1], "resolution": [0, 4]})")),
                    "/light/resolution/0: expected an integer in [1, 131072], got 0");
    EXPECT_CONTAINS(
        parseError(sceneText("", R"({"type": "spot", "position": [0,0,0], "direction": [0,0,1], "near": -1})")),
        "/light/near: expected a number in [0, 1e+12], got -1");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "sphere", "radius": 1, "opacity": [1, 1, 1.5]})")),
                    "/objects/0/opacity: expected a number or [r, g, b] in [0, 1], got [1,1,1.5]");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "volume", "bounds": [[0,0,0],[1,1,1]],
        "density": {"type": "noise", "octaves": 0}})")),
                    "/objects/0/density/octaves: expected an integer in [1, 16], got 0");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "volume", "bounds": [[0,0,0],[1,0,1]],
        "density": {"type": "homogeneous", "value": 1}})")),
                    "/objects/0/bounds: the minimum must be below the maximum");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "hair", "hairball": {"count": 2.5}})")),
                    "/objects/0/hairball/count: expected an integer in [1, 10000000], got 2.5");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "quad", "u": [1,0,0], "v": [2,0,0]})")),
                    "/objects/0/v: is not perpendicular to \"u\"");
    EXPECT_CONTAINS(parseError(sceneText("", R"({"type": "spot", "position": [0,0,0], "direction": [0,1,0]})")),
                    "/light: the light looks along the default \"up\"");
}

TEST(SceneErrors, MissingRequiredFields) {
    EXPECT_CONTAINS(parseError(R"({"objects": []})"), "scene 'test.json': missing required key \"light\"");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "sphere"})")), "/objects/0: missing required key \"radius\"");
    EXPECT_CONTAINS(parseError(sceneText(R"({"radius": 1})")), "/objects/0: missing required key \"type\"");
    EXPECT_CONTAINS(parseError(sceneText("", R"({"type": "spot", "position": [0,0,0]})")),
                    "/light: missing required key \"direction\" (or \"look_at\")");
    EXPECT_CONTAINS(parseError(sceneText("", R"({"type": "distant", "position": [0,0,0], "direction": [0,0,1]})")),
                    "/light: missing required key \"extent\"");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "volume", "density": {"type": "homogeneous", "value": 1}})")),
                    "/objects/0: missing required key \"bounds\"");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "mesh"})")),
                    "/objects/0: missing required key \"file\" (or \"positions\" and \"triangles\")");
}

TEST(SceneErrors, UnknownKeysAndMisuse) {
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "sphere", "radious": 1})")),
                    "/objects/0/radious: unknown key \"radious\" for a sphere (allowed here: type, name, opacity, "
                    "transform, motion, center, radius)");
    EXPECT_CONTAINS(
        parseError(sceneText("", R"({"type": "spot", "position": [0,0,0], "direction": [0,0,1], "colour": 1})")),
        "/light/colour: unknown key \"colour\"");
    EXPECT_CONTAINS(
        parseError(
            R"({"light": {"type": "spot", "position": [0,0,0], "direction": [0,0,1]}, "objects": [], "camera": 1})"),
        "scene 'test.json': /camera: unknown key");
    EXPECT_CONTAINS(
        parseError(sceneText(
            "", R"({"type": "distant", "position": [0,0,0], "direction": [0,0,1], "extent": 1, "area_radius": 1})")),
        "/light/area_radius: applies only to spot lights");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "volume", "opacity": 0.5, "bounds": [[0,0,0],[1,1,1]],
        "density": {"type": "homogeneous", "value": 1}})")),
                    "/objects/0/opacity: does not apply to volumes");
    EXPECT_CONTAINS(
        parseError(
            sceneText(R"({"type": "sphere", "radius": 1, "transform": {"rotate": {"axis": [0,1,0], "degrees": 5}}})")),
        "/objects/0/transform/rotate/degrees: unknown key");
    // Keys starting with '_' are comments.
    EXPECT_EQ(parseError(R"({"_comment": "a scene", "light": {"type": "spot", "_note": 1, "position": [0,0,0],
        "direction": [0,0,1]}, "objects": [{"type": "sphere", "radius": 1, "_why": "test"}]})"),
              "");
}

TEST(SceneErrors, InvalidJsonAndDuplicateKeys) {
    EXPECT_CONTAINS(parseError("{\"light\": "), "scene 'test.json': /light: invalid JSON: ");
    EXPECT_CONTAINS(
        parseError(
            R"({"light": {"type": "spot", "type": "distant", "position": [0,0,0], "direction": [0,0,1]}, "objects": []})"),
        "scene 'test.json': /light/type: key \"type\" appears twice in one object");
}

TEST(SceneErrors, MissingFilesAreNamed) {
    dsm::test::TempDir dir;
    const std::string base = dir.path().string();
    std::string m = parseError(sceneText(R"({"type": "mesh", "file": "nope.obj"})"), base);
    EXPECT_CONTAINS(m, "/objects/0/file: OBJ file '");
    EXPECT_CONTAINS(m, (dir / "nope.obj").string());
    m = parseError(sceneText(R"({"type": "hair", "file": "nope.hair"})"), base);
    EXPECT_CONTAINS(m, "/objects/0/file: hair file '" + (dir / "nope.hair").string() + "'");
    m = parseError(sceneText(R"({"type": "volume", "density": {"type": "vdb", "file": "nope.vdb"}})"), base);
    EXPECT_CONTAINS(m, "/objects/0/density/file: VDB file '" + (dir / "nope.vdb").string() + "'");
    // Checked even when the bounds are given and the grid is read only later.
    m = parseError(
        sceneText(R"({"type": "volume", "bounds": [[0,0,0],[1,1,1]], "density": {"type": "vdb", "file": "nope.vdb"}})"),
        base);
    EXPECT_CONTAINS(m, "/objects/0/density/file: VDB file '" + (dir / "nope.vdb").string() + "' does not exist");
    try {
        dsm::loadScene((dir / "missing.json").string());
        FAIL() << "no error";
    } catch (const dsm::Error& e) {
        EXPECT_CONTAINS(std::string(e.what()), "scene '" + (dir / "missing.json").string() + "'");
    }
}

// ---------------------------------------------------------------------------
// Files.

TEST(SceneFiles, ObjShapesMergedAndTriangulated) {
    dsm::test::TempDir dir;
    writeFile(dir / "two.obj", R"(# two shapes
mtllib missing.mtl
o square
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
f 1 2 3 4
o triangle
v 0 0 1
v 1 0 1
v 0 1 1
usemtl nothing
f -3 -2 -1
)");
    writeFile(dir / "scene.json", sceneText(R"({"type": "mesh", "file": "two.obj", "opacity": 0.25})"));
    const auto s = dsm::loadScene((dir / "scene.json").string());
    EXPECT_EQ(s.path, (dir / "scene.json").string());
    const auto& m = std::get<dsm::TriangleMesh>(only(s).geometry);
    ASSERT_EQ(m.positions.size(), 7u);
    EXPECT_EQ(m.positions[4], (std::array<float, 3>{0, 0, 1}));
    ASSERT_EQ(m.triangles.size(), 3u);  // the square in two (either diagonal), then the triangle
    double area = 0.0;
    for (int t = 0; t < 2; ++t) {
        const auto& tri = m.triangles[static_cast<std::size_t>(t)];
        for (std::uint32_t i : tri) EXPECT_LT(i, 4u);
        const auto &a = m.positions[tri[0]], &b = m.positions[tri[1]], &c = m.positions[tri[2]];
        area += 0.5 * std::abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
    }
    EXPECT_NEAR(area, 1.0, 1e-6);
    EXPECT_EQ(m.triangles[2], (std::array<std::uint32_t, 3>{4, 5, 6}));
}

TEST(SceneFiles, ObjWithoutFacesIsRejected) {
    dsm::test::TempDir dir;
    writeFile(dir / "points.obj", "v 0 0 0\nv 1 0 0\n");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "mesh", "file": "points.obj"})"), dir.path().string()),
                    "has no faces");
}

TEST(SceneFiles, HairRoundTrip) {
    dsm::test::TempDir dir;
    HairSpec h;
    h.hairCount = 2;
    h.segments = {2, 3};
    h.points = {{0, 0, 0}, {0, 1, 0}, {0, 2, 0}, {1, 0, 0}, {1, 1, 0}, {1, 2, 0}, {1, 3, 0.5f}};
    h.thickness = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f};
    h.transparencyAndColour = true;
    writeBytes(dir / "a.hair", hairBytes(h));
    const dsm::Curves c = dsm::loadHairFile((dir / "a.hair").string());
    EXPECT_EQ(c.pointsPerCurve, (std::vector<std::uint32_t>{3, 4}));
    EXPECT_EQ(c.points, h.points);
    EXPECT_EQ(c.widths, h.thickness);

    // No segments or thickness arrays: the header's defaults apply.
    HairSpec d;
    d.hairCount = 3;
    d.defaultSegments = 1;
    d.defaultThickness = 0.05f;
    d.points = {{0, 0, 0}, {0, 0, 1}, {1, 0, 0}, {1, 0, 1}, {2, 0, 0}, {2, 0, 1}};
    writeBytes(dir / "b.hair", hairBytes(d));
    writeFile(dir / "scene.json",
              sceneText(R"({"type": "hair", "file": "b.hair"}, {"type": "hair", "file": "b.hair", "width": 0.01})"));
    const auto s = dsm::loadScene((dir / "scene.json").string());
    const auto& b = std::get<dsm::Curves>(s.objects[0].geometry);
    EXPECT_EQ(b.pointsPerCurve, (std::vector<std::uint32_t>{2, 2, 2}));
    EXPECT_EQ(b.points, d.points);
    EXPECT_EQ(b.widths, (std::vector<float>{0.05f}));
    EXPECT_EQ(std::get<dsm::Curves>(s.objects[1].geometry).widths, (std::vector<float>{0.01f}));
}

TEST(SceneFiles, BadHairFilesAreRejected) {
    dsm::test::TempDir dir;
    HairSpec h;
    h.hairCount = 2;
    h.segments = {2, 3};
    h.points = {{0, 0, 0}, {0, 1, 0}, {0, 2, 0}, {1, 0, 0}, {1, 1, 0}, {1, 2, 0}, {1, 3, 0}};
    h.defaultThickness = 0.1f;
    const auto good = hairBytes(h);

    auto truncated = good;
    truncated.pop_back();
    const std::string t = (dir / "truncated.hair").string();
    writeBytes(t, truncated);
    EXPECT_CONTAINS(hairError(t), "hair file '" + t + "': ");
    EXPECT_CONTAINS(hairError(t), "(truncated)");

    auto header = good;
    header.resize(100);
    writeBytes(dir / "short.hair", header);
    EXPECT_CONTAINS(hairError((dir / "short.hair").string()), "shorter than the 128-byte header");

    auto magic = good;
    magic[0] = 'X';
    writeBytes(dir / "magic.hair", magic);
    EXPECT_CONTAINS(hairError((dir / "magic.hair").string()), "does not start with \"HAIR\"");

    auto mismatch = h;
    mismatch.segments = {2, 2};  // 6 points by the segments, 7 by the header
    writeBytes(dir / "mismatch.hair", hairBytes(mismatch));
    EXPECT_CONTAINS(hairError((dir / "mismatch.hair").string()), "add up to 6 points but the header says 7");

    auto huge = good;
    putU32(huge, 8, 10'000'000u);  // a point count far beyond the file
    writeBytes(dir / "huge.hair", huge);
    EXPECT_CONTAINS(hairError((dir / "huge.hair").string()), "(truncated)");

    // Counts from the header are checked before anything is allocated for them.
    auto tooMany = good;
    putU32(tooMany, 8, 0xFFFFFFFFu);
    writeBytes(dir / "too_many.hair", tooMany);
    try {
        dsm::loadHairFile((dir / "too_many.hair").string());
        ADD_FAILURE() << "no error";
    } catch (const dsm::Error& e) {
        EXPECT_EQ(e.code(), dsm::ErrorCode::limit);
        EXPECT_CONTAINS(std::string(e.what()), "has 4294967295 points, more than the limit of 100000000");
    }
    HairSpec uniform = h;  // no segments array: the file's size does not bound the hair count
    uniform.segments.clear();
    uniform.defaultSegments = 2;
    uniform.hairCount = 0xFFFFFFFFu;
    writeBytes(dir / "many_hairs.hair", hairBytes(uniform));
    EXPECT_CONTAINS(hairError((dir / "many_hairs.hair").string()),
                    "has 4294967295 hairs but only 7 points (every hair has at least 2)");

    auto trailing = good;
    trailing.push_back(0);
    writeBytes(dir / "trailing.hair", trailing);
    EXPECT_CONTAINS(hairError((dir / "trailing.hair").string()), "implies");

    auto noThickness = h;
    noThickness.defaultThickness = 0.0f;
    writeBytes(dir / "thin.hair", hairBytes(noThickness));
    EXPECT_CONTAINS(hairError((dir / "thin.hair").string()), "default thickness");
}

// ---------------------------------------------------------------------------
// Hair balls.

TEST(HairBall, DeterministicShape) {
    dsm::HairBallParameters h;
    h.center = {1, 2, 3};
    h.radius = 0.75;
    h.count = 500;
    h.length = 0.4;
    h.curl = 6.0;
    h.segments = 6;
    h.seed = 42;
    const dsm::Curves a = dsm::generateHairBall(h), b = dsm::generateHairBall(h);
    EXPECT_EQ(a.points, b.points);
    ASSERT_EQ(a.pointsPerCurve.size(), 500u);
    for (std::uint32_t n : a.pointsPerCurve) EXPECT_EQ(n, 7u);
    ASSERT_EQ(a.points.size(), 500u * 7u);
    EXPECT_EQ(a.widths, (std::vector<float>{static_cast<float>(h.width)}));
    for (std::size_t i = 0; i < a.points.size(); ++i) {
        const auto& p = a.points[i];
        const double r = std::sqrt((p[0] - 1) * (p[0] - 1) + (p[1] - 2) * (p[1] - 2) + (p[2] - 3) * (p[2] - 3));
        EXPECT_LE(r, h.radius + h.length + 1e-5) << "point " << i;
        if (i % 7 == 0) {
            EXPECT_NEAR(r, h.radius, 1e-5) << "root " << i;  // rooted on the sphere
        }
    }
    // Hair i does not depend on the count; another seed gives other hairs.
    h.count = 10;
    const dsm::Curves c = dsm::generateHairBall(h);
    EXPECT_TRUE(std::equal(c.points.begin(), c.points.end(), a.points.begin()));
    h.seed = 43;
    EXPECT_NE(dsm::generateHairBall(h).points[0], c.points[0]);
}

TEST(HairBall, SameOnEveryPlatform) {
    // The generator uses only integer hashing, +, *, / and sqrt: these values
    // are exact on any IEEE 754 platform. A change here changes every map.
    dsm::HairBallParameters h;
    h.count = 3;
    h.segments = 2;
    h.seed = 1;
    const dsm::Curves c = dsm::generateHairBall(h);
    ASSERT_EQ(c.points.size(), 9u);
    const std::array<float, 3> first = c.points[0], last = c.points[8];
    EXPECT_EQ(first, (std::array<float, 3>{0x1.c4e804p-1f, 0x1.d12bc2p-2f, 0x1.b094fcp-4f}))
        << std::hexfloat << first[0] << " " << first[1] << " " << first[2];
    EXPECT_EQ(last, (std::array<float, 3>{-0x1.0fdfe4p-1f, 0x1.432c46p-3f, -0x1.e4fc76p-1f}))
        << std::hexfloat << last[0] << " " << last[1] << " " << last[2];
}

// ---------------------------------------------------------------------------
// Density fields.

TEST(Density, Homogeneous) {
    dsm::Volume v;
    v.boundsMin = {0, 0, 0};
    v.boundsMax = {1, 2, 3};
    v.density = dsm::HomogeneousDensity{0.7};
    const auto f = dsm::makeDensityField(v);
    EXPECT_EQ(f->density({0.5, 1, 1.5}), 0.7);
    EXPECT_EQ(f->density({0, 0, 0}), 0.7);
    EXPECT_EQ(f->density({1.01, 1, 1}), 0.0);
    EXPECT_EQ(f->density({0.5, -0.01, 1}), 0.0);
}

TEST(Density, NoiseCloud) {
    dsm::Volume v;
    v.boundsMin = {-1, -1, -2};
    v.boundsMax = {1, 1, 2};
    dsm::NoiseCloudDensity n;
    n.density = 3.0;
    n.frequency = 2.0;
    n.octaves = 4;
    n.seed = 5;
    n.falloff = 0.5;
    v.density = n;
    const auto a = dsm::makeDensityField(v), b = dsm::makeDensityField(v);
    n.seed = 6;
    v.density = n;
    const auto other = dsm::makeDensityField(v);
    double sum = 0.0, maximum = 0.0;
    int differ = 0, count = 0;
    for (int i = 0; i <= 20; ++i)
        for (int j = 0; j <= 20; ++j)
            for (int k = 0; k <= 20; ++k) {
                const Vec3 p{-1 + 0.1 * i, -1 + 0.1 * j, -2 + 0.2 * k};
                const double d = a->density(p);
                EXPECT_EQ(d, b->density(p));
                EXPECT_GE(d, 0.0);
                EXPECT_LE(d, 3.0);
                if (d != other->density(p)) ++differ;
                sum += d;
                maximum = std::max(maximum, d);
                ++count;
                // On the box boundary (and in its corners, outside the ellipsoid) it is 0.
                if (i == 0 || i == 20 || j == 0 || j == 20 || k == 0 || k == 20) {
                    EXPECT_EQ(d, 0.0);
                }
            }
    EXPECT_GT(sum / count, 0.05);
    EXPECT_GT(maximum, 1.0);
    EXPECT_GT(differ, count / 10);
    // Outside the box, and fading smoothly near the boundary.
    EXPECT_EQ(a->density({0, 0, 2.5}), 0.0);
    EXPECT_EQ(a->density({5, 0, 0}), 0.0);
    EXPECT_LT(a->density({0.99, 0, 0}), 3.0 * 0.002);
    EXPECT_LT(a->density({0, 0, 1.98}), 3.0 * 0.002);
    // Falloff 0: no fade inside the ellipsoid.
    n.falloff = 0.0;
    v.density = n;
    const auto hard = dsm::makeDensityField(v);
    double nearEdge = 0.0;
    for (int i = 0; i < 50; ++i)
        nearEdge = std::max(nearEdge, hard->density({0.95 * std::cos(i * 0.1), 0.95 * std::sin(i * 0.1), 0}));
    EXPECT_GT(nearEdge, 0.5);
}

#if DSM_WITH_OPENVDB
TEST(Density, VdbRoundTrip) {
    openvdb::initialize();
    dsm::test::TempDir dir;
    const std::string path = (dir / "cloud.vdb").string();
    {
        auto grid = openvdb::FloatGrid::create(0.0f);
        grid->setName("density");
        grid->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
        auto acc = grid->getAccessor();
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                for (int k = 0; k < 4; ++k) acc.setValue(openvdb::Coord(i, j, k), 2.0f + 0.25f * static_cast<float>(i));
        acc.setValue(openvdb::Coord(0, 0, 3), -1.0f);  // negative densities read as 0
        auto temperature = openvdb::FloatGrid::create(0.0f);
        temperature->setName("temperature");
        temperature->tree().setValue(openvdb::Coord(0, 0, 0), 1.0f);
        auto velocity = openvdb::Vec3SGrid::create();
        velocity->setName("vel");
        velocity->tree().setValue(openvdb::Coord(0, 0, 0), openvdb::Vec3s(1, 0, 0));
        openvdb::GridPtrVec grids{grid, temperature, velocity};
        openvdb::io::File(path).write(grids);
    }
    const auto s = parse(sceneText(R"({"type": "volume", "density": {"type": "vdb", "file": "cloud.vdb"}, "scale": 2},
        {"type": "volume", "bounds": [[0, 0, 0], [1, 1, 1]], "density": {"type": "vdb", "file": "cloud.vdb", "grid": "temperature"}})"),
                         dir.path().string());
    const auto& v = std::get<dsm::Volume>(s.objects[0].geometry);
    // The active voxels 0..3 grown by one voxel, at 0.5 units per voxel.
    expectNear(v.boundsMin, {-0.5, -0.5, -0.5});
    expectNear(v.boundsMax, {2.0, 2.0, 2.0});
    EXPECT_EQ(std::get<dsm::VdbDensity>(v.density).file, path);
    EXPECT_EQ(std::get<dsm::VdbDensity>(v.density).grid, "density");
    EXPECT_EQ(v.scale, 2.0);
    EXPECT_DOUBLE_EQ(v.step, 2.5 / 64);
    const auto f = dsm::makeDensityField(v);
    EXPECT_NEAR(f->density({0.5, 0.5, 0.5}), 2.25, 1e-6);    // voxel (1, 1, 1)
    EXPECT_NEAR(f->density({0.75, 0.5, 0.5}), 2.375, 1e-6);  // halfway to (2, 1, 1): trilinear
    EXPECT_NEAR(f->density({1.5, 1.0, 0.0}), 2.75, 1e-6);    // voxel (3, 2, 0)
    EXPECT_NEAR(f->density({-0.25, 0.5, 0.5}), 1.0, 1e-6);   // half a voxel out: half of 2.0
    EXPECT_EQ(f->density({0.0, 0.0, 1.5}), 0.0);             // the negative voxel
    EXPECT_EQ(f->density({3.0, 0.5, 0.5}), 0.0);             // outside the bounds
    const auto& t = std::get<dsm::Volume>(s.objects[1].geometry);
    expectNear(t.boundsMax, {1, 1, 1});  // given bounds are kept
    EXPECT_NEAR(dsm::makeDensityField(t)->density({0, 0, 0}), 1.0, 1e-6);

    EXPECT_CONTAINS(
        parseError(sceneText(R"({"type": "volume", "density": {"type": "vdb", "file": "cloud.vdb", "grid": "smoke"}})"),
                   dir.path().string()),
        "has no grid 'smoke' (grids: 'density', 'temperature', 'vel')");
    EXPECT_CONTAINS(
        parseError(sceneText(R"({"type": "volume", "density": {"type": "vdb", "file": "cloud.vdb", "grid": "vel"}})"),
                   dir.path().string()),
        "grid 'vel' holds vec3s values; expected a float grid");
    writeFile(dir / "junk.vdb", "not a vdb file at all");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "volume", "density": {"type": "vdb", "file": "junk.vdb"}})"),
                               dir.path().string()),
                    "/objects/0/density/file: VDB file '" + (dir / "junk.vdb").string() + "': ");
}
#else
TEST(Density, VdbNeedsOpenVdb) {
    dsm::test::TempDir dir;
    writeFile(dir / "cloud.vdb", "any bytes");
    EXPECT_CONTAINS(parseError(sceneText(R"({"type": "volume", "density": {"type": "vdb", "file": "cloud.vdb"}})"),
                               dir.path().string()),
                    "built without OpenVDB");
}
#endif

// ---------------------------------------------------------------------------
// The shipped examples stay valid.

TEST(SceneExamples, AllParse) {
    for (const char* name : {"hairball.json", "cloud-and-pipes.json", "leaves.json", "motion.json", "area-light.json"}) {
        SCOPED_TRACE(name);
        const std::string path = std::string(DSM_SOURCE_DIR) + "/examples/" + name;
        dsm::Scene s;
        ASSERT_NO_THROW(s = dsm::loadScene(path));
        EXPECT_FALSE(s.objects.empty());
        EXPECT_NO_THROW(dsm::lightCamera(s.light));
        for (const auto& o : s.objects)
            if (const auto* v = std::get_if<dsm::Volume>(&o.geometry)) {
                EXPECT_NO_THROW(dsm::makeDensityField(*v));
            }
    }
}
