// The source image's header attributes and windows, kept in an imported map's
// metadata and given back when it is exported (internal; spec/exr-interop.md
// "Kept attributes").
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <ImathBox.h>
#include <ImfHeader.h>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN
namespace exr {

/// The metadata JSON text of a map imported from header `h` of file
/// `fileName`: the image's dsm:metadata object when it has one (a map
/// exported by us), else {"source": "deep OpenEXR", "file": ...}; with the
/// top-level key "exr" set to the header's string attributes (except type and
/// dsm:*) and "dataWindow" / "displayWindow" as [xmin, ymin, xmax, ymax].
std::string importedMetadata(const Imf::Header& h, const std::string& fileName);

/// What an exported image gives back from a map's metadata "exr" object.
struct KeptAttributes {
    std::vector<std::pair<std::string, std::string>> strings;
    std::optional<Imath::Box2i> dataWindow, displayWindow;
};

/// The "exr" object of `metadata` (nothing when it has none or is not JSON).
KeptAttributes keptAttributes(const std::string& metadata);

}  // namespace exr
DSM_NAMESPACE_END
