#include "dsm/shadow_system.h"

#include <deque>
#include <mutex>
#include <unordered_map>

#include "dsm/error.h"
#include "file_pool.h"
#include "lookup_state.h"
#include "reader_impl.h"

DSM_NAMESPACE_BEGIN

class MapHandle {
public:
    explicit MapHandle(std::shared_ptr<const DeepShadowMap> m) : map(std::move(m)), reader(&ImplAccess::of(*map)) {}
    const std::shared_ptr<const DeepShadowMap> map;
    const MapImpl* const reader;
};

struct ShadowSystem::Impl {
    ShadowSystemOptions options;
    std::shared_ptr<TileCache> cache;
    std::shared_ptr<FilePool> files;
    mutable std::mutex mutex;                          // guards the two below
    std::deque<MapHandle> handles;                     // stable addresses
    std::unordered_map<std::string, MapHandle*> byPath;

    ReaderOptions readerOptions() const {
        ReaderOptions o = options.limits;
        o.cache = cache;
        return o;
    }
};

struct ShadowThread::Impl {
    Impl(const void* s, unsigned tiles) : system(s), state(tiles) {}
    const void* system;  // the ShadowSystem::Impl that made it
    LookupState state;
};

ShadowThread::ShadowThread(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ShadowThread::~ShadowThread() = default;
const LookupFailure& ShadowThread::lastFailure() const noexcept { return impl_->state.failure; }
std::size_t ShadowThread::memoryBytes() const noexcept { return sizeof(*this) + sizeof(Impl) + impl_->state.memoryBytes(); }

std::shared_ptr<ShadowSystem> ShadowSystem::create(const ShadowSystemOptions& options) {
    return std::shared_ptr<ShadowSystem>(new ShadowSystem(options));
}

ShadowSystem::ShadowSystem(const ShadowSystemOptions& options) : impl_(std::make_unique<Impl>()) {
    impl_->options = options;
    impl_->cache = options.cache ? options.cache : TileCache::create(options.cacheBytes);
    impl_->files = FilePool::create(options.maxOpenFiles);
}

ShadowSystem::~ShadowSystem() = default;

MapHandle* ShadowSystem::open(const std::string& path) {
    Impl& s = *impl_;
    {
        std::lock_guard lock(s.mutex);
        if (auto found = s.byPath.find(path); found != s.byPath.end()) return found->second;
    }
    // Opened without the lock (it reads the file); if another thread opened
    // the same path meanwhile, theirs is kept and this one closed.
    auto map = DeepShadowMap::open(s.files->open(path), path, s.readerOptions());
    std::lock_guard lock(s.mutex);
    if (auto found = s.byPath.find(path); found != s.byPath.end()) return found->second;
    MapHandle* handle = &s.handles.emplace_back(std::move(map));
    try {
        s.byPath.emplace(path, handle);
    } catch (...) {
        s.handles.pop_back();
        throw;
    }
    return handle;
}

MapHandle* ShadowSystem::open(std::shared_ptr<const MapInput> input, const std::string& name) {
    Impl& s = *impl_;
    auto map = DeepShadowMap::open(std::move(input), name, s.readerOptions());
    std::lock_guard lock(s.mutex);
    return &s.handles.emplace_back(std::move(map));
}

std::shared_ptr<const DeepShadowMap> ShadowSystem::map(const MapHandle* handle) const {
    if (!handle) throw Error(ErrorCode::argument, "shadow system: no map handle given");
    return handle->map;
}

std::unique_ptr<ShadowThread> ShadowSystem::createThread() {
    return std::unique_ptr<ShadowThread>(
        new ShadowThread(std::make_unique<ShadowThread::Impl>(impl_.get(), impl_->options.threadTiles)));
}

namespace {

// Why a lookup cannot start; null when it can.
const char* unusable(const void* threadSystem, const void* system, const MapHandle* handle) {
    if (!handle) return "shadow system: no map handle given";
    if (threadSystem != system) return "shadow system: the thread state belongs to another shadow system";
    return nullptr;
}

int channelsOf(const MapHandle* handle) { return handle ? handle->reader->info.channels : 1; }

}  // namespace

bool ShadowSystem::lookup(ShadowThread& thread, const MapHandle* handle, LookupSpace space,
                          const std::array<double, 3>& point, const LookupOptions& options,
                          LookupResult& result) const noexcept {
    ShadowThread::Impl& t = *thread.impl_;
    if (const char* why = unusable(t.system, impl_.get(), handle)) {
        recordFailure(t.state.failure, ErrorCode::argument, why);
        result = failureValue(channelsOf(handle));
        return false;
    }
    return t.state.tryAt(*handle->reader, space, point, options, result);
}

std::size_t ShadowSystem::lookup(ShadowThread& thread, const MapHandle* handle, LookupSpace space,
                                 Span<const std::array<double, 3>> points, const LookupOptions& options,
                                 Span<LookupResult> results) const noexcept {
    ShadowThread::Impl& t = *thread.impl_;
    if (const char* why = unusable(t.system, impl_.get(), handle)) {
        recordFailure(t.state.failure, ErrorCode::argument, why);
        const std::size_t n = std::min(points.size(), results.size());
        for (std::size_t i = 0; i < n; ++i) results[i] = failureValue(channelsOf(handle));
        return n;
    }
    return t.state.tryBatch(*handle->reader, space, points, options, results);
}

TileCache& ShadowSystem::cache() const { return *impl_->cache; }

ShadowSystemStats ShadowSystem::stats() const {
    const Impl& s = *impl_;
    ShadowSystemStats out;
    out.cache = s.cache->stats();
    {
        std::lock_guard lock(s.mutex);
        out.maps = s.handles.size();
    }
    const FilePoolStats f = s.files->stats();
    out.filesOpen = f.filesOpen;
    out.peakFilesOpen = f.peakFilesOpen;
    out.fileOpens = f.opens;
    out.reopens = f.reopens;
    return out;
}

void ShadowSystem::resetStats() {
    impl_->cache->resetStats();
    impl_->files->resetStats();
}

DSM_NAMESPACE_END
