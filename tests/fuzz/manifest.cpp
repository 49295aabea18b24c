// A store's manifest (storage/manifest.h): Manifest::from_json over untrusted text, as a store
// whose manifest was damaged or hand-edited hands it over (its checksum is optional). What it
// accepts must be usable: the grid layout it implies, its histogram, and a round trip through
// to_json() that reads back to the same text.

#include <cstdio>
#include <cstdlib>
#include <string>

#include "storage/manifest.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  return fuzz::run_one([&] {
    const Manifest m = Manifest::from_json(text, "fuzz/store");
    if (m.kind == DataKind::structured) {
      const GridLayout layout = m.layout();
      (void)layout.total_bricks();
      (void)m.format.bytes();
      (void)m.histogram.quantile(0.5);
    }
    const std::string again = m.to_json();
    std::string twice;
    try {
      twice = Manifest::from_json(again, "fuzz/store (written back)").to_json();
    } catch (const Error& e) {
      std::fprintf(stderr, "fuzz: a manifest that was accepted does not read back after to_json(): %s\n", e.what());
      std::abort();
    }
    if (twice != again) {
      std::fprintf(stderr, "fuzz: a manifest's to_json() changes on a round trip:\n%s\n---\n%s\n", again.c_str(), twice.c_str());
      std::abort();
    }
  });
}
