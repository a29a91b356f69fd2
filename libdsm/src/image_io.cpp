#include "dsm/image_io.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string_view>
#include <system_error>
#include <vector>

#include <OpenImageIO/imageio.h>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

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
        throw Error(concat(where(path), ": OpenImageIO knows no image format for the extension '",
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

/// A name beside `path` for writing before the rename, keeping the extension
/// (some writers look at it) and unlikely to be taken.
fs::path temporaryBeside(const fs::path& path) {
    std::random_device random;
    const auto tag = std::to_string(random()) + std::to_string(random());
    return path.parent_path() / (concat(".", path.stem().string(), ".tmp-", tag) + path.extension().string());
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

void writeImage(const std::string& path, const FloatImage& image) {
    if (image.width == 0 || image.height == 0)
        throw Error(concat(where(path), ": cannot write an empty image (", image.width, " x ", image.height, ")"));
    if (image.channels < 1 || image.channels > 4)
        throw Error(concat(where(path), ": cannot write an image of ", image.channels, " channels (1 to 4)"));
    if (image.values.size() != static_cast<std::size_t>(image.width) * image.height * static_cast<std::size_t>(image.channels))
        throw Error(concat(where(path), ": image holds ", image.values.size(), " values, not width * height * channels"));

    auto out = outputFor(path);
    const bool floats = keepsFloats(*out);
    const OIIO::TypeDesc type = floats ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8;
    OIIO::ImageSpec spec(static_cast<int>(image.width), static_cast<int>(image.height), image.channels, type);
    spec.channelnames = channelNames(image.channels);
    spec.alpha_channel = image.channels == 2 || image.channels == 4 ? image.channels - 1 : -1;
    spec.attribute("Software", "libdsm");
    // The values are stored as they are, not through the sRGB curve: say so
    // (a PNG gets a gAMA chunk of 1.0).
    spec.attribute("oiio:ColorSpace", "Linear");

    const fs::path temporary = temporaryBeside(path);
    const auto discard = [&] {
        std::error_code ignored;
        fs::remove(temporary, ignored);
    };
    {
        // Creating it first gives the system's reason when the place cannot
        // be written (OpenImageIO only says it could not open the file).
        errno = 0;
        std::ofstream probe(temporary, std::ios::binary);
        if (!probe) {
            const std::string why = errno ? std::strerror(errno) : "cannot create a file there";
            throw Error(concat(where(path), ": cannot write: ", why));
        }
    }
    if (!out->open(temporary.string(), spec)) {
        const std::string why = oneLine(out->geterror(), temporary.string(), path);
        discard();
        throw Error(concat(where(path), ": cannot write: ", why));
    }
    bool written = false;
    if (floats) {
        written = out->write_image(OIIO::TypeDesc::FLOAT, image.values.data());
    } else {
        const std::vector<std::uint8_t> bytes = quantise8(image.values);
        written = out->write_image(OIIO::TypeDesc::UINT8, bytes.data());
    }
    const bool closed = out->close();
    if (!written || !closed) {
        const std::string why = oneLine(out->geterror(), temporary.string(), path);
        discard();
        throw Error(concat(where(path), ": cannot write: ", why));
    }
    std::error_code error;
    fs::rename(temporary, path, error);
    if (error) {
        discard();
        throw Error(concat(where(path), ": cannot write: ", error.message()));
    }
}

FloatImage readImage(const std::string& path) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) throw Error(concat(where(path), ": cannot read image: ", oneLine(OIIO::geterror())));
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
        throw Error(concat(where(path), ": empty image"));
    FloatImage image(static_cast<std::uint32_t>(spec.width), static_cast<std::uint32_t>(spec.height), spec.nchannels);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, image.values.data()))
        throw Error(concat(where(path), ": cannot read image: ", oneLine(in->geterror())));
    return image;
}

DSM_NAMESPACE_END
