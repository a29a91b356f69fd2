// The OpenVDB module (vdb_module.h): reads float grids and samples them.
// Built as a loadable module of its own, linked to OpenVDB; libdsm itself
// never links OpenVDB.
#include "vdb_module.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <mutex>
#include <new>
#include <string>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include "dsm/error.h"
#include "text.h"

struct DsmVdbGrid {
    openvdb::FloatGrid::ConstPtr grid;
};

namespace {

using dsm::ErrorCode;
using dsm::detail::clip;

void report(ErrorCode code, const std::string& text, int* errorCode, char* message, std::size_t messageSize) {
    *errorCode = static_cast<int>(code);
    if (messageSize == 0) return;
    const std::size_t n = std::min(text.size(), messageSize - 1);
    std::memcpy(message, text.data(), n);
    message[n] = '\0';
}

DsmVdbGrid* readGrid(const char* path, const char* gridName, int* errorCode, char* message,
                     std::size_t messageSize) {
    try {
        static std::once_flag once;
        std::call_once(once, [] { openvdb::initialize(); });
        openvdb::io::File file(path);
        file.open(/*delayLoad=*/false);
        if (!file.hasGrid(gridName)) {
            std::string names;
            for (auto it = file.beginName(); it != file.endName(); ++it)
                names += (names.empty() ? "'" : ", '") + clip(*it) + "'";
            file.close();
            report(ErrorCode::scene,
                   "has no grid '" + clip(gridName) + "' (grids: " +
                       clip(names.empty() ? "none" : names, dsm::detail::kMaxQuotedPath) + ")",
                   errorCode, message, messageSize);
            return nullptr;
        }
        const openvdb::GridBase::Ptr base = file.readGrid(gridName);
        file.close();
        openvdb::FloatGrid::Ptr grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
        if (!grid) {
            report(ErrorCode::scene,
                   "grid '" + clip(gridName) + "' holds " + base->valueType() + " values; expected a float grid",
                   errorCode, message, messageSize);
            return nullptr;
        }
        return new DsmVdbGrid{std::move(grid)};
    } catch (const openvdb::IoError& e) {
        report(ErrorCode::io, clip(e.what()), errorCode, message, messageSize);
    } catch (const openvdb::Exception& e) {
        report(ErrorCode::format, clip(e.what()), errorCode, message, messageSize);
    } catch (const std::bad_alloc&) {
        report(ErrorCode::limit, "out of memory reading the grid", errorCode, message, messageSize);
    } catch (const std::exception& e) {
        report(ErrorCode::format, clip(e.what()), errorCode, message, messageSize);
    } catch (...) {
        report(ErrorCode::internal, "unknown exception reading the grid", errorCode, message, messageSize);
    }
    return nullptr;
}

int activeBounds(const DsmVdbGrid* g, double boundsMin[3], double boundsMax[3]) {
    openvdb::CoordBBox box;
    try {
        box = g->grid->evalActiveVoxelBoundingBox();
    } catch (const std::bad_alloc&) {
        return -1;
    }
    if (box.empty()) return 0;
    const openvdb::Vec3d lo = box.min().asVec3d() - openvdb::Vec3d(1.0), hi = box.max().asVec3d() + openvdb::Vec3d(1.0);
    std::fill(boundsMin, boundsMin + 3, HUGE_VAL);
    std::fill(boundsMax, boundsMax + 3, -HUGE_VAL);
    for (int corner = 0; corner < 8; ++corner) {
        const openvdb::Vec3d c((corner & 1) ? hi.x() : lo.x(), (corner & 2) ? hi.y() : lo.y(),
                               (corner & 4) ? hi.z() : lo.z());
        const openvdb::Vec3d w = g->grid->transform().indexToWorld(c);
        for (int i = 0; i < 3; ++i) {
            boundsMin[i] = std::min(boundsMin[i], w[i]);
            boundsMax[i] = std::max(boundsMax[i], w[i]);
        }
    }
    return 1;
}

float sample(const DsmVdbGrid* g, const double p[3]) {
    const openvdb::Vec3d index = g->grid->transform().worldToIndex(openvdb::Vec3d(p[0], p[1], p[2]));
    // An unregistered accessor of our own per call: nothing is shared
    // between threads, and the eight lookups of one sample share its cache.
    openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> accessor(g->grid->tree());
    return openvdb::tools::BoxSampler::sample(accessor, index);
}

void release(DsmVdbGrid* g) { delete g; }

constexpr DsmVdbModule kModule{DSM_VDB_MODULE_VERSION, readGrid, activeBounds, sample, release};

}  // namespace

extern "C" __attribute__((visibility("default"))) const DsmVdbModule* dsm_vdb_module(void) { return &kModule; }
