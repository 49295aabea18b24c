// Generation throughput of every procedural field: voxels per second per core, single- and
// multi-threaded, for f32 and u8 grids. Run: build/bench/bench_fields [--benchmark_out=x.csv
// --benchmark_out_format=csv]. Figures are reported, never asserted.

#include <benchmark/benchmark.h>

#include "bench_util.h"

#include <vector>

#include <tbb/task_arena.h>

#include "fields/field.h"
#include "fields/grid.h"

namespace {

using namespace brickyard;

// Samples one 128^2 x 16 slab per iteration, inside an arena of `threads` threads.
void BM_Generate(benchmark::State& state, const std::string& field_name, ValueType type) {
  const int threads = static_cast<int>(state.range(0));
  auto field = make_field(field_name);
  const Vec3s dims{128, 128, 128};
  GridSampler sampler(*field, dims, type);
  const int64_t slab = 16;
  std::vector<std::byte> out(size_t(slab) * sampler.slice_bytes());
  tbb::task_arena arena(threads);
  int64_t z0 = 0;
  for (auto _ : state) {
    arena.execute([&] { sampler.sample_slab(z0, z0 + slab, out); });
    benchmark::DoNotOptimize(out.data());
    z0 = (z0 + slab) % dims.z;
  }
  const double voxels = double(state.iterations()) * double(dims.x * dims.y * slab);
  state.counters["voxels/s"] = benchmark::Counter(voxels, benchmark::Counter::kIsRate);
  state.counters["voxels/s/core"] = benchmark::Counter(voxels / threads, benchmark::Counter::kIsRate);
  state.SetBytesProcessed(int64_t(voxels) * int64_t(size_of(type)));
}

void register_all() {
  for (const auto& name : field_names())
    for (ValueType type : {ValueType::f32, ValueType::u8}) {
      const std::string label = "Generate/" + name + "/" + std::string(to_string(type));
      benchmark::RegisterBenchmark(label.c_str(), BM_Generate, name, type)
          ->Arg(1)
          ->Arg(2)
          ->ArgName("threads")
          ->UseRealTime()
          ->Unit(benchmark::kMillisecond);
    }
}

}  // namespace

int main(int argc, char** argv) { return brickyard::bench::run_benchmarks(argc, argv, register_all); }
