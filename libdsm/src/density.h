// Density fields of volumes, evaluated in object space (internal).
#pragma once

#include <memory>

#include "dsm/scene.h"

namespace dsm {

/// A scalar density field. Thread-safe: evaluate() may be called from many
/// threads at once.
class DensityField {
public:
    virtual ~DensityField() = default;
    /// Density at an object-space point; 0 outside the field.
    virtual double density(const Vec3& objectPoint) const = 0;
};

/// The field of a volume (homogeneous, noise cloud or OpenVDB grid). Loads
/// the VDB file if any; throws dsm::Error naming the file and grid on failure.
/// The returned field is 0 outside [volume.boundsMin, volume.boundsMax].
std::unique_ptr<DensityField> makeDensityField(const Volume& volume);

}  // namespace dsm
