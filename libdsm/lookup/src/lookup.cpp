#include "dsm/lookup.h"

#include "dsm/error.h"
#include "lookup_state.h"
#include "reader_impl.h"

DSM_NAMESPACE_BEGIN

struct LookupContext::Impl {
    std::shared_ptr<const DeepShadowMap> map;
    const MapImpl* reader = nullptr;
    LookupState state{kDefaultThreadTiles};
};

LookupContext::LookupContext(std::shared_ptr<const DeepShadowMap> map) : impl_(std::make_unique<Impl>()) {
    if (!map) throw Error(ErrorCode::argument, "lookup: no map given");
    impl_->reader = &ImplAccess::of(*map);
    impl_->map = std::move(map);
}

LookupContext::~LookupContext() = default;

LookupResult LookupContext::raster(double rx, double ry, double z, const LookupOptions& options) {
    return impl_->state.raster(*impl_->reader, rx, ry, z, options);
}

LookupResult LookupContext::light(const std::array<double, 3>& p, const LookupOptions& options) {
    return impl_->state.at(*impl_->reader, LookupSpace::light, p, options);
}

LookupResult LookupContext::world(const std::array<double, 3>& p, const LookupOptions& options) {
    return impl_->state.at(*impl_->reader, LookupSpace::world, p, options);
}

bool LookupContext::tryRaster(double rx, double ry, double z, const LookupOptions& options,
                              LookupResult& result) noexcept {
    return impl_->state.tryAt(*impl_->reader, LookupSpace::raster, {rx, ry, z}, options, result);
}

bool LookupContext::tryLight(const std::array<double, 3>& p, const LookupOptions& options,
                             LookupResult& result) noexcept {
    return impl_->state.tryAt(*impl_->reader, LookupSpace::light, p, options, result);
}

bool LookupContext::tryWorld(const std::array<double, 3>& p, const LookupOptions& options,
                             LookupResult& result) noexcept {
    return impl_->state.tryAt(*impl_->reader, LookupSpace::world, p, options, result);
}

const LookupFailure& LookupContext::lastFailure() const noexcept { return impl_->state.failure; }

DSM_NAMESPACE_END
