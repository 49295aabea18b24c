#pragma once
/// @file module.h
/// @brief A back end built outside the tree, as a shared library (a module), as OSPRay loads
/// its modules with ospLoadModule. The module defines its entry point with BRICKYARD_MODULE and
/// registers its back ends there; `brickyard --module PATH.so` (or BRICKYARD_MODULES) loads it
/// before any scene is opened (session/modules.h), and its back ends are then chosen by name
/// like the built-in ones:
///
///   #include <brickyard/renderers/common/module.h>
///   BRICKYARD_MODULE(registry) { registry.add(my_backend()); }
///
/// A module is built against the installed package (find_package(brickyard), target
/// brickyard::module) and links no brickyard library: it uses the host's (the brickyard
/// executable exports them), so it must come from the same brickyard version and compiler.
/// kModuleApiVersion guards the first: a module built for another one is refused by name.

#include "renderers/common/renderer.h"

namespace brickyard {

/// @brief Bumped whenever the interface a module compiles against (renderer.h, the cache, the
/// dataset views) changes in a way old modules cannot survive.
inline constexpr int kModuleApiVersion = 2;  // 2: BackendInfo::pixel_state_bytes

}  // namespace brickyard

/// Defines the module's entry point, brickyard_module_init: the host passes its API version
/// and registry; a module built for another version returns its own and registers nothing.
#define BRICKYARD_MODULE(registry)                                                                  \
  static void brickyard_module_register(::brickyard::BackendRegistry& registry);                    \
  extern "C" __attribute__((visibility("default"))) int brickyard_module_init(                      \
      int api_version, ::brickyard::BackendRegistry* host_registry) {                               \
    if (api_version != ::brickyard::kModuleApiVersion) return ::brickyard::kModuleApiVersion;        \
    brickyard_module_register(*host_registry);                                                      \
    return 0;                                                                                       \
  }                                                                                                 \
  static void brickyard_module_register(::brickyard::BackendRegistry& registry)
