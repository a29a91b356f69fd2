// Colour ramps for 8-bit pictures of one-channel map images (dsm-info).
#pragma once

#include "dsm/map_images.h"

namespace dsm {

/// A one-channel image mapped through a colour ramp to RGB in [0, 1] for 8-bit
/// pictures: value / `maximum` goes black (0), blue, magenta, orange to white
/// (1). Values outside [0, maximum] are clamped; `maximum` <= 0 gives black.
/// Throws dsm::Error when `image` does not have one channel.
FloatImage colourRamp(const FloatImage& image, float maximum);

}  // namespace dsm
