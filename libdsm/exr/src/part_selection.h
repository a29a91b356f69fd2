// Which part of a multi-part deep EXR is imported (internal;
// spec/exr-interop.md "Parts and views").
#pragma once

#include <string>
#include <vector>

#include <ImfMultiPartInputFile.h>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN
namespace exr {

struct SelectedPart {
    int index = 0;
    /// "part 1 'beauty' (view 'left')", for messages and the report.
    std::string description;
    /// What the caller should know: the other deep parts it did not read.
    std::vector<std::string> notes;
};

/// The deep part to import: `part` (an index or a name) when given, else the
/// first deep part whose view is `view` when given, else the first deep part.
/// Throws dsm::Error (without the file name) naming what exists when there is
/// no such part, or it is not deep.
SelectedPart selectDeepPart(const Imf::MultiPartInputFile& file, const std::string& part, const std::string& view);

/// "part I 'NAME' (view 'VIEW')", the name and view only when the header has them.
std::string describePart(const Imf::MultiPartInputFile& file, int index);

}  // namespace exr
DSM_NAMESPACE_END
