#pragma once
// Shared by the benchmark programs: where generated inputs live, and a main() that registers
// the program's benchmarks first.

#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace brickyard::bench {

/// @brief $BRICKYARD_BENCH_DIR, default /tmp/brickyard-bench: inputs generated once, reused.
inline std::string bench_dir() {
  const char* env = std::getenv("BRICKYARD_BENCH_DIR");
  std::string dir = env ? env : "/tmp/brickyard-bench";
  std::filesystem::create_directories(dir);
  return dir;
}

/// @brief Whether $BRICKYARD_BENCH_LARGE is set: the programs then add their large inputs
/// (1024^3 stores, gigabyte pools) to the default ones.
inline bool large_inputs() { return std::getenv("BRICKYARD_BENCH_LARGE") != nullptr; }

inline int run_benchmarks(int argc, char** argv, void (*register_all)()) {
  register_all();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

}  // namespace brickyard::bench
