#include "embree_device.h"

#include <limits>

#include "dsm/error.h"
#include "text.h"

DSM_NAMESPACE_BEGIN

namespace {

// Embree reports errors to the thread that caused them; so does this.
thread_local std::string lastEmbreeMessage;

void rememberEmbreeError(void*, RTCError, const char* message) {
    lastEmbreeMessage = message != nullptr ? message : "";
}

const char* errorCodeName(RTCError code) {
    switch (code) {
        case RTC_ERROR_NONE: return "no error";
        case RTC_ERROR_UNKNOWN: return "unknown error";
        case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
        case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
        case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
        case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
        case RTC_ERROR_CANCELLED: return "cancelled";
    }
    return "unrecognised error code";
}

}  // namespace

RTCDevice newEmbreeDevice(std::string_view who) {
    RTCDevice device = rtcNewDevice(nullptr);
    if (device == nullptr) throwIfEmbreeFailed(nullptr, who, "creating a device");
    rtcSetDeviceErrorFunction(device, rememberEmbreeError, nullptr);
    return device;
}

void throwIfEmbreeFailed(RTCDevice device, std::string_view who, std::string_view doing) {
    const RTCError code = rtcGetDeviceError(device);
    if (code == RTC_ERROR_NONE) return;
    const std::string message = lastEmbreeMessage.empty() ? errorCodeName(code) : lastEmbreeMessage;
    lastEmbreeMessage.clear();
    throw Error(ErrorCode::internal, detail::concat(who, ": Embree failed ", doing, ": ", message));
}

RTCRay embreeRay(const Vec3& origin, const Vec3& direction, double tMax, double time) {
    RTCRay ray{};
    ray.org_x = static_cast<float>(origin[0]);
    ray.org_y = static_cast<float>(origin[1]);
    ray.org_z = static_cast<float>(origin[2]);
    ray.dir_x = static_cast<float>(direction[0]);
    ray.dir_y = static_cast<float>(direction[1]);
    ray.dir_z = static_cast<float>(direction[2]);
    ray.tnear = 0.0f;
    ray.tfar = tMax >= std::numeric_limits<float>::max() ? std::numeric_limits<float>::infinity()
                                                          : static_cast<float>(tMax);
    ray.time = static_cast<float>(time);
    ray.mask = ~0u;
    ray.flags = 0;
    return ray;
}

DSM_NAMESPACE_END
