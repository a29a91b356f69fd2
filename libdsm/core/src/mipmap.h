// Building a coarser mip level: exact averages of 2 x 2 blocks of functions,
// recompressed (Lokovic & Veach 2000, §5.3). Internal.
#pragma once

#include <span>

#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// The light-centre function of `f` as a single layer with `channels`
/// channels (a monochrome function is repeated into RGB): layer 0, followed
/// by a drop to 0 at its last depth when further layers exist, since all light
/// is blocked there. Counts of layer 0 are kept when `withCounts`.
VisibilityFunction lightCentreFunction(const VisibilityView& f, int channels, bool withCounts);

/// The weighted average of the light-centre functions of `children` (by the
/// sweep), compressed with `tolerance`; monochrome when the children allow it.
/// Counts add up when `withCounts`. Empty when every child is empty.
VisibilityFunction averageFunctions(std::span<const VisibilityView> children, std::span<const double> weights,
                                    double tolerance, bool withCounts, bool centred = false);

DSM_NAMESPACE_END
