// Checks of an OpenEXR file's headers before OpenEXR reads them (internal).
#pragma once

#include <cstdint>
#include <string>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN
namespace exr {

/// Reads the attribute list of every header of the OpenEXR file at `path`
/// (`fileSize` bytes) without OpenEXR and refuses an attribute size no file
/// of this length can hold, or one whose content disagrees with it (OpenEXR
/// 3.1 allocates what an attribute claims before reading it). Throws
/// dsm::Error (ErrorCode::corrupt) naming the file, part and attribute.
void checkExrHeaderSizes(const std::string& path, std::uint64_t fileSize);

/// Bounds OpenEXR's own allocations for every file it opens from now on: its
/// header check refuses data windows and tiles larger than a map can be.
void limitOpenExrAllocations();

}  // namespace exr
DSM_NAMESPACE_END
