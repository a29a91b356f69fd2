// Writing and reading flat pictures (FloatImage) through OpenImageIO, in any
// format it knows, chosen by the file's extension.
#pragma once

#include <string>
#include <vector>
#include <vector>

#include "dsm/map_images.h"

namespace dsm {

/// True when the format chosen by `path`'s extension keeps 32-bit floats
/// (OpenEXR, TIFF); false for 8-bit formats (PNG, JPEG, BMP, ...). Throws
/// dsm::Error naming the file when OpenImageIO knows no format for it.
bool imageFormatKeepsFloats(const std::string& path);

/// Writes `image` (1 to 4 channels) to `path`, the format chosen by the
/// extension. Float formats store the values exactly as 32-bit floats. Other
/// formats store 8 bits per channel, value v as round(255 * clamp(v, 0, 1)):
/// a linear quantisation, no sRGB transfer curve. The picture is written to a
/// temporary file beside `path` and renamed over it, so `path` is never left
/// half written. Throws dsm::Error naming the file when the format is unknown,
/// the image is empty or malformed, or the file cannot be written. `names`
/// names the channels (default Y; Y, A; R, G, B; R, G, B, A).
void writeImage(const std::string& path, const FloatImage& image, const std::vector<std::string>& names = {});

/// Reads a whole picture (the first subimage, level 0) as floats: 8- and
/// 16-bit integer channels become value / 255 (or / 65535). Throws dsm::Error
/// naming the file when it cannot be read.
FloatImage readImage(const std::string& path);

}  // namespace dsm
