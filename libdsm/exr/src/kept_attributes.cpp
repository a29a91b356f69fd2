// The source image's header attributes and windows, kept in an imported map's
// metadata and given back on export (spec/exr-interop.md "Kept attributes").
#include "kept_attributes.h"

#include <ImfStringAttribute.h>
#include <nlohmann/json.hpp>

#include "exr_common.h"

DSM_NAMESPACE_BEGIN
namespace exr {

namespace {

using Json = nlohmann::json;

constexpr const char* kKey = "exr";

Json boxJson(const Imath::Box2i& b) { return Json::array({b.min.x, b.min.y, b.max.x, b.max.y}); }

std::optional<Imath::Box2i> boxFrom(const Json& j) {
    if (!j.is_array() || j.size() != 4) return std::nullopt;
    for (const Json& v : j)
        if (!v.is_number_integer()) return std::nullopt;
    const Imath::Box2i b(Imath::V2i(j[0].get<int>(), j[1].get<int>()), Imath::V2i(j[2].get<int>(), j[3].get<int>()));
    if (b.min.x > b.max.x || b.min.y > b.max.y) return std::nullopt;
    return b;
}

/// Attributes export writes itself: never given back.
bool ownAttribute(const std::string& name) { return name == "type" || name.rfind("dsm:", 0) == 0; }

}  // namespace

std::string importedMetadata(const Imf::Header& h, const std::string& fileName) {
    Json metadata;
    if (const auto* m = findAttribute<Imf::StringAttribute>(h, "dsm:metadata")) {
        metadata = Json::parse(m->value(), nullptr, false);
        if (!metadata.is_object()) metadata = Json{{"sourceMetadata", m->value()}};
    } else {
        metadata = Json{{"source", "deep OpenEXR"}, {"file", fileName}};
    }
    Json kept = Json::object();
    for (auto it = h.begin(); it != h.end(); ++it)
        if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute()); s && !ownAttribute(it.name()))
            kept[it.name()] = s->value();
    kept["dataWindow"] = boxJson(h.dataWindow());
    kept["displayWindow"] = boxJson(h.displayWindow());
    metadata[kKey] = kept;
    // Attribute text is not always UTF-8: invalid bytes become U+FFFD.
    return metadata.dump(-1, ' ', false, Json::error_handler_t::replace);
}

KeptAttributes keptAttributes(const std::string& metadata) {
    KeptAttributes out;
    const Json j = Json::parse(metadata, nullptr, false);
    if (!j.is_object() || !j.contains(kKey) || !j[kKey].is_object()) return out;
    for (const auto& [name, value] : j[kKey].items()) {
        if (name == "dataWindow") out.dataWindow = boxFrom(value);
        else if (name == "displayWindow") out.displayWindow = boxFrom(value);
        else if (value.is_string() && !name.empty() && name.size() < 256 && !ownAttribute(name))
            out.strings.emplace_back(name, value.get<std::string>());
    }
    return out;
}

}  // namespace exr
DSM_NAMESPACE_END
