// Versions: of the library (CMakeLists.txt reads its project version from here) and of the .dsm
// file format it reads and writes (spec/dsm-format.md); and the versioned
// namespace every public declaration lives in.
#pragma once

#include <cstdint>

#include "dsm/export.h"

// The library version: the one place it is written. The top-level
// CMakeLists.txt reads it from these lines, so a header needs nothing
// generated at configure time.
#define DSM_VERSION_MAJOR 0
#define DSM_VERSION_MINOR 1
#define DSM_VERSION_PATCH 0
#define DSM_VERSION_STRING "0.1.0"

/// Every public name is dsm::NAME, declared in the inline namespace
/// dsm::vMAJOR: programs spell dsm::NAME, while the linker sees the major
/// version, so that a program built against one major version of a shared
/// libdsm fails to link against another instead of misbehaving.
#define DSM_ABI_NAMESPACE_CONCAT_(prefix, major) prefix##major
#define DSM_ABI_NAMESPACE_NAME_(prefix, major) DSM_ABI_NAMESPACE_CONCAT_(prefix, major)
#define DSM_ABI_NAMESPACE DSM_ABI_NAMESPACE_NAME_(v, DSM_VERSION_MAJOR)
#define DSM_NAMESPACE_BEGIN \
    namespace dsm {         \
    inline namespace DSM_ABI_NAMESPACE {
#define DSM_NAMESPACE_END \
    }                     \
    }

DSM_NAMESPACE_BEGIN

/// The library version these headers belong to (DSM_VERSION_* as numbers).
inline constexpr int kLibraryVersionMajor = DSM_VERSION_MAJOR;
inline constexpr int kLibraryVersionMinor = DSM_VERSION_MINOR;
inline constexpr int kLibraryVersionPatch = DSM_VERSION_PATCH;

/// The library version the program runs with, "MAJOR.MINOR.PATCH" (with a
/// shared libdsm it may differ from DSM_VERSION_STRING, the headers' version).
/// Thread-safe; never fails.
DSM_API const char* libraryVersion() noexcept;

/// The .dsm format version this library writes by default. It reads every
/// file of the same major version up to this minor one (spec/dsm-format.md,
/// "Compatibility"); WriterOptions::formatMinor may ask for 1.0 files.
inline constexpr std::uint16_t kFormatVersionMajor = 1;
inline constexpr std::uint16_t kFormatVersionMinor = 1;

DSM_NAMESPACE_END
