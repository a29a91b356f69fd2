// A point or direction in world or light space.
#pragma once

#include <array>

namespace dsm {

using Vec3 = std::array<double, 3>;

}  // namespace dsm
