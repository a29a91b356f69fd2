#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

const char* libraryVersion() noexcept { return DSM_VERSION_STRING; }

DSM_NAMESPACE_END
