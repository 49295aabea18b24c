// Raw-volume sidecars (core/raw_volume.h, FILE.raw.json): read_raw_sidecar over untrusted
// JSON. What it accepts must be consistent: a byte count that matches its dims and type, and
// a sidecar that, written back (write_raw_sidecar), reads back to the same description.

#include <cstdio>
#include <cstdlib>

#include "core/raw_volume.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz::write_temp("volume.raw.json", data, size);
  return fuzz::run_one([&] {
    const RawVolumeInfo info = read_raw_sidecar(path);
    const auto bytes = checked_grid_bytes(info.dims, info.type);
    if (!bytes || *bytes != info.bytes) {
      std::fprintf(stderr, "fuzz: an accepted sidecar's byte count does not match its dims\n");
      std::abort();
    }
    const std::string again = (fuzz::temp_dir() / "again.raw.json").string();
    write_raw_sidecar(again, info);
    try {
      const RawVolumeInfo back = read_raw_sidecar(again);
      if (back.dims != info.dims || back.type != info.type || back.bytes != info.bytes || back.xxh3_64 != info.xxh3_64) {
        std::fprintf(stderr, "fuzz: a sidecar written back reads as another volume\n");
        std::abort();
      }
    } catch (const Error& e) {
      std::fprintf(stderr, "fuzz: an accepted sidecar, written back, is refused: %s\n", e.what());
      std::abort();
    }
  });
}
