// A module built for another module API version: the host must refuse it by name, before it
// registers anything.

#include "renderers/common/module.h"

extern "C" __attribute__((visibility("default"))) int brickyard_module_init(int, brickyard::BackendRegistry*) {
  return brickyard::kModuleApiVersion + 98;
}
