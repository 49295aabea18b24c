// The built-in back ends. Adding one: a folder renderers/NAME/ (its .cpp files are built
// automatically) defining `BackendEntry NAME_backend()` in namespace brickyard, and one line
// X(NAME) below.

#include "renderers/common/renderer.h"

#define BRICKYARD_BACKENDS(X) \
  X(reference)                \
  X(raymarch)                 \
  X(gobbetti)                 \
  X(gigavoxels)                \
  X(octree_cgt)                \
  X(tet_bvh)

namespace brickyard {

#define BRICKYARD_DECLARE(name) BackendEntry name##_backend();
BRICKYARD_BACKENDS(BRICKYARD_DECLARE)
#undef BRICKYARD_DECLARE

const BackendRegistry& builtin_backends() {
  static const BackendRegistry registry = [] {
    BackendRegistry r;
#define BRICKYARD_REGISTER(name) r.add(name##_backend());
    BRICKYARD_BACKENDS(BRICKYARD_REGISTER)
#undef BRICKYARD_REGISTER
    return r;
  }();
  return registry;
}

BackendRegistry& backends() {
  static BackendRegistry registry = builtin_backends();
  return registry;
}

}  // namespace brickyard
