#include "view_server.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <pthread.h>
#include <string_view>
#include <thread>

#include <httplib.h>
#include <nlohmann/json.hpp>

#include "colour_ramp.h"
#include "dsm/area_light.h"
#include "dsm/error.h"
#include "dsm/map_images.h"
#include "dsm/soft_shadow_image.h"
#include "map_json.h"
#include "view_page.h"

namespace dsm::tools {

namespace {

using Json = nlohmann::ordered_json;

/// A request the API refuses, with its HTTP status (4xx).
struct Refusal {
    int status;
    std::string message;
};

[[noreturn]] void refuse(const std::string& message, int status = 400) { throw Refusal{status, message}; }

/// The query parameter `name` as a whole unsigned integer below `limit`.
std::uint32_t unsignedParam(const httplib::Request& request, const char* name, std::uint64_t limit) {
    if (!request.has_param(name)) refuse(std::string("missing parameter '") + name + "'");
    const std::string text = request.get_param_value(name);
    std::uint64_t value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || error != std::errc() || end != text.data() + text.size() || value >= limit)
        refuse(std::string("parameter '") + name + "' must be an integer in [0, " + std::to_string(limit - 1) + "]");
    return static_cast<std::uint32_t>(value);
}

/// The query parameter `name` as a finite number (or `fallback` when absent).
double numberParam(const httplib::Request& request, const char* name, std::optional<double> fallback = {}) {
    if (!request.has_param(name)) {
        if (fallback) return *fallback;
        refuse(std::string("missing parameter '") + name + "'");
    }
    const std::string text = request.get_param_value(name);
    double value = 0.0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || error != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
        refuse(std::string("parameter '") + name + "' must be a finite number");
    return value;
}

/// Smallest and largest vertex depth of level 0, from the tile directory
/// (the slice slider's range); the near plane and one beyond for an empty map.
std::array<double, 2> depthRange(const DeepShadowMap& map) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const TileRow& row : levelTiles(map, 0))
        if (!row.summary.empty()) {
            lo = std::min<double>(lo, row.summary.minZ);
            hi = std::max<double>(hi, row.summary.maxZ);
        }
    if (!(lo <= hi)) return {map.info().camera.nearPlane, map.info().camera.nearPlane + 1.0};
    return {lo, hi};
}

class ViewServer {
public:
    explicit ViewServer(const std::vector<ViewedMap>& maps) : maps_(maps) {}

    void install(httplib::Server& server) {
        for (const EmbeddedFile& file : viewPageFiles())
            server.Get(std::string("/") + (std::strcmp(file.name, "index.html") == 0 ? "" : file.name),
                       [file](const httplib::Request&, httplib::Response& response) {
                           response.set_content(std::string(reinterpret_cast<const char*>(file.data), file.size),
                                                file.type);
                       });
        server.Get("/api/maps", guarded([this](const httplib::Request&, httplib::Response& r) { maps(r); }));
        server.Get("/api/picture",
                   guarded([this](const httplib::Request& q, httplib::Response& r) { picture(q, r); }));
        server.Get("/api/pixel", guarded([this](const httplib::Request& q, httplib::Response& r) { pixel(q, r); }));
        server.Get("/api/tile", guarded([this](const httplib::Request& q, httplib::Response& r) { tile(q, r); }));
    }

private:
    using Handler = std::function<void(const httplib::Request&, httplib::Response&)>;

    /// Runs a handler; a refusal or an error becomes a JSON {"error": ...}
    /// reply: 4xx for what the request asked wrong, 500 for a damaged map.
    static Handler guarded(Handler handler) {
        return [handler](const httplib::Request& request, httplib::Response& response) {
            auto fail = [&](int status, const std::string& message) {
                response.status = status;
                response.set_content(Json{{"error", message}}.dump(-1, ' ', false, Json::error_handler_t::replace),
                                     "application/json");
            };
            try {
                handler(request, response);
            } catch (const Refusal& r) {
                fail(r.status, r.message);
            } catch (const Error& e) {
                fail(e.code() == ErrorCode::argument ? 400 : 500, e.what());
            } catch (const std::exception& e) {
                fail(500, e.what());
            }
        };
    }

    const ViewedMap& mapParam(const httplib::Request& request, const char* name = "map") const {
        return maps_[unsignedParam(request, name, maps_.size())];
    }

    static unsigned levelParam(const httplib::Request& request, const DeepShadowMap& map) {
        return unsignedParam(request, "level", map.info().levels.size());
    }

    void maps(httplib::Response& response) const {
        Json list = Json::array();
        for (const ViewedMap& m : maps_)
            list.push_back({{"name", m.name},
                            {"depth_range", depthRange(*m.map)},
                            {"recorded_area_radius", AreaLight::recordedRadius(m.map->info())},
                            {"info", Json::parse(mapInfoJson(m.map->info(), m.name, -1))}});
        // The heat maps' colours, the same ramp as dsm-info's pictures.
        FloatImage steps(256, 1, 1);
        for (std::uint32_t i = 0; i < steps.width; ++i) steps.at(i, 0) = static_cast<float>(i);
        const FloatImage ramp = colourRamp(steps, 255.0f);
        Json rampJson = Json::array();
        for (std::uint32_t i = 0; i < ramp.width; ++i)
            rampJson.push_back({ramp.at(i, 0, 0), ramp.at(i, 0, 1), ramp.at(i, 0, 2)});
        const Json reply{{"maps", std::move(list)},
                         {"max_picture_pixels", kMaxPicturePixels},
                         {"ramp", std::move(rampJson)}};
        response.set_content(reply.dump(-1, ' ', false, Json::error_handler_t::replace), "application/json");
    }

    /// A picture of a rectangle of a level as little-endian 32-bit floats,
    /// channels interleaved; X-Channels says how many.
    void picture(const httplib::Request& request, httplib::Response& response) const {
        const ViewedMap& viewed = mapParam(request);
        const DeepShadowMap& map = *viewed.map;
        const unsigned level = levelParam(request, map);
        PixelRect rect;
        rect.x = unsignedParam(request, "x", UINT32_MAX);
        rect.y = unsignedParam(request, "y", UINT32_MAX);
        rect.width = unsignedParam(request, "w", UINT32_MAX);
        rect.height = unsignedParam(request, "h", UINT32_MAX);
        if (static_cast<std::uint64_t>(rect.width) * rect.height > kMaxPicturePixels)
            refuse("picture of " + std::to_string(rect.width) + " x " + std::to_string(rect.height) +
                       " pixels is larger than " + std::to_string(kMaxPicturePixels) + " pixels",
                   413);
        const std::string kind = request.get_param_value("kind");
        const auto make = [&](const ViewedMap& v) -> FloatImage {
            const DeepShadowMap& m = *v.map;
            if (kind == "opacity") return opacityImage(m, level, rect);
            if (kind == "slice") return visibilitySlice(m, level, numberParam(request, "z"), rect);
            if (kind == "vertices") return vertexCountImage(m, level, rect);
            if (kind == "layers") return layerCountImage(m, level, rect);
            if (kind == "soft") {
                SoftShadowImageOptions options;
                options.receiverDepth = numberParam(request, "z");
                options.shadow.samples = static_cast<int>(unsignedParam(request, "samples", 257));
                if (options.shadow.samples < 1) refuse("parameter 'samples' must be at least 1");
                if (static_cast<std::uint64_t>(rect.width) * rect.height * options.shadow.samples > kMaxSoftShadowRays)
                    refuse("soft shadow of " + std::to_string(rect.width) + " x " + std::to_string(rect.height) +
                               " pixels with " + std::to_string(options.shadow.samples) + " rays each traces more than " +
                               std::to_string(kMaxSoftShadowRays) + " rays",
                           413);
                return softShadowImage(softTracer(v, numberParam(request, "radius")), level, rect, options);
            }
            refuse("parameter 'kind' must be opacity, slice, vertices, layers or soft");
        };
        FloatImage image = make(viewed);
        if (request.has_param("minus")) image = differenceImage(image, make(mapParam(request, "minus")));
        static_assert(std::numeric_limits<float>::is_iec559 && sizeof(float) == 4);
        std::string body(image.values.size() * sizeof(float), '\0');
        std::memcpy(body.data(), image.values.data(), body.size());
        response.set_header("X-Channels", std::to_string(image.channels));
        response.set_content(std::move(body), "application/octet-stream");
    }

    /// Soft-shadow tracers are kept per map and light radius: building one
    /// reads the tile directory, and the page asks for tile after tile.
    std::shared_ptr<const SoftShadowTracer> softTracer(const ViewedMap& viewed, double radius) const {
        if (!(radius > 0.0)) refuse("parameter 'radius' must be > 0");
        std::lock_guard lock(tracersMutex_);
        if (tracers_.size() >= kMaxSoftShadowTracers) tracers_.clear();  // each holds a depth hierarchy
        auto& tracer = tracers_[{viewed.map.get(), radius}];
        if (!tracer) {
            try {
                tracer = std::make_shared<const SoftShadowTracer>(
                    viewed.map, AreaLight::forMap(viewed.map->info(), AreaLightShape::Disk, radius, radius));
            } catch (const Error& e) {
                tracers_.erase({viewed.map.get(), radius});
                if (e.code() != ErrorCode::argument) throw;
                refuse("'" + viewed.name + "': " + e.what());  // a light this map cannot have
            }
        }
        return tracer;
    }

    void pixel(const httplib::Request& request, httplib::Response& response) const {
        const DeepShadowMap& map = *mapParam(request).map;
        const unsigned level = levelParam(request, map);
        const LevelInfo& L = map.info().levels[level];
        const std::uint32_t x = unsignedParam(request, "x", L.width), y = unsignedParam(request, "y", L.height);
        const PixelFunction f = map.pixel(level, x, y);
        Json reply = Json::parse(pixelFunctionJson(f.view(), level, x, y));
        reply["tolerance"] = L.tolerance;
        reply["error_bound"] = L.errorBound;
        response.set_content(reply.dump(-1, ' ', false, Json::error_handler_t::replace), "application/json");
    }

    void tile(const httplib::Request& request, httplib::Response& response) const {
        const DeepShadowMap& map = *mapParam(request).map;
        const unsigned level = levelParam(request, map);
        const LevelInfo& L = map.info().levels[level];
        const std::uint32_t tx = unsignedParam(request, "tx", L.tilesX), ty = unsignedParam(request, "ty", L.tilesY);
        const std::uint32_t size = map.info().tileSize;
        const TileRow row{level, tx, ty, tx * size, ty * size, std::min(size, L.width - tx * size),
                          std::min(size, L.height - ty * size), map.tile(level, tx, ty)};
        response.set_content(Json::parse(tilesJson({row})).at(0).dump(), "application/json");
    }

    const std::vector<ViewedMap>& maps_;
    mutable std::mutex tracersMutex_;
    mutable std::map<std::pair<const DeepShadowMap*, double>, std::shared_ptr<const SoftShadowTracer>> tracers_;
};

bool isLoopback(const std::string& host) {
    return host == "127.0.0.1" || host == "localhost" || host == "::1";
}

/// True when the request's Host names this server. On a loopback address a
/// page of another site whose name resolves to 127.0.0.1 (DNS rebinding) is
/// refused; an address the user opened to the network takes any name.
bool hostAllowed(const httplib::Request& request, const std::string& host, int port) {
    if (!isLoopback(host)) return true;
    const std::string value = request.get_header_value("Host");
    std::string suffix = ":";
    suffix += std::to_string(port);
    for (const char* name : {"127.0.0.1", "localhost", "[::1]"})
        if (value == name + suffix) return true;
    return false;
}

}  // namespace

bool serveMaps(const std::vector<ViewedMap>& maps, const std::string& host, int port,
               const std::function<void(const std::string& url)>& ready) {
    // SIGINT and SIGTERM stop the server from a thread of their own: stop()
    // is not safe in a signal handler. Blocked before the server's threads
    // start, so that they inherit the mask.
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);

    httplib::Server server;
    ViewServer view(maps);
    view.install(server);
    // The API takes no bodies; anything but GET and HEAD is refused.
    server.set_payload_max_length(4096);
    server.set_read_timeout(5, 0);
    // Idle keep-alive connections are closed soon, so that stopping (which
    // waits for them) is quick.
    server.set_keep_alive_timeout(1);
    int boundPort = 0;
    server.set_pre_routing_handler([&](const httplib::Request& request, httplib::Response& response) {
        if (request.method != "GET" && request.method != "HEAD") {
            response.status = 405;
            return httplib::Server::HandlerResponse::Handled;
        }
        if (!hostAllowed(request, host, boundPort)) {
            response.status = 403;
            response.set_content("{\"error\":\"unexpected Host header\"}", "application/json");
            return httplib::Server::HandlerResponse::Handled;
        }
        return httplib::Server::HandlerResponse::Unhandled;
    });
    server.set_post_routing_handler([](const httplib::Request&, httplib::Response& response) {
        response.set_header("X-Content-Type-Options", "nosniff");
        response.set_header("Cache-Control", "no-store");
    });

    boundPort = port == 0 ? server.bind_to_any_port(host) : (server.bind_to_port(host, port) ? port : -1);
    if (boundPort <= 0) return false;
    std::thread([&server, signals] {
        int received = 0;
        sigwait(&signals, &received);
        server.stop();
    }).detach();
    const bool ipv6 = host.find(':') != std::string::npos;
    ready("http://" + (ipv6 ? "[" + host + "]" : host) + ":" + std::to_string(boundPort) + "/");
    return server.listen_after_bind();
}

}  // namespace dsm::tools
