// The light camera of an imported deep EXR (internal).
#pragma once

#include <cstdint>
#include <string>

#include <ImfHeader.h>

#include "dsm/exr_deep.h"

DSM_NAMESPACE_BEGIN
namespace exr {

/// The light camera for a `width` x `height` map from header `h`: the
/// options' camera, field of view or orthographic width, else the dsm:*
/// attributes, else the standard worldToCamera and worldToNDC. `source` names
/// which (ExrImportReport::cameraSource). Throws dsm::Error (without the file
/// name) when there is none or the attributes do not describe one.
LightCamera lightCamera(const Imf::Header& h, const ExrImportOptions& options, std::uint32_t width,
                        std::uint32_t height, std::string& source);

}  // namespace exr
DSM_NAMESPACE_END
