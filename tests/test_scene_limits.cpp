// Hostile scenes (spec/scene.md §1.1-1.3): numbers outside their ranges,
// nesting, sizes and long text are refused with one short dsm::Error line that
// names the scene and the JSON pointer, never a hang, a crash, a bare library
// exception or a silently wrong scene. Registered with a short ctest timeout:
// before these limits some of these inputs looped forever.
#include <gtest/gtest.h>

#include <dsm/error.h>
#include <dsm/scene.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <istream>
#include <sstream>
#include <streambuf>
#include <string>
#include <variant>
#include <vector>

#include "ray_caster.h"
#include "text.h"
#include "temp_dir.h"

namespace {

const char* kLight = R"({"type": "spot", "position": [0, 0, 0], "direction": [0, 0, 1]})";

std::string sceneText(const std::string& objects, const std::string& light = kLight) {
    return R"({"light": )" + light + R"(, "objects": [)" + objects + "]}";
}

// The dsm::Error that `action` throws; fails the test if it throws nothing.
dsm::Error errorOf(const std::function<void()>& action) {
    try {
        action();
    } catch (const dsm::Error& e) {
        return e;
    }
    ADD_FAILURE() << "no dsm::Error thrown";
    return dsm::Error(dsm::ErrorCode::internal, "");
}

dsm::Error parseError(const std::string& json, const dsm::SceneReadOptions& options = {}) {
    return errorOf([&] { dsm::parseScene(json, "", "test.json", options); });
}

// One line, naming the scene, of a sane length.
void expectOneShortLine(const dsm::Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_LT(m.size(), 600u) << m.substr(0, 600);
    EXPECT_EQ(m.rfind("scene 'test.json': ", 0), 0u) << m.substr(0, 600);
}

void expectSceneError(const std::string& json, const std::string& wanted,
                      dsm::ErrorCode code = dsm::ErrorCode::scene) {
    const dsm::Error e = parseError(json);
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(wanted), std::string::npos)
        << "message: " << e.what() << "\nwanted: " << wanted;
    expectOneShortLine(e);
}

std::string hairBall(const std::string& keys) { return R"({"type": "hair", "hairball": {)" + keys + "}}"; }

}  // namespace

// ---------------------------------------------------------------------------
// Hair balls: a NaN direction once made perpendicular() loop forever.

TEST(SceneLimits, HairBallHugeCurlOrLengthIsRefused) {
    expectSceneError(sceneText(hairBall(R"("count": 3, "curl": 1e160)")),
                     "/objects/0/hairball/curl: expected a number in [0, 1000000], got 1e+160");
    expectSceneError(sceneText(hairBall(R"("count": 3, "length": 1e308)")),
                     "/objects/0/hairball/length: expected a number in [1e-12, 1e+12], got 1e+308");
    dsm::HairBallParameters h;
    h.count = 3;
    h.curl = 1e160;
    const dsm::Error e = errorOf([&] { dsm::generateHairBall(h); });
    EXPECT_EQ(e.code(), dsm::ErrorCode::argument);
    EXPECT_STREQ(e.what(), "hair ball: curl 1e+160 is not in [0, 1000000]");
    h.curl = 4.0;
    h.segments = 0;
    EXPECT_EQ(errorOf([&] { dsm::generateHairBall(h); }).code(), dsm::ErrorCode::argument);
}

TEST(SceneLimits, HairBallAtTheEdgesOfItsRangesIsFinite) {
    const dsm::Scene scene = dsm::parseScene(
        sceneText(hairBall(R"("count": 20, "segments": 50, "curl": 1e6, "length": 1e12, "radius": 1e12,
                              "center": [1e12, -1e12, 1e12], "width": 1e-12)")),
        "", "test.json");
    const auto& curves = std::get<dsm::Curves>(scene.objects.at(0).geometry);
    ASSERT_EQ(curves.points.size(), 20u * 51u);
    for (const auto& p : curves.points)
        for (const float c : p) ASSERT_TRUE(std::isfinite(c));
}

// Generating hair takes time and memory in proportion to its points: the
// caller bounds them, across all hair balls, before any is generated.
TEST(SceneLimits, HairBallPointsAreBoundedBeforeGenerating) {
    dsm::SceneReadOptions small;
    small.maxHairPoints = 1000;
    const std::string ball = hairBall(R"("count": 100, "segments": 9)");  // 1000 points
    const dsm::Scene one = dsm::parseScene(sceneText(ball), "", "test.json", small);
    EXPECT_EQ(std::get<dsm::Curves>(one.objects.at(0).geometry).points.size(), 1000u);
    const dsm::Error two = parseError(sceneText(ball + ", " + ball), small);
    EXPECT_EQ(two.code(), dsm::ErrorCode::limit);
    EXPECT_NE(std::string(two.what()).find("/objects/1/hairball: 1000 hair points would bring the scene's hair balls "
                                            "to 2000, more than the limit of 1000"),
              std::string::npos)
        << two.what();
    expectOneShortLine(two);
    // Ten million hairs: refused at once rather than generated.
    const dsm::Error huge = parseError(sceneText(hairBall(R"("count": 10000000, "segments": 9)")), small);
    EXPECT_EQ(huge.code(), dsm::ErrorCode::limit);
    EXPECT_NE(std::string(huge.what()).find("/objects/0/hairball: 100000000 hair points"), std::string::npos)
        << huge.what();
    EXPECT_EQ(dsm::SceneReadOptions{}.maxHairPoints, 100'000'000u);
}

// ---------------------------------------------------------------------------
// Nesting: formatting a 100,000-deep value once overflowed the stack.

TEST(SceneLimits, DeepNestingIsRefusedAsALimit) {
    for (const std::size_t depth : {std::size_t{100'000}, std::size_t{1'000'000}}) {
        const std::string json =
            R"({"light": )" + std::string(depth, '[') + std::string(depth, ']') + R"(, "objects": []})";
        const dsm::Error e = parseError(json);
        EXPECT_EQ(e.code(), dsm::ErrorCode::limit);
        EXPECT_NE(std::string(e.what()).find("nested deeper than 64 levels"), std::string::npos) << e.what();
        EXPECT_EQ(std::string(e.what()).rfind("scene 'test.json': /light/0/0/0/", 0), 0u) << e.what();
        expectOneShortLine(e);
    }
    // The top-level object is level 1: 64 levels parse, 65 do not.
    auto nested = [](std::size_t arrays) {
        return R"({"_comment": )" + std::string(arrays, '[') + std::string(arrays, ']') + R"(, "light": )" + kLight +
               R"(, "objects": []})";
    };
    EXPECT_NO_THROW(dsm::parseScene(nested(dsm::kMaxSceneNesting - 1), "", "test.json"));
    EXPECT_EQ(parseError(nested(dsm::kMaxSceneNesting)).code(), dsm::ErrorCode::limit);
}

// ---------------------------------------------------------------------------
// Numbers beyond the double range and out of their documented ranges.

TEST(SceneLimits, NumberBeyondDoubleRangeNamesSceneAndPointer) {
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1}, {"type": "sphere", "radius": 1e400})"),
                     "scene 'test.json': /objects/1/radius: invalid JSON: number overflow parsing '1e400'");
    expectSceneError(sceneText(R"({"type": "curves", "points_per_curve": [2], "points": [[0,0,0], [0,0,-1e999]],
                                   "width": 1})"),
                     "/objects/0/points/1/2: invalid JSON: number overflow");
}

TEST(SceneLimits, HugeTranslationsAndScalesAreRefused) {
    // 1e308 + 1e308 once overflowed to infinity and the object vanished.
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1,
                                   "transform": [{"translate": [1e308, 0, 0]}, {"translate": [1e308, 0, 0]}]})"),
                     "/objects/0/transform/0/translate: expected [x, y, z] (3 numbers in [-1e+12, 1e+12]), got "
                     "[1e+308,0,0]");
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1,
                                   "transform": [{"translate": [1e12, 0, 0]}, {"translate": [1e12, 0, 0]}]})"),
                     "/objects/0/transform: the transform translates by 2e+12, beyond +-1e+12");
    // A scale of 1e300 was once reported as a singular transform.
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1, "transform": {"scale": 1e300}})"),
                     "/objects/0/transform/scale: expected a number in [-1000000, 1000000], got 1e+300");
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1, "transform": {"scale": [1, 1e-7, 1]}})"),
                     "/objects/0/transform/scale: expected scale factors with magnitudes in [1e-06, 1000000]");
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1,
                                   "transform": [{"scale": 1e6}, {"scale": 1e6}]})"),
                     "/objects/0/transform: the transform's 3x3 part has an entry 1e+12 beyond +-1000000");
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1,
                                   "transform": [1e-7, 0, 0, 0,  0, 1e-7, 0, 0,  0, 0, 1e-7, 0,  0, 0, 0, 1]})"),
                     "/objects/0/transform: the transform is singular or nearly so");
    // Just under the limit: the determinant is given to 17 digits, not rounded onto the limit.
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1,
                                   "transform": [{"scale": 1e-6}, {"scale": [1, 1, 0.9999999999]}]})"),
                     "/objects/0/transform: the transform is singular or nearly so (the determinant of its 3x3 "
                     "part is 9.99999999");
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1,
                                   "transform": {"rotate": {"axis": [0, 1, 0], "angle": 1e300}}})"),
                     "/objects/0/transform/rotate/angle: expected a number in [-1000000, 1000000]");
}

TEST(SceneLimits, LightFarAwayIsRefusedForWhatItIs) {
    // Once reported as "up is parallel to the direction".
    expectSceneError(sceneText("", R"({"type": "spot", "position": [1e308, 0, 0], "look_at": [0, 0, 0]})"),
                     "/light/position: expected [x, y, z] (3 numbers in [-1e+12, 1e+12]), got [1e+308,0,0]");
    expectSceneError(sceneText("", R"({"type": "spot", "position": [0, 0, 0], "direction": [0, 0, 1e-300]})"),
                     "/light/direction: expected a non-zero vector [x, y, z] (length >= 1e-12)");
    expectSceneError(sceneText("", R"({"type": "spot", "position": [0, 0, 0], "direction": [0, 0, 1],
                                       "fov": 1e-300})"),
                     "/light/fov: expected a number in [0.001, 180), got 1e-300");
    expectSceneError(sceneText("", R"({"type": "distant", "position": [0, 0, 0], "direction": [0, 0, 1],
                                       "extent": 1e300})"),
                     "/light/extent: expected a number in [1e-12, 1e+12], got 1e+300");
}

TEST(SceneLimits, OtherNumbersHaveRanges) {
    const std::string box = R"("bounds": [[0, 0, 0], [1, 1, 1]])";
    expectSceneError(
        sceneText(R"({"type": "volume", )" + box + R"(, "density": {"type": "noise", "frequency": 1e300}})"),
        "/objects/0/density/frequency: expected a number in [1e-12, 1000000]");
    expectSceneError(
        sceneText(R"({"type": "volume", )" + box + R"(, "density": {"type": "homogeneous", "value": 1e300}})"),
        "/objects/0/density/value: expected a number in [0, 1e+12]");
    expectSceneError(sceneText(R"({"type": "volume", )" + box + R"(, "scale": 1e300,
                                   "density": {"type": "homogeneous", "value": 1}})"),
                     "/objects/0/scale: expected a number in [0, 1e+12]");
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1, "motion": [0, -1e200, 0]})"),
                     "/objects/0/motion: expected [x, y, z] (3 numbers in [-1e+12, 1e+12])");
    expectSceneError(
        sceneText(R"({"type": "mesh", "positions": [[0,0,0], [1,0,0], [0,1e39,0]], "triangles": [[0,1,2]]})"),
        "/objects/0/positions/2: expected [x, y, z] (3 numbers in [-1e+12, 1e+12])");
    expectSceneError(sceneText(R"({"type": "quad", "u": [1e-300, 0, 0], "v": [0, 1, 0]})"),
                     "/objects/0/u: expected a non-zero vector");
    expectSceneError(sceneText(R"({"type": "sphere", "radius": 1e-300})"),
                     "/objects/0/radius: expected a number in [1e-12, 1e+12]");
}

TEST(SceneLimits, ObjVerticesOutOfRangeAreRefused) {
    dsm::test::TempDir dir;
    std::ofstream(dir / "far.obj") << "v 0 0 0\nv 1 0 0\nv 0 1e30 0\nf 1 2 3\n";
    const dsm::Error e = errorOf([&] {
        dsm::parseScene(sceneText(R"({"type": "mesh", "file": "far.obj"})"), dir.path().string(), "test.json");
    });
    EXPECT_EQ(e.code(), dsm::ErrorCode::scene);
    EXPECT_NE(std::string(e.what()).find("/objects/0/file: OBJ file '"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("vertex 3 has a coordinate 1.00000002e+30"), std::string::npos) << e.what();
}

// ---------------------------------------------------------------------------
// Volumes: a step of 1e-300 made a count beyond 2^64 and the volume vanished.

TEST(SceneLimits, TinyVolumeStepIsRefusedAtParseTime) {
    const std::string volume =
        R"({"type": "volume", "bounds": [[0, 0, 0], [1, 1, 1]], "density": {"type": "homogeneous", "value": 1},
            "step": 1e-300})";
    const dsm::Error e = parseError(sceneText(volume));
    EXPECT_EQ(e.code(), dsm::ErrorCode::scene) << e.what();
    EXPECT_NE(std::string(e.what()).find("/objects/0/step: expected a number in [1e-12, 1e+12], got 1e-300"),
              std::string::npos)
        << e.what();
    // In range, but a million samples across a box of side 1 is the most allowed.
    expectSceneError(sceneText(R"({"type": "volume", "bounds": [[0, 0, 0], [1, 1, 1]],
                                   "density": {"type": "homogeneous", "value": 1}, "step": 1e-9})"),
                     "/objects/0/step: a step of 1e-09 takes 1.73205081e+09 samples across the volume's box",
                     dsm::ErrorCode::limit);
    // The box is measured in the world: scaled up 1000 times, a step of 1e-3 is too fine.
    expectSceneError(sceneText(R"({"type": "volume", "bounds": [[0, 0, 0], [1, 1, 1]], "transform": {"scale": 1000},
                                   "density": {"type": "homogeneous", "value": 1}, "step": 1e-3})"),
                     "/objects/0/step: a step of 0.001 takes", dsm::ErrorCode::limit);
    // A flat box's default step (shortest side / 64) is refused where it is not given.
    expectSceneError(sceneText(R"({"type": "volume", "bounds": [[0, 0, 0], [1, 1, 1e-9]],
                                   "density": {"type": "homogeneous", "value": 1}})"),
                     "/objects/0: the default step (shortest side / 64) of", dsm::ErrorCode::limit);
    EXPECT_NO_THROW(dsm::parseScene(sceneText(R"({"type": "volume", "bounds": [[0, 0, 0], [1, 1, 1]],
        "density": {"type": "homogeneous", "value": 1}, "step": 2e-6})"),
                                    "", "test.json"));
}

TEST(SceneLimits, RayCasterRefusesTooManyStepsInsteadOfDroppingTheVolume) {
    // A scene built in code skips the parser's checks; the ray caster bounds
    // the count itself (a double beyond 2^64 converted to an integer is
    // undefined, and once gave no samples at all).
    dsm::Scene scene;
    dsm::SceneObject object;
    dsm::Volume volume;
    volume.density = dsm::HomogeneousDensity{1.0};
    volume.step = 1e-300;
    object.geometry = volume;
    scene.objects.push_back(object);
    const dsm::RayCaster caster(scene);
    std::vector<dsm::RayVolumeSample> samples;
    const dsm::Error e = errorOf([&] { caster.volumeSamples({0, 0, -5}, {0, 0, 1}, 0.0, 0.0, samples); });
    EXPECT_EQ(e.code(), dsm::ErrorCode::limit);
    EXPECT_NE(std::string(e.what()).find("steps along one ray, more than 10000000"), std::string::npos) << e.what();

    // A step in range samples the box from entry (z = -1) to exit (z = 1).
    std::get<dsm::Volume>(scene.objects[0].geometry).step = 0.5;
    const dsm::RayCaster fine(scene);
    samples.clear();
    fine.volumeSamples({0, 0, -5}, {0, 0, 1}, 0.0, 0.0, samples);
    ASSERT_FALSE(samples.empty());
    EXPECT_NEAR(samples.front().t, 4.0, 1e-9);
    EXPECT_NEAR(samples.back().t, 6.0, 1e-9);
}

// ---------------------------------------------------------------------------
// Long text: a 100 MB key once gave a 200 MB error line.

TEST(SceneLimits, LongUserTextIsCutInMessages) {
    const std::string longKey(10'000'000, 'k');
    const dsm::Error key = parseError(sceneText(R"({"type": "sphere", "radius": 1, ")" + longKey + R"(": 1})"));
    EXPECT_EQ(key.code(), dsm::ErrorCode::scene);
    EXPECT_NE(std::string(key.what()).find("unknown key \"kkkk"), std::string::npos);
    EXPECT_NE(std::string(key.what()).find("...\" for a sphere"), std::string::npos) << key.what();
    expectOneShortLine(key);

    const dsm::Error value = parseError(sceneText(R"({"type": "sphere", "radius": ")" + longKey + R"("})"));
    EXPECT_NE(std::string(value.what()).find("got \"kkkk"), std::string::npos);
    expectOneShortLine(value);

    const dsm::Error array =
        parseError(sceneText(R"({"type": "sphere", "radius": 1, "center": [)" + std::string(1'000'000, '[') +
                             std::string(1'000'000, ']') + "]}"));
    EXPECT_EQ(array.code(), dsm::ErrorCode::limit);
    expectOneShortLine(array);

    std::string ones = "1";
    for (int i = 0; i < 1'000'000; ++i) ones += ",1";
    const dsm::Error wide = parseError(sceneText(R"({"type": "sphere", "radius": [)" + ones + "]}"));
    EXPECT_NE(std::string(wide.what()).find("got [1,1,1,"), std::string::npos) << wide.what();
    expectOneShortLine(wide);

    // A control character in a key never breaks the line.
    const dsm::Error newline = parseError(sceneText(R"({"type": "sphere", "radius": 1, "a\nb": 1})"));
    EXPECT_NE(std::string(newline.what()).find("unknown key \"a\\nb\""), std::string::npos) << newline.what();
    expectOneShortLine(newline);

    // A pointer through many levels of long keys.
    std::string deep;
    for (int i = 0; i < 60; ++i) deep += "{\"" + std::string(100, 'a' + i % 26) + "\": ";
    const dsm::Error pointer =
        parseError(R"({"_comment": )" + deep + "1e400" + std::string(60, '}') + R"(, "light": )" + kLight + "}");
    EXPECT_NE(std::string(pointer.what()).find("scene 'test.json': /_comment/aaaa"), std::string::npos)
        << pointer.what();
    EXPECT_NE(std::string(pointer.what()).find("...: invalid JSON: number overflow"), std::string::npos)
        << pointer.what();
    expectOneShortLine(pointer);

    // A long token in a syntax error.
    const dsm::Error syntax = parseError(sceneText(R"({"type": "sphere", "radius": )" + std::string(1'000'000, 't')));
    EXPECT_NE(std::string(syntax.what()).find("invalid JSON"), std::string::npos);
    expectOneShortLine(syntax);
}

TEST(SceneLimits, ClipCutsAtACharacterBoundaryAndEscapesControls) {
    using dsm::detail::clip;
    EXPECT_EQ(clip("short"), "short");
    EXPECT_EQ(clip(std::string(80, 'a')), std::string(80, 'a'));
    EXPECT_EQ(clip(std::string(81, 'a')), std::string(80, 'a') + "...");
    EXPECT_EQ(clip("a\tb\r\n\x01\x7f"), "a\\tb\\r\\n\\x01\\x7F");
    // "é" is two bytes: a cut never leaves half of it.
    EXPECT_EQ(clip("abc\xC3\xA9z", 4), "abc...");
    EXPECT_EQ(clip("ab\xC3\xA9\xC3\xA9", 4), "ab...");
    EXPECT_EQ(clip("abcd\xC3\xA9", 4), "abcd...");
}

// ---------------------------------------------------------------------------
// Sizes.

TEST(SceneLimits, SceneTextIsBoundedBeforeParsing) {
    dsm::SceneReadOptions small;
    small.maxBytes = 100;
    const std::string text = sceneText(R"({"type": "sphere", "radius": 1, "center": [0, 0, 5]})");
    ASSERT_GT(text.size(), 100u);
    const dsm::Error e = parseError(text, small);
    EXPECT_EQ(e.code(), dsm::ErrorCode::limit);
    EXPECT_NE(std::string(e.what()).find("more than the limit of 100"), std::string::npos) << e.what();
    EXPECT_NO_THROW(dsm::parseScene(text, "", "test.json"));
    EXPECT_EQ(dsm::SceneReadOptions{}.maxBytes, std::uint64_t{256} << 20);

    dsm::test::TempDir dir;
    const std::string path = (dir / "scene.json").string();
    std::ofstream(path) << text;
    const dsm::Error file = errorOf([&] { dsm::loadScene(path, small); });
    EXPECT_EQ(file.code(), dsm::ErrorCode::limit);
    EXPECT_NO_THROW(dsm::loadScene(path));
    EXPECT_EQ(errorOf([&] { dsm::loadScene((dir / "missing.json").string()); }).code(), dsm::ErrorCode::io);
}

namespace {
// An endless stream of zero bytes, like /dev/zero.
class ZeroBuffer : public std::streambuf {
public:
    ZeroBuffer() : zeros_(4096, '\0') { setg(zeros_.data(), zeros_.data(), zeros_.data() + zeros_.size()); }

protected:
    int_type underflow() override {
        setg(zeros_.data(), zeros_.data(), zeros_.data() + zeros_.size());
        return traits_type::to_int_type('\0');
    }

private:
    std::vector<char> zeros_;
};
}  // namespace

TEST(SceneLimits, EndlessStreamStopsAtTheLimit) {
    ZeroBuffer zeros;
    std::istream in(&zeros);
    dsm::SceneReadOptions options;
    options.maxBytes = 1 << 20;
    const dsm::Error e = errorOf([&] { dsm::readScene(in, "", "<stdin>", options); });
    EXPECT_EQ(e.code(), dsm::ErrorCode::limit);
    EXPECT_STREQ(e.what(), "scene '<stdin>': is more than the limit of 1048576 bytes");

    std::istringstream ok(sceneText(R"({"type": "sphere", "radius": 1})"));
    EXPECT_EQ(dsm::readScene(ok, "", "<stdin>").objects.size(), 1u);
}
