// Per-pixel deep samples of a band of rows and the frame buffer that points
// OpenEXR at them, for reading and for writing (internal).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <ImfDeepFrameBuffer.h>

#include "dsm/exr_deep.h"

DSM_NAMESPACE_BEGIN
namespace exr {

/// The values of the dsm.* vertex channels of one sample
/// (spec/exr-interop.md "Vertex samples"); layer 0 marks an ordinary sample.
struct VertexFields {
    std::uint32_t layer = 0;
    std::uint32_t count = 0;
    std::array<float, 3> value{0.0f, 0.0f, 0.0f};
};

/// Which file channel each sample field is read from or written to; an empty
/// name leaves the field out of the frame buffer.
struct BandChannels {
    std::string z = "Z", zBack = "ZBack", alpha = "A";
    /// Per-channel opacities; empty for a monochrome image.
    std::array<std::string, 3> alphaRGB;
    /// Written only: colour channels repeating alphaRGB (R = AR etc.).
    std::array<std::string, 3> colour;
    /// The vertex channels (all empty when the image has none); one value
    /// channel for a monochrome map, three for RGB.
    std::string layer, count;
    std::vector<std::string> value;
    bool withVertices() const { return !layer.empty(); }
};

/// Rows [y0, y0 + rows) of columns [x0, x0 + width), in the file's pixel
/// coordinates.
struct Band {
    int x0 = 0, y0 = 0, width = 0, rows = 0;
    std::vector<unsigned> counts;
    std::vector<std::vector<DeepSample>> samples;
    /// Parallel to samples when the image has vertex channels, else empty.
    std::vector<std::vector<VertexFields>> vertices;

    void reset(int x, int y, int w, int h, bool withVertices) {
        x0 = x, y0 = y, width = w, rows = h;
        const std::size_t n = pixels();
        counts.assign(n, 0);
        samples.assign(n, {});
        vertices.assign(withVertices ? n : 0, {});
        for (auto* v : pointerArrays()) v->assign(n, nullptr);
    }
    std::size_t pixels() const { return std::size_t(width) * std::size_t(rows > 0 ? rows : 0); }
    std::uint64_t sampleCount() const {
        std::uint64_t total = 0;
        for (unsigned c : counts) total += c;
        return total;
    }
    /// Sizes every pixel's samples to its count and points the frame buffer
    /// at them.
    void sizeToCounts() {
        for (std::size_t i = 0; i < samples.size(); ++i) {
            samples[i].resize(counts[i]);
            if (!vertices.empty()) vertices[i].resize(counts[i]);
        }
        point();
    }
    /// Points every field at the pixels' samples (after they are sized).
    void point() {
        for (std::size_t i = 0; i < samples.size(); ++i) {
            DeepSample* s = samples[i].data();
            if (!s) continue;
            z_[i] = reinterpret_cast<char*>(&s->z);
            zBack_[i] = reinterpret_cast<char*>(&s->zBack);
            alpha_[i] = reinterpret_cast<char*>(&s->alpha);
            for (std::size_t c = 0; c < 3; ++c) alphaRGB_[c][i] = reinterpret_cast<char*>(&s->alphaRGB[c]);
            if (vertices.empty()) continue;
            VertexFields* v = vertices[i].data();
            layer_[i] = reinterpret_cast<char*>(&v->layer);
            count_[i] = reinterpret_cast<char*>(&v->count);
            for (std::size_t c = 0; c < 3; ++c) value_[c][i] = reinterpret_cast<char*>(&v->value[c]);
        }
    }
    Imf::DeepFrameBuffer frameBuffer(const BandChannels& names) {
        Imf::DeepFrameBuffer fb;
        fb.insertSampleCountSlice(
            Imf::Slice(Imf::UINT, base(counts), sizeof(unsigned), sizeof(unsigned) * std::size_t(width)));
        const std::size_t xs = sizeof(char*), ys = sizeof(char*) * std::size_t(width);
        auto slice = [&](const std::string& name, std::vector<char*>& v, Imf::PixelType type, std::size_t stride) {
            if (!name.empty()) fb.insert(name, Imf::DeepSlice(type, base(v), xs, ys, stride));
        };
        slice(names.z, z_, Imf::FLOAT, sizeof(DeepSample));
        slice(names.zBack, zBack_, Imf::FLOAT, sizeof(DeepSample));
        slice(names.alpha, alpha_, Imf::FLOAT, sizeof(DeepSample));
        for (std::size_t c = 0; c < 3; ++c) {
            slice(names.alphaRGB[c], alphaRGB_[c], Imf::FLOAT, sizeof(DeepSample));
            slice(names.colour[c], alphaRGB_[c], Imf::FLOAT, sizeof(DeepSample));
        }
        if (names.withVertices()) {
            slice(names.layer, layer_, Imf::UINT, sizeof(VertexFields));
            slice(names.count, count_, Imf::UINT, sizeof(VertexFields));
            for (std::size_t c = 0; c < names.value.size() && c < 3; ++c)
                slice(names.value[c], value_[c], Imf::FLOAT, sizeof(VertexFields));
        }
        return fb;
    }

private:
    std::vector<std::vector<char*>*> pointerArrays() {
        return {&z_, &zBack_, &alpha_, &alphaRGB_[0], &alphaRGB_[1], &alphaRGB_[2],
                &layer_, &count_, &value_[0], &value_[1], &value_[2]};
    }
    template <class T>
    char* base(std::vector<T>& v) const {
        // OpenEXR addresses pixel (x, y) at base + x * xStride + y * yStride.
        const std::ptrdiff_t offset = std::ptrdiff_t(x0) + std::ptrdiff_t(y0) * width;
        return reinterpret_cast<char*>(v.data()) - offset * std::ptrdiff_t(sizeof(T));
    }

    std::vector<char*> z_, zBack_, alpha_, layer_, count_;
    std::array<std::vector<char*>, 3> alphaRGB_, value_;
};

}  // namespace exr
DSM_NAMESPACE_END
