// A point or direction in world or light space.
#pragma once

#include <array>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

using Vec3 = std::array<double, 3>;

DSM_NAMESPACE_END
