// gmsh meshes (.msh 2.2 and 4.1, ASCII or binary, $NodeData): read_gmsh over untrusted bytes.
// Then tetrahedralize(), as import-mesh runs it (tests/fuzz/mesh_common.h).

#include "tests/fuzz/mesh_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return brickyard::fuzz::run_mesh(data, size, {"mesh.msh"}, brickyard::read_gmsh);
}
