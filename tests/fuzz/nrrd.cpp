// NRRD volumes (preprocess/volume_source.h, open_nrrd_source): the header reader over untrusted
// text, then the data as the builder reads it, slab by slab in z (raw or gzip, attached or in a
// detached file, native or converted types), for volumes of a size a fuzzer can write.
//
// Input: the .nrrd file; optionally kFileSeparator and then a detached data file, written
// beside it as "data.raw" (a header's "data file: data.raw" reads it).

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "core/raw_volume.h"
#include "preprocess/volume_source.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto parts = fuzz::split({reinterpret_cast<const char*>(data), size}, fuzz::kFileSeparator, 2);
  const std::string path = fuzz::write_temp("volume.nrrd", parts[0]);
  fuzz::write_temp("data.raw", parts[1]);
  return fuzz::run_one([&] {
    auto source = open_nrrd_source(path);
    const Vec3s d = source->dims();
    const auto total = checked_grid_bytes(d, source->type());
    if (!total) {  // the reader must refuse empty volumes and byte counts that overflow
      std::fprintf(stderr, "fuzz: an accepted NRRD header has dims %ldx%ldx%ld\n", long(d.x), long(d.y), long(d.z));
      std::abort();
    }
    if (*total > (uint64_t(1) << 24)) return;  // too big to read here
    const uint64_t slice = *total / uint64_t(d.z);
    (void)source->describe_json();
    std::vector<std::byte> slab;
    for (int pass = 0; pass < 2; ++pass) {
      for (int64_t z = 0; z < d.z; z += 4) {
        const int64_t z1 = std::min(d.z, z + 4);
        slab.resize(size_t(slice) * size_t(z1 - z));
        source->read_slab(z, z1, slab);
      }
      source->rewind();
    }
  });
}
