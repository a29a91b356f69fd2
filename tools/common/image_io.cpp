#include "image_io.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <vector>

#include <OpenImageIO/imageio.h>

#include "dsm/error.h"
#include "dsm/output_file.h"
#include "text.h"

namespace dsm {

using detail::concat;

namespace {

namespace fs = std::filesystem;

std::string where(const std::string& path) { return concat("'", path, "'"); }

/// OpenImageIO's error text as one line (it may hold several), naming `path`
/// where it names the temporary file written instead.
std::string oneLine(std::string text, const std::string& temporary = {}, const std::string& path = {}) {
    if (!temporary.empty())
        for (auto at = text.find(temporary); at != std::string::npos; at = text.find(temporary, at + path.size()))
            text.replace(at, temporary.size(), path);
    std::replace(text.begin(), text.end(), '\n', ' ');
    while (!text.empty() && text.back() == ' ') text.pop_back();
    return text.empty() ? "unknown OpenImageIO error" : text;
}

/// The writer for the format of `path`'s extension (not yet opened).
std::unique_ptr<OIIO::ImageOutput> outputFor(const std::string& path) {
    auto out = OIIO::ImageOutput::create(path);
    if (!out) {
        (void)OIIO::geterror();  // clear it; it would only repeat the file name
        throw Error(ErrorCode::unsupported,
                    concat(where(path), ": OpenImageIO knows no image format for the extension '",
                           fs::path(path).extension().string(), "'"));
    }
    return out;
}

bool keepsFloats(const OIIO::ImageOutput& out) {
    const std::string_view name = out.format_name();
    return name == "openexr" || name == "tiff";
}

std::vector<std::string> channelNames(int channels) {
    switch (channels) {
        case 1: return {"Y"};
        case 2: return {"Y", "A"};
        case 3: return {"R", "G", "B"};
        default: return {"R", "G", "B", "A"};
    }
}

/// The bytes a complete file of the format ends with, where the format has
/// such a mark: PNG's IEND chunk, JPEG's end-of-image marker.
std::string_view requiredEnding(std::string_view formatName) {
    static constexpr char kPngEnd[] = "\0\0\0\0IEND\xae\x42\x60\x82";
    static constexpr char kJpegEnd[] = "\xff\xd9";
    if (formatName == "png") return {kPngEnd, sizeof kPngEnd - 1};
    if (formatName == "jpeg") return {kJpegEnd, sizeof kJpegEnd - 1};
    return {};
}

/// Checks the picture OpenImageIO wrote before it replaces `path`: some of its
/// writers (PNG) do not report a failed write, e.g. on a full disk. The file
/// must end as its format requires and read back whole with the image's size.
void verifyWrittenPicture(const OutputFile& file, std::string_view formatName, const FloatImage& image) {
    const std::string& written = file.temporaryPath();
    const auto fail = [&](const std::string& why) {
        throw Error(ErrorCode::io, concat(where(file.path()), ": cannot write: the written file ", why));
    };
    if (const std::string_view ending = requiredEnding(formatName); !ending.empty()) {
        std::ifstream in(written, std::ios::binary | std::ios::ate);
        const std::streamoff size = in ? std::streamoff(in.tellg()) : std::streamoff(-1);
        std::string tail(ending.size(), '\0');
        if (size < std::streamoff(ending.size()) || !in.seekg(size - std::streamoff(ending.size())) ||
            !in.read(tail.data(), std::streamsize(tail.size())) || tail != ending)
            fail("is truncated (the disk may be full)");
    }
    auto in = OIIO::ImageInput::open(written);
    if (!in) fail(concat("does not read back: ", oneLine(OIIO::geterror(), written, file.path())));
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.width != static_cast<int>(image.width) || spec.height != static_cast<int>(image.height) ||
        spec.nchannels != image.channels)
        fail(concat("reads back as ", spec.width, " x ", spec.height, " x ", spec.nchannels));
    std::vector<float> values(image.values.size());
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, values.data()))
        fail(concat("does not read back: ", oneLine(in->geterror(), written, file.path())));
}

/// round(255 * clamp(v, 0, 1)), with NaN as 0.
std::vector<std::uint8_t> quantise8(const std::vector<float>& values) {
    std::vector<std::uint8_t> bytes(values.size());
    for (std::size_t i = 0; i < values.size(); ++i) {
        const float v = std::isnan(values[i]) ? 0.0f : std::clamp(values[i], 0.0f, 1.0f);
        bytes[i] = static_cast<std::uint8_t>(std::lround(v * 255.0f));
    }
    return bytes;
}

}  // namespace

bool imageFormatKeepsFloats(const std::string& path) { return keepsFloats(*outputFor(path)); }

void writeImage(const std::string& path, const FloatImage& image, const std::vector<std::string>& names) {
    if (image.width == 0 || image.height == 0)
        throw Error(ErrorCode::argument,
                    concat(where(path), ": cannot write an empty image (", image.width, " x ", image.height, ")"));
    if (image.channels < 1 || image.channels > 4)
        throw Error(ErrorCode::argument,
                    concat(where(path), ": cannot write an image of ", image.channels, " channels (1 to 4)"));
    if (image.values.size() != static_cast<std::size_t>(image.width) * image.height * static_cast<std::size_t>(image.channels))
        throw Error(ErrorCode::argument, concat(where(path), ": image holds ", image.values.size(),
                                                " values, not width * height * channels"));

    auto out = outputFor(path);
    const bool floats = keepsFloats(*out);
    const OIIO::TypeDesc type = floats ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8;
    OIIO::ImageSpec spec(static_cast<int>(image.width), static_cast<int>(image.height), image.channels, type);
    if (!names.empty() && names.size() != static_cast<std::size_t>(image.channels))
        throw Error(ErrorCode::argument, concat(where(path), ": ", names.size(), " channel names for ", image.channels,
                                                " channels"));
    spec.channelnames = names.empty() ? channelNames(image.channels) : names;
    spec.alpha_channel = names.empty() && (image.channels == 2 || image.channels == 4) ? image.channels - 1 : -1;
    if (names.size() == 1 && names[0] == "A") spec.alpha_channel = 0;
    spec.attribute("Software", "libdsm");
    // The values are stored as they are, not through the sRGB curve: say so
    // (a PNG gets a gAMA chunk of 1.0).
    spec.attribute("oiio:ColorSpace", "Linear");

    // The temporary keeps the extension: OpenImageIO chooses a reader by it.
    OutputFile output(path, fs::path(path).extension().string());
    const std::string& temporary = output.temporaryPath();
    if (!out->open(temporary, spec))
        throw Error(ErrorCode::io, concat(where(path), ": cannot write: ", oneLine(out->geterror(), temporary, path)));
    bool written = false;
    if (floats) {
        written = out->write_image(OIIO::TypeDesc::FLOAT, image.values.data());
    } else {
        const std::vector<std::uint8_t> bytes = quantise8(image.values);
        written = out->write_image(OIIO::TypeDesc::UINT8, bytes.data());
    }
    const bool closed = out->close();
    if (!written || !closed)
        throw Error(ErrorCode::io, concat(where(path), ": cannot write: ", oneLine(out->geterror(), temporary, path)));
    verifyWrittenPicture(output, out->format_name(), image);
    output.commit();
}

FloatImage readImage(const std::string& path) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) throw Error(ErrorCode::io, concat(where(path), ": cannot read image: ", oneLine(OIIO::geterror())));
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
        throw Error(ErrorCode::corrupt, concat(where(path), ": empty image"));
    FloatImage image(static_cast<std::uint32_t>(spec.width), static_cast<std::uint32_t>(spec.height), spec.nchannels);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, image.values.data()))
        throw Error(ErrorCode::io, concat(where(path), ": cannot read image: ", oneLine(in->geterror())));
    return image;
}

}  // namespace dsm
