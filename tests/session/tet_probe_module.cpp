// The tet-probe test back end (tet_fixture.h) as a module: built as a shared library that links
// no brickyard library, loaded into the brickyard executable by --module.

#include "renderers/common/module.h"
#include "tet_fixture.h"

BRICKYARD_MODULE(registry) { registry.add(brickyard::testing::tet_probe_backend()); }
