// DSM_TESTED_INTERNAL marks an internal class or function (declared in
// libdsm/src, never installed) that the tests call directly, so that they link
// against a shared libdsm too (internal). It is no part of the API.
#pragma once

#include "dsm/export.h"

#define DSM_TESTED_INTERNAL DSM_API
