// VTK XML unstructured grids (.vtu: ASCII, base64, appended, zlib): read_vtu over untrusted bytes.
// Then tetrahedralize(), as import-mesh runs it (tests/fuzz/mesh_common.h).

#include "tests/fuzz/mesh_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return brickyard::fuzz::run_mesh(data, size, {"mesh.vtu"}, brickyard::read_vtu);
}
