#include "dsm/error.h"

namespace dsm {

Error::Error(const std::string& message) : std::runtime_error(message) {}

}  // namespace dsm
