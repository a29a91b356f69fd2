// What a shadow needs to know about a scene: where the light is, and what
// covers, attenuates or absorbs its light. No shading. The JSON form is
// specified in spec/scene.md.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <variant>
#include <vector>

#include "dsm/map_info.h"
#include "dsm/vec3.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

using Rgb = std::array<float, 3>;

/// The light as a camera. A spot light is a perspective camera at `position`
/// looking along `direction`; a distant light is an orthographic camera
/// looking along `direction` whose window, of half-size `extent` across the
/// wider image side, is centred on `position` (spec/scene.md §3).
struct LightDescription {
    Projection projection = Projection::Perspective;
    Vec3 position{0.0, 0.0, 0.0};
    Vec3 direction{0.0, 0.0, 1.0};
    Vec3 up{0.0, 1.0, 0.0};
    /// Full field of view across the wider image side, degrees (spot light).
    double fieldOfViewDegrees = 45.0;
    /// Half-size of the window across the wider image side, world units
    /// (distant light); the other side is scaled by the aspect ratio.
    double extent = 1.0;
    std::uint32_t width = 512;
    std::uint32_t height = 512;
    /// Near plane, measured from `position` along `direction`.
    double nearPlane = 0.0;
    /// Radius of an area light centred on the light (spot lights only). The
    /// projection centre is pushed back by d = radius / tan(theta), theta the
    /// half-angle of the narrower image side (Xie et al. 2007, eq. 4), so the
    /// map sees whatever any point of the light sees; depths and the near
    /// plane grow by d.
    double areaLightRadius = 0.0;
};

/// Triangles in object space.
struct TriangleMesh {
    std::vector<std::array<float, 3>> positions;
    std::vector<std::array<std::uint32_t, 3>> triangles;
};

struct Sphere {
    Vec3 center{0.0, 0.0, 0.0};
    double radius = 1.0;
};

/// A flat rectangle: centre and two perpendicular half-axes (corners at
/// center +- halfU +- halfV).
struct Quad {
    Vec3 center{0.0, 0.0, 0.0};
    Vec3 halfU{1.0, 0.0, 0.0};
    Vec3 halfV{0.0, 0.0, 1.0};
};

/// Hair: polylines with a width, rendered as ribbons facing the light.
struct Curves {
    std::vector<std::uint32_t> pointsPerCurve;
    std::vector<std::array<float, 3>> points;
    /// One width per point, or one for all (size 1).
    std::vector<float> widths{0.01f};
};

/// Procedural density fields inside a box.
struct HomogeneousDensity {
    double density = 1.0;
};
struct NoiseCloudDensity {
    double density = 1.0;     ///< peak density
    double frequency = 2.0;   ///< noise features per unit length
    int octaves = 4;
    std::uint32_t seed = 1;
    /// The cloud fills the ellipsoid inscribed in the box; its density fades
    /// to 0 over this fraction of the half-size towards the ellipsoid's surface
    /// (0 = a hard edge, 1 = from the centre).
    double falloff = 1.0;
};
/// An OpenVDB float grid, sampled trilinearly (world units of the grid).
struct VdbDensity {
    std::string file;
    std::string grid = "density";
};

/// A participating medium: extinction kappa = density * scale per unit length,
/// sampled along each light ray every `step` units.
struct Volume {
    Vec3 boundsMin{-1.0, -1.0, -1.0};
    Vec3 boundsMax{1.0, 1.0, 1.0};
    std::variant<HomogeneousDensity, NoiseCloudDensity, VdbDensity> density;
    double scale = 1.0;
    double step = 0.05;
};

using Geometry = std::variant<TriangleMesh, Sphere, Quad, Curves, Volume>;

struct SceneObject {
    std::string name;
    Geometry geometry;
    /// Opacity per channel in [0, 1] (surfaces; volumes ignore it).
    Rgb opacity{1.0f, 1.0f, 1.0f};
    /// Row-major 4x4 object-to-world matrix.
    std::array<double, 16> objectToWorld{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    /// World-space displacement over the shutter: at time t in [0, 1) the
    /// object is translated by t * motion (linear motion blur).
    Vec3 motion{0.0, 0.0, 0.0};
};

struct Scene {
    LightDescription light;
    std::vector<SceneObject> objects;
    /// The JSON text the scene was read from (stored in a map's metadata).
    std::string source;
    /// File the scene came from, for messages.
    std::string path;
    /// Every file the scene reads (OBJ meshes, hair files, VDB grids), as
    /// resolved paths: a tool refuses to write an output over any of them.
    std::vector<std::string> files;

    /// True when some surface opacity differs between channels, so maps need
    /// RGB visibility.
    bool isColoured() const;
};

/// A ball of hair like Lokovic & Veach's Fig. 6: `count` curves rooted at
/// random points of a sphere, growing outwards with random curl. Every field
/// must lie in the range spec/scene.md §5.5 gives it; generateHairBall()
/// throws dsm::Error (ErrorCode::argument) otherwise.
struct HairBallParameters {
    Vec3 center{0.0, 0.0, 0.0};
    double radius = 1.0;
    std::uint32_t count = 10000;
    double length = 0.5;
    /// Curl: how far (in radians per unit length) a hair turns.
    double curl = 4.0;
    double width = 0.002;
    std::uint32_t segments = 8;
    std::uint32_t seed = 1;
};
DSM_API Curves generateHairBall(const HairBallParameters& parameters);

/// Limits on what reading a scene may consume (spec/scene.md §1.2).
struct SceneReadOptions {
    /// Largest scene text read, in bytes; a larger scene is refused with
    /// ErrorCode::limit before it is read (or as soon as a stream exceeds it).
    std::uint64_t maxBytes = std::uint64_t{256} << 20;
    /// Most points the scene's hair balls may generate together (each hair
    /// has segments + 1); a scene asking for more is refused with
    /// ErrorCode::limit before its hair is generated. The default is the
    /// per-ball cap of 10^8, which a larger value does not lift.
    std::uint64_t maxHairPoints = 100'000'000;
};

/// Deepest nesting of arrays and objects a scene may have (the top-level object
/// is level 1). Deeper JSON is refused with ErrorCode::limit while it is parsed,
/// before anything walks it recursively.
inline constexpr std::size_t kMaxSceneNesting = 64;

/// Reads Cem Yuksel's binary .hair format (header "HAIR", points, optional
/// segments, thickness). Throws dsm::Error naming the file on bad input.
DSM_API Curves loadHairFile(const std::string& path);

/// Reads a scene file (spec/scene.md). Relative file names inside (OBJ, .hair,
/// .vdb) are relative to the scene file. Throws dsm::Error naming the file, the
/// JSON path (e.g. "/objects/2/opacity") and what was expected: ErrorCode::scene
/// for an invalid scene, ::limit for one too large or too deeply nested, ::io
/// when the file cannot be read.
DSM_API Scene loadScene(const std::string& path, const SceneReadOptions& options = {});
/// Reads a scene from a stream (e.g. standard input) up to its end, never more
/// than `options.maxBytes`; otherwise as parseScene().
DSM_API Scene readScene(std::istream& in, const std::string& baseDirectory, const std::string& name,
                        const SceneReadOptions& options = {});
/// Parses scene JSON text; `baseDirectory` resolves relative file names and
/// `name` is used in messages.
DSM_API Scene parseScene(const std::string& jsonText, const std::string& baseDirectory, const std::string& name,
                         const SceneReadOptions& options = {});

/// The light camera of a scene's light (with the area-light push-back).
DSM_API LightCamera lightCamera(const LightDescription& light);

DSM_NAMESPACE_END
