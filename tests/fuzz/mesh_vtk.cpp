// Legacy VTK files (.vtk, UNSTRUCTURED_GRID, ASCII or BINARY): read_legacy_vtk over untrusted bytes.
// Then tetrahedralize(), as import-mesh runs it (tests/fuzz/mesh_common.h).

#include "tests/fuzz/mesh_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return brickyard::fuzz::run_mesh(data, size, {"mesh.vtk"}, brickyard::read_legacy_vtk);
}
