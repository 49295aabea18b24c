// ParaView collections (.pvd): read_pvd over an untrusted collection and the .vtu files it may name
// ("a.vtu", "b.vtu"; the input is the three files joined by kFileSeparator).
// Then tetrahedralize(), as import-mesh runs it (tests/fuzz/mesh_common.h).

#include "tests/fuzz/mesh_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return brickyard::fuzz::run_mesh(data, size, {"mesh.pvd", "a.vtu", "b.vtu"}, brickyard::read_pvd);
}
