// The HTTP side of dsm-view: a page and a small JSON/binary API over the maps
// named on the command line, and nothing else (no file is served by path).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "dsm/reader.h"

namespace dsm::tools {

/// A map the viewer shows: the name the page prints and the open map.
struct ViewedMap {
    std::string name;
    std::shared_ptr<const DeepShadowMap> map;
};

/// The largest picture one request may ask for, in pixels: a page asks for
/// tiles of 256 x 256, so this only stops a request from making the server
/// compute a whole huge level at once.
inline constexpr std::uint64_t kMaxPicturePixels = 1024 * 1024;

/// The most rays one soft-shadow picture may trace (a page asks for 256 x 256
/// pixels with at most 64 rays each), and the most soft-shadow tracers (one
/// per map and light radius asked for) kept at once.
inline constexpr std::uint64_t kMaxSoftShadowRays = 256 * 256 * 64;
inline constexpr std::size_t kMaxSoftShadowTracers = 8;

/// Serves the page and the API on host:port (port 0: a free one) until
/// SIGINT or SIGTERM. `ready` is called with the URL once the socket listens.
/// Returns false (after printing why) when the address cannot be bound.
bool serveMaps(const std::vector<ViewedMap>& maps, const std::string& host, int port,
               const std::function<void(const std::string& url)>& ready);

}  // namespace dsm::tools
