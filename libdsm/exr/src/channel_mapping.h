// Which channels of a deep part give depth and opacity (internal;
// spec/exr-interop.md "Channels of an imported image").
#pragma once

#include <map>
#include <string>

#include <ImfChannelList.h>

#include "deep_band.h"

DSM_NAMESPACE_BEGIN
namespace exr {

struct ResolvedChannels {
    /// The file channels read for each field.
    BandChannels names;
    /// AR, AG and AB all found: an RGB map.
    bool rgb = false;
    /// "Z=depth.Z, A=rgba.A": the roles read and their channels.
    std::string summary;
};

/// The channels for each role (Z, ZBack, A, AR, AG, AB): the one `mapping`
/// names, else the channel of that name, else the one channel whose last
/// component (after the last '.') is the role; and the dsm.* vertex channels
/// when all are present. Throws dsm::Error (without the file name) for a
/// missing Z or opacity, a mapped channel that does not exist, or a role that
/// more than one channel could fill.
ResolvedChannels resolveChannels(const Imf::ChannelList& channels, const std::map<std::string, std::string>& mapping);

}  // namespace exr
DSM_NAMESPACE_END
