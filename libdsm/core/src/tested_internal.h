// DSM_TESTED_INTERNAL marks an internal class or function (declared in a
// component's src/, never installed) that the tests or another component call
// directly, so that they link against a shared library too (internal). It is
// no part of the API.
#pragma once

#include "dsm/export.h"

#define DSM_TESTED_INTERNAL DSM_API
