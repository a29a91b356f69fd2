// The page dsm-view serves (tools/dsm_view/page/), built into the tool by
// cmake/embed_files.cmake.
#pragma once

#include <cstddef>
#include <vector>

namespace dsm::tools {

struct EmbeddedFile {
    const char* name;  ///< file name, no directory
    const char* type;  ///< Content-Type
    const unsigned char* data;
    std::size_t size;
};

/// index.html and the files it loads.
const std::vector<EmbeddedFile>& viewPageFiles();

}  // namespace dsm::tools
