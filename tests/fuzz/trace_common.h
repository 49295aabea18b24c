#pragma once
// What the trace targets share: a trace read from untrusted bytes, then what `brickyard replay`
// and `cachebench` do with one: its summaries, each object's next access, and a replay through
// every policy at a capacity below its working set.

#include <cstdio>
#include <cstdlib>
#include <string>

#include "cache/policy.h"
#include "cache/replay.h"
#include "cache/trace.h"
#include "tests/fuzz/fuzz_util.h"

namespace brickyard::fuzz {

inline int run_trace(const uint8_t* data, size_t size, const char* name, TraceFormat format) {
  const std::string path = write_temp(name, data, size);
  return run_one([&] {
    const Trace t = read_trace(path, format);
    (void)t.unique_objects();
    (void)t.frames();
    (void)t.record_kinds();
    if (t.records.size() > 4096) return;  // replays of long traces are the benchmark's, not ours
    const std::vector<uint64_t> ids = object_ids(t);
    const std::vector<uint64_t> next = next_demand_access(t, ids);
    const uint64_t capacity = t.unique_bytes() / 2 + 1;
    for (const std::string& policy : policy_names()) {
      const ReplayResult r = replay(t, next, policy, capacity);
      if (r.misses > r.requests) {
        std::fprintf(stderr, "fuzz: %s replays %llu misses of %llu requests\n", policy.c_str(),
                     static_cast<unsigned long long>(r.misses), static_cast<unsigned long long>(r.requests));
        std::abort();
      }
    }
  });
}

}  // namespace brickyard::fuzz
