#include "dsm/error.h"

DSM_NAMESPACE_BEGIN

const char* errorCodeName(ErrorCode code) noexcept {
    switch (code) {
    case ErrorCode::io: return "io";
    case ErrorCode::format: return "format";
    case ErrorCode::corrupt: return "corrupt";
    case ErrorCode::limit: return "limit";
    case ErrorCode::argument: return "argument";
    case ErrorCode::scene: return "scene";
    case ErrorCode::unsupported: return "unsupported";
    case ErrorCode::internal: return "internal";
    }
    return "internal";
}

Error::Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}

DSM_NAMESPACE_END
