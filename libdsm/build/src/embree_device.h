// Embree devices and their errors (internal), for the build's ray caster and
// the reference tracer: a device whose errors become dsm::Error.
#pragma once

#include <embree3/rtcore.h>

#include <string>
#include <string_view>

#include "dsm/scene.h"
#include "tested_internal.h"

DSM_NAMESPACE_BEGIN

/// A new Embree device that remembers its errors for throwIfEmbreeFailed;
/// throws dsm::Error (internal) naming `who` when Embree cannot make one.
DSM_TESTED_INTERNAL RTCDevice newEmbreeDevice(std::string_view who);

/// Throws dsm::Error (internal), "<who>: Embree failed <doing>: <message>",
/// when `device` (null: device creation) has an error pending.
DSM_TESTED_INTERNAL void throwIfEmbreeFailed(RTCDevice device, std::string_view who, std::string_view doing);

/// An Embree ray from `origin` along `direction` over [0, tMax] (tMax at or
/// above the largest float: unbounded) at shutter time `time`, every mask bit.
DSM_TESTED_INTERNAL RTCRay embreeRay(const Vec3& origin, const Vec3& direction, double tMax, double time);

/// Releases a geometry on every path out of the code that fills it (attached
/// geometries are held by the scene as well).
struct OwnedGeometry {
    RTCGeometry handle;
    explicit OwnedGeometry(RTCGeometry g) : handle(g) {}
    ~OwnedGeometry() {
        if (handle != nullptr) rtcReleaseGeometry(handle);
    }
    OwnedGeometry(const OwnedGeometry&) = delete;
    OwnedGeometry& operator=(const OwnedGeometry&) = delete;
};

DSM_NAMESPACE_END
