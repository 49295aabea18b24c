// TetGen meshes (.node and .ele): read_tetgen over an untrusted pair (the input is the two files
// joined by kFileSeparator).
// Then tetrahedralize(), as import-mesh runs it (tests/fuzz/mesh_common.h).

#include "tests/fuzz/mesh_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return brickyard::fuzz::run_mesh(data, size, {"mesh.node", "mesh.ele"}, brickyard::read_tetgen);
}
