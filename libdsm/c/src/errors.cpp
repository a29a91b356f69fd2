// Results, the per-thread last failure and the error callback of the C API.
#include <mutex>
#include <string>

#include "c_api.h"

namespace dsm::c {

namespace {

struct LastFailure {
    dsm_result result = DSM_OK;
    std::string message;
    std::string file;  ///< dsm::Error::file(): empty when the failure names no file
};

LastFailure& lastFailure() noexcept {
    thread_local LastFailure last;
    return last;
}

std::mutex callbackMutex;
dsm_error_callback callbackFunction = nullptr;
void* callbackUser = nullptr;

}  // namespace

dsm_result resultOf(ErrorCode code) noexcept {
    switch (code) {
    case ErrorCode::io:
        return DSM_ERROR_IO;
    case ErrorCode::format:
        return DSM_ERROR_FORMAT;
    case ErrorCode::corrupt:
        return DSM_ERROR_CORRUPT;
    case ErrorCode::limit:
        return DSM_ERROR_LIMIT;
    case ErrorCode::argument:
        return DSM_ERROR_ARGUMENT;
    case ErrorCode::scene:
        return DSM_ERROR_SCENE;
    case ErrorCode::unsupported:
        return DSM_ERROR_UNSUPPORTED;
    case ErrorCode::internal:
        return DSM_ERROR_INTERNAL;
    }
    return DSM_ERROR_INTERNAL;
}

dsm_result failNaming(dsm_result result, const char* message, const char* file) noexcept {
    LastFailure& last = lastFailure();
    last.result = result;
    try {
        last.message = message ? message : "";
        last.file = file ? file : "";
    } catch (...) {
        last.message.clear();  // out of memory: the code alone must do
        last.file.clear();
    }
    dsm_error_callback callback = nullptr;
    void* user = nullptr;
    {
        const std::lock_guard<std::mutex> lock(callbackMutex);
        callback = callbackFunction;
        user = callbackUser;
    }
    if (callback) callback(user, result, last.message.c_str());
    return result;
}

dsm_result fail(dsm_result result, const char* message) noexcept { return failNaming(result, message, nullptr); }

dsm_result fail(const Error& error) noexcept {
    return failNaming(resultOf(error.code()), error.what(), error.file().c_str());
}

dsm_result fail(dsm_result result, const char* function, const char* what) noexcept {
    try {
        return fail(result, (std::string(function) + ": " + what).c_str());
    } catch (...) {
        return fail(result, what);
    }
}

dsm_result missing(const char* function, const char* argument) noexcept {
    try {
        return fail(DSM_ERROR_ARGUMENT, (std::string(function) + ": " + argument + " is NULL").c_str());
    } catch (...) {
        return fail(DSM_ERROR_ARGUMENT, "an argument is NULL");
    }
}

}  // namespace dsm::c

extern "C" {

const char* dsm_result_name(dsm_result result) {
    switch (result) {
    case DSM_OK:
        return "ok";
    case DSM_ERROR_IO:
        return "io";
    case DSM_ERROR_FORMAT:
        return "format";
    case DSM_ERROR_CORRUPT:
        return "corrupt";
    case DSM_ERROR_LIMIT:
        return "limit";
    case DSM_ERROR_ARGUMENT:
        return "argument";
    case DSM_ERROR_SCENE:
        return "scene";
    case DSM_ERROR_UNSUPPORTED:
        return "unsupported";
    case DSM_ERROR_INTERNAL:
        return "internal";
    }
    return "unknown";
}

const char* dsm_last_error_message(void) { return dsm::c::lastFailure().message.c_str(); }

const char* dsm_last_error_file(void) { return dsm::c::lastFailure().file.c_str(); }

dsm_result dsm_last_error(void) { return dsm::c::lastFailure().result; }

void dsm_clear_last_error(void) {
    dsm::c::LastFailure& last = dsm::c::lastFailure();
    last.result = DSM_OK;
    last.message.clear();
    last.file.clear();
}

void dsm_set_error_callback(dsm_error_callback callback, void* user) {
    const std::lock_guard<std::mutex> lock(dsm::c::callbackMutex);
    dsm::c::callbackFunction = callback;
    dsm::c::callbackUser = user;
}

}  // extern "C"
