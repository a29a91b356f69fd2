// The one exception type that crosses libdsm's API.
#pragma once

#include <stdexcept>
#include <string>

namespace dsm {

/// Every failure inside libdsm is reported by throwing dsm::Error. The message
/// is one line and names what is wrong and where: the file, mip level, tile,
/// pixel, vertex index or input line, whichever are known.
class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message);
};

}  // namespace dsm
