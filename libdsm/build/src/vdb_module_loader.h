// Finding and loading the OpenVDB module (internal; vdb_module.h).
#pragma once

#include <string>

#include "dsm/version.h"
#include "vdb_module.h"

DSM_NAMESPACE_BEGIN

/// The OpenVDB module, loaded on the first call (once per process, however
/// many threads ask) and never unloaded. Where it is looked for, first
/// found first: the file DSM_VDB_MODULE names when that variable is set;
/// else beside the library or program holding this code, in `dsm/` and in
/// `../<libdir>/dsm/` (the build tree's layout and an installed one's);
/// else the directory it was installed to. When no module loads, throws
/// dsm::Error (unsupported) for `file`, its message starting with `where`
/// (the caller's name for the file), and the same on every later call.
const DsmVdbModule& vdbModule(const std::string& where, const std::string& file);

DSM_NAMESPACE_END
