// A few objects kept for reuse from one tile to the next, by whichever
// thread codes it (internal). Compressor and decompressor states (zlib
// streams, zstd contexts) cost about as much to make as coding a small tile
// does: each new one's memory is allocated and cleared afresh. A few are
// kept for the threads that code at once; any beyond them are made and
// freed per tile. Slots rather than thread_local storage, so that
// dsm::core needs no thread-local runtime from the dynamic loader.
#pragma once

#include <array>
#include <atomic>

namespace dsm::detail {

/// Objects of type T made by Traits::make() (null when out of memory) and
/// freed by Traits::destroy(T*). Any thread may take and give back at once.
template <class T, class Traits>
class KeptObjects {
public:
    KeptObjects() = default;
    KeptObjects(const KeptObjects&) = delete;
    KeptObjects& operator=(const KeptObjects&) = delete;
    ~KeptObjects() {
        for (auto& slot : slots_)
            if (T* object = slot.load()) Traits::destroy(object);
    }

    /// A kept object, else a new one; null when none can be made.
    T* take() {
        for (auto& slot : slots_)
            if (T* object = slot.exchange(nullptr, std::memory_order_acquire)) return object;
        return Traits::make();
    }

    /// Keeps `object` (from take()) for a later take(), or frees it when every slot is full.
    void give(T* object) {
        if (!object) return;
        for (auto& slot : slots_) {
            T* empty = nullptr;
            if (slot.compare_exchange_strong(empty, object, std::memory_order_release)) return;
        }
        Traits::destroy(object);
    }

    /// An object taken for a scope and given back at its end.
    class Lease {
    public:
        explicit Lease(KeptObjects& kept) : kept_(kept), object_(kept.take()) {}
        Lease(const Lease&) = delete;
        Lease& operator=(const Lease&) = delete;
        ~Lease() { kept_.give(object_); }
        T* get() const { return object_; }

    private:
        KeptObjects& kept_;
        T* object_;
    };

private:
    std::array<std::atomic<T*>, 4> slots_{};
};

}  // namespace dsm::detail
