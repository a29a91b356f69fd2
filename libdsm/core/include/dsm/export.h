// DSM_API marks what a shared libdsm exports: the library is compiled with
// hidden visibility, so anything without it stays internal.
#pragma once

#if defined(DSM_STATIC_DEFINE)
// A static libdsm (set on the target's interface by CMake): nothing to export.
#define DSM_API
#elif defined(_WIN32) || defined(__CYGWIN__)
#if defined(DSM_EXPORTS)
#define DSM_API __declspec(dllexport)
#else
#define DSM_API __declspec(dllimport)
#endif
#elif defined(__GNUC__) || defined(__clang__)
#define DSM_API __attribute__((visibility("default")))
#else
#define DSM_API
#endif
