// The samples of one exported pixel, with what the export reports about them (internal).
#pragma once

#include <cstdint>
#include <vector>

#include "dsm/exr_deep.h"

DSM_NAMESPACE_BEGIN
namespace exr {

/// deepSamplesFromVisibility(), also giving the largest deviation of a volume
/// sample written and the count of one-float-step pieces above the bound
/// (ExrExportReport::largestDeviation, oneStepExcess).
std::vector<DeepSample> samplesWithDeviation(const VisibilityView& function, double maxDeviation, double& largest,
                                             std::uint64_t& oneStepExcess);

}  // namespace exr
DSM_NAMESPACE_END
