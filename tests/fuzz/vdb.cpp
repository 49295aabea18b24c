// OpenVDB import (preprocess/volume_source.h, open_vdb_source): an untrusted .vdb file through
// the importer's entry (OpenVDB's own reader underneath), then, for grids of a size a fuzzer
// can write, its voxels slab by slab as the builder reads them. The only target that needs
// OpenVDB (the importer's library brings it).

#include <algorithm>
#include <vector>

#include "core/raw_volume.h"
#include "preprocess/volume_source.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz::write_temp("grid.vdb", data, size);
  return fuzz::run_one([&] {
    auto source = open_vdb_source(path, "");
    const Vec3s d = source->dims();
    const auto total = checked_grid_bytes(d, source->type());
    if (!total || *total > (uint64_t(1) << 24)) return;
    const uint64_t slice = *total / uint64_t(d.z);
    std::vector<std::byte> slab;
    for (int64_t z = 0; z < d.z; z += 8) {
      const int64_t z1 = std::min(d.z, z + 8);
      slab.resize(size_t(slice) * size_t(z1 - z));
      source->read_slab(z, z1, slab);
    }
  });
}
