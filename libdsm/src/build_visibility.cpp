#include "dsm/build_visibility.h"

#include <limits>
#include <vector>

#include "dsm/error.h"
#include "dsm/sweep.h"
#include "text.h"

namespace dsm {

VisibilityFunction buildVisibility(std::span<const SampleRay> rays, std::span<const double> weights,
                                   const CompressorOptions& options) {
    Compressor compressor(options);
    std::vector<VisibilityFunction> taus;
    taus.reserve(rays.size());
    float zStart = -std::numeric_limits<float>::infinity();
    for (;;) {
        taus.clear();
        for (std::size_t k = 0; k < rays.size(); ++k) {
            try {
                taus.push_back(transmittance(rays[k], options.channels, options.keepCounts, zStart));
            } catch (const Error& e) {
                throw Error(detail::concat("ray ", k, ": ", e.what()));
            }
        }
        if (!sweep(taus, weights, options.channels, compressor)) break;
        // The compressor ended a layer: everything up to its depth is in it.
        zStart = compressor.layerEndDepth();
    }
    return compressor.finish();
}

}  // namespace dsm
