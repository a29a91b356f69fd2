// How library code reaches the private insides of public classes (internal).
// A public class with a pimpl names ImplAccess as a friend and offers no
// accessor of its own; library code writes ImplAccess::of(object) for the
// Impl, and ImplAccess::Impl<Class> or ImplAccess::Nested... for the types.
#pragma once

#include <type_traits>
#include <utility>

#include "dsm/version.h"

DSM_NAMESPACE_BEGIN

class ImplAccess {
public:
    // The types are named inside member declarations (where friendship grants
    // access) and handed out through decltype: clang checks an alias
    // template's access where it is used, not where it is declared.
    template <typename T>
    static auto implPointer() -> typename T::Impl*;
    template <typename T>
    static auto tileOwnerPointer() -> typename T::TileOwner*;

    template <typename T>
    using Impl = std::remove_pointer_t<decltype(implPointer<T>())>;

    template <typename T>
    static const typename T::Impl& of(const T& object) {
        return *object.impl_;
    }
    template <typename T>
    static typename T::Impl& of(T& object) {
        return *object.impl_;
    }

    /// The opaque keep-alive handle of a PixelFunction.
    template <typename T>
    using TileOwner = std::remove_pointer_t<decltype(tileOwnerPointer<T>())>;

    /// Calls a private constructor of T.
    template <typename T, typename... Args>
    static T make(Args&&... args) {
        return T(std::forward<Args>(args)...);
    }
};

DSM_NAMESPACE_END
