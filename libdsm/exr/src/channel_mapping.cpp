// Which channels of a deep part give depth and opacity (spec/exr-interop.md
// "Channels of an imported image").
#include "channel_mapping.h"

#include <algorithm>
#include <array>
#include <vector>

#include "dsm/error.h"
#include "exr_common.h"
#include "vertex_samples.h"

DSM_NAMESPACE_BEGIN

using detail::concat;

namespace {

constexpr std::array<const char*, 6> kRoles = {"Z", "ZBack", "A", "AR", "AG", "AB"};

std::string listChannels(const Imf::ChannelList& channels) {
    std::string out;
    int n = 0;
    for (auto it = channels.begin(); it != channels.end(); ++it, ++n) {
        if (n == 24) return out + ", ...";
        out += concat(n ? ", " : "", exr::safeText(it.name(), detail::kMaxQuotedChars));
    }
    return out.empty() ? "none" : out;
}

/// The channel for `role`: mapped, exact, or the one ending in ".role"; "" when none.
std::string channelFor(const Imf::ChannelList& channels, const std::map<std::string, std::string>& mapping,
                       const std::string& role) {
    if (const auto it = mapping.find(role); it != mapping.end()) {
        if (!channels.findChannel(it->second))
            throw Error(ErrorCode::argument, concat("the channel mapping ", role, "=",
                                                    exr::safeText(it->second, detail::kMaxQuotedChars),
                                                    " names no channel of the part (channels: ",
                                                    listChannels(channels), ")"));
        return it->second;
    }
    if (channels.findChannel(role)) return role;
    std::vector<std::string> candidates;
    const std::string suffix = "." + role;
    for (auto it = channels.begin(); it != channels.end(); ++it) {
        const std::string name = it.name();
        if (name.size() > suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0)
            candidates.push_back(name);
    }
    if (candidates.size() > 1) {
        std::string list;
        for (const std::string& c : candidates) list += concat(list.empty() ? "" : ", ", exr::safeText(c, 80));
        throw Error(ErrorCode::format, concat("channel ", role, " is ambiguous: ", list, " (choose one with --channels ",
                                              role, "=NAME)"));
    }
    return candidates.empty() ? std::string() : candidates.front();
}

}  // namespace

std::map<std::string, std::string> parseExrChannelMapping(const std::string& text) {
    std::map<std::string, std::string> mapping;
    std::size_t at = 0;
    while (at <= text.size()) {
        const std::size_t end = std::min(text.find(',', at), text.size());
        const std::string item = text.substr(at, end - at);
        const std::size_t equals = item.find('=');
        if (equals == std::string::npos || equals == 0 || equals + 1 == item.size())
            throw Error(ErrorCode::argument, concat("channel mapping '", exr::safeText(item, detail::kMaxQuotedChars),
                                                    "' is not ROLE=CHANNEL"));
        const std::string role = item.substr(0, equals);
        if (std::find(kRoles.begin(), kRoles.end(), role) == kRoles.end())
            throw Error(ErrorCode::argument, concat("channel mapping '", exr::safeText(item, detail::kMaxQuotedChars),
                                                    "': the role is not one of Z, ZBack, A, AR, AG, AB"));
        if (!mapping.emplace(role, item.substr(equals + 1)).second)
            throw Error(ErrorCode::argument, concat("channel mapping: ", role, " is mapped twice"));
        at = end + 1;
    }
    return mapping;
}

exr::ResolvedChannels exr::resolveChannels(const Imf::ChannelList& channels,
                                           const std::map<std::string, std::string>& mapping) {
    ResolvedChannels r;
    std::string found[kRoles.size()];
    for (std::size_t i = 0; i < kRoles.size(); ++i) found[i] = channelFor(channels, mapping, kRoles[i]);
    if (found[0].empty())
        throw Error(ErrorCode::format, concat("no Z channel (a deep image needs depths; channels: ",
                                              listChannels(channels), "; map one with --channels Z=NAME)"));
    r.rgb = !found[3].empty() && !found[4].empty() && !found[5].empty();
    if (!r.rgb && found[2].empty())
        throw Error(ErrorCode::format,
                    concat("no A channel (nor AR, AG and AB): nothing gives the opacity (channels: ",
                           listChannels(channels), "; map one with --channels A=NAME)"));
    r.names.z = found[0];
    r.names.zBack = found[1];
    r.names.alpha = r.rgb ? std::string() : found[2];
    if (r.rgb)
        for (std::size_t c = 0; c < 3; ++c) r.names.alphaRGB[c] = found[3 + c];
    for (std::size_t i = 0; i < kRoles.size(); ++i)
        if (!found[i].empty() && (i != 2 || !r.rgb) && (i < 3 || r.rgb))
            r.summary += concat(r.summary.empty() ? "" : ", ", kRoles[i], "=", safeText(found[i], detail::kMaxQuotedChars));
    // Vertex samples: all of their channels, for the map's channel count.
    const std::vector<std::string> values = vertexValueChannels(r.rgb ? 3 : 1);
    bool vertices = channels.findChannel(kLayerChannel) && channels.findChannel(kCountChannel);
    for (const std::string& v : values) vertices = vertices && channels.findChannel(v);
    if (vertices) {
        r.names.layer = kLayerChannel;
        r.names.count = kCountChannel;
        r.names.value = values;
    }
    return r;
}

DSM_NAMESPACE_END
