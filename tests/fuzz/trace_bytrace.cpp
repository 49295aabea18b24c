// Access traces (cache/trace.h), format brickyard (trace.bytrace): read_trace over untrusted bytes,
// then replayed through every policy (tests/fuzz/trace_common.h).

#include "tests/fuzz/trace_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return brickyard::fuzz::run_trace(data, size, "trace.bytrace", brickyard::TraceFormat::brickyard);
}
