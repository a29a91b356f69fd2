// Quantised storage of visibility values (spec/dsm-format.md §5, "Tolerances
// and bounds"; coded in §7):
// a level of tolerance epsilon stores its values as multiples of a step, and
// its functions are compressed with epsilon less half that step, so the
// tolerance the file states still bounds the error of the values as stored.
#pragma once

#include "dsm/version.h"
#include "dsm/visibility.h"

DSM_NAMESPACE_BEGIN

/// The step a level of `tolerance` stores its values with: the largest power
/// of two 2^-k (1 <= k <= 24) not above tolerance / 8; 0 (values stored
/// exactly as float32) when tolerance / 8 < 2^-24 or the tolerance is not a
/// finite value > 0. Multiples of it up to 1 are exact float32 numbers.
DSM_API double valueStep(double tolerance);

/// The tolerance to compress a level's functions with so that, once their
/// values are rounded to valueStep(tolerance), they stay within `tolerance`
/// of the input: tolerance - valueStep(tolerance) / 2.
DSM_API double compressorTolerance(double tolerance);

/// `f` with every value rounded to the nearest multiple of `step` (ties away
/// from zero); `f` itself when step is 0. Rounding keeps values in [0, 1] and
/// never makes a non-increasing layer increase.
DSM_API VisibilityFunction roundValues(const VisibilityView& f, double step);

/// roundValues() into `out`, whose contents it replaces and whose storage it
/// keeps (no allocation while it has room). `out` must not be the function
/// `f` views.
DSM_API void roundValues(const VisibilityView& f, double step, VisibilityFunction& out);

DSM_NAMESPACE_END
