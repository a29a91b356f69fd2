// The boundary between libdsm and its OpenVDB module (internal).
// OpenVDB and the libraries it brings cost a process about 28 ms to load and
// bind before main() runs, which every program linking dsm::build paid
// whether or not its scene had a VDB volume. Their code lives in a module of
// its own instead (vdb_module.cpp), loaded the first time a scene reads a VDB
// file (vdb_module_loader.h). Only C types cross the boundary, and nothing
// thrown crosses it: the module reports failures as an error code and a
// message.
#pragma once

#include <cstddef>

extern "C" {

/// A float grid read by the module, owned by it until release().
typedef struct DsmVdbGrid DsmVdbGrid;

/// Version of DsmVdbModule's layout; the loader refuses a module of another.
#define DSM_VDB_MODULE_VERSION 1

/// What the module does. Every function may be called from any thread; a
/// grid is read-only once returned.
typedef struct DsmVdbModule {
    int version;
    /// Reads float grid `grid` of the VDB file `file`. Returns the grid, or
    /// null with *errorCode set to a dsm::ErrorCode and `message` (room for
    /// messageSize bytes) to what went wrong, NUL-terminated, without the
    /// file's name (the caller adds it).
    DsmVdbGrid* (*readGrid)(const char* file, const char* grid, int* errorCode, char* message,
                            std::size_t messageSize);
    /// The box of the grid's active voxels, grown by one voxel on every side
    /// (the reach of trilinear interpolation), in world space. Returns 1, or 0
    /// when no voxel is active, or -1 when memory ran out finding them.
    int (*activeBounds)(const DsmVdbGrid* grid, double boundsMin[3], double boundsMax[3]);
    /// The grid's value at world-space point p, interpolated trilinearly, as
    /// stored (it may be negative or not finite).
    float (*sample)(const DsmVdbGrid* grid, const double p[3]);
    void (*release)(DsmVdbGrid* grid);
} DsmVdbModule;

/// The module's one exported symbol: a function returning its table.
#define DSM_VDB_MODULE_ENTRY "dsm_vdb_module"
typedef const DsmVdbModule* (*DsmVdbModuleEntry)(void);
}
