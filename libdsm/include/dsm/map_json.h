// A map's description as JSON: the schema of `dsm-info --json` (documented in
// docs/dsm-info.md), shared by the tool and the Python bindings so that both
// say exactly the same thing.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

#include "dsm/map_info.h"
#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

/// Version of the description schema. The minor version grows when fields are
/// added, the major one when a field changes meaning.
inline constexpr const char* kMapJsonSchemaVersion = "1.1";

/// The description of an open map's header, levels and metadata as a JSON
/// object (text, indented by `indent` spaces; -1 = one line). `file` is the
/// name recorded in the "file" field. Metadata that is JSON is embedded as
/// JSON; other metadata (or JSON nested more than 100 levels deep) as a string.
DSM_API std::string mapInfoJson(const MapInfo& info, const std::string& file, int indent = 2);

/// Metadata nested deeper than this is kept as text: formatting JSON recurses
/// once per level, and a file may hold 16 MiB of "[[[[...".
inline constexpr std::size_t kMaxMetadataDepth = 100;

/// Deepest nesting of arrays and objects in JSON text (strings skipped; the
/// text need not be valid JSON).
DSM_API std::size_t jsonNestingDepth(std::string_view text);

/// Names used in the description (and by the tools' text output).
DSM_API const char* projectionName(Projection projection);
DSM_API const char* filterName(PixelFilter filter);
/// The filter named "box", "triangle" or "gaussian" (as filterName() gives);
/// nothing for any other text.
DSM_API std::optional<PixelFilter> pixelFilterFromName(std::string_view name);

DSM_NAMESPACE_END
