// Density fields of volumes, evaluated in object space (internal).
#pragma once

#include <memory>

#include "dsm/scene.h"
#include "tested_internal.h"

DSM_NAMESPACE_BEGIN

/// A scalar density field. Thread-safe: evaluate() may be called from many
/// threads at once.
class DSM_TESTED_INTERNAL DensityField {
public:
    virtual ~DensityField() = default;
    /// Density at an object-space point; 0 outside the field.
    virtual double density(const Vec3& objectPoint) const = 0;
};

/// The field of a volume (homogeneous, noise cloud or OpenVDB grid). Loads
/// the VDB file if any; throws dsm::Error naming the file and grid on failure.
/// The returned field is 0 outside [volume.boundsMin, volume.boundsMax].
DSM_TESTED_INTERNAL std::unique_ptr<DensityField> makeDensityField(const Volume& volume);

/// The box where an OpenVDB grid's density can be non-zero, in the grid's world
/// space (= the volume's object space): the bounding box of the active voxels,
/// grown by one voxel on every side (the reach of trilinear interpolation) and
/// mapped from index to world space. Throws dsm::Error naming the file and
/// grid when the file cannot be read, the grid is missing or not a float grid,
/// or it has no active voxels.
DSM_TESTED_INTERNAL void vdbBounds(const VdbDensity& vdb, Vec3& boundsMin, Vec3& boundsMax);

DSM_NAMESPACE_END
