// The `gigavoxels` procedural brick producers: what one brick costs the loader. Figures are
// reported, never asserted.
//
//   GigavoxelsProcedural/Menger/M:N            produce() of the shared Menger brick, (N+2)^3
//                                              floats (a copy); bricks/s and MB/s
//   GigavoxelsProcedural/Amplified/octaves:K   produce() of a 34^3 amplified brick (M = 32) K
//                                              depths below the stored depth, so K noise
//                                              octaves per voxel, on top of a trilinear coarse
//                                              sampler over a 64^3 grid; bricks/s
//   GigavoxelsProcedural/MengerClassify        classify() of random depth-39 nodes
//   GigavoxelsFeedback/Record/threads:T        begin_frame() and recording every ray of a
//                                              512x512 frame with K = 4 and coherent lists
//                                              (16 to 23 nodes per ray); pixels/s per core
//   GigavoxelsFeedback/TraceOnly               the same node ids with no recording, the part
//                                              of Record that is not the recorder's
//   GigavoxelsFeedback/Compact/threads:T       compacting that frame's buffer; pixels/s per
//                                              core and the fraction of entries removed
//
//   build/bench/bench_gigavoxels

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "bench_util.h"
#include "core/parallel.h"
#include "renderers/gigavoxels/feedback.h"
#include "renderers/gigavoxels/procedural.h"

namespace {

using namespace brickyard::gigavoxels;

void menger_benchmark(benchmark::State& state) {
  const MengerProducer menger(int(state.range(0)));
  const size_t E = size_t(menger.brick_size() + 2);
  std::vector<float> out(E * E * E);
  const NodeAddress node{5, 0, 2, 20};
  for (auto _ : state) {
    menger.produce(node, out.data());
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(int64_t(state.iterations()));
  state.SetBytesProcessed(int64_t(state.iterations()) * int64_t(out.size() * sizeof(float)));
}

void menger_classify_benchmark(benchmark::State& state) {
  const MengerProducer menger;
  std::mt19937_64 rng(1);
  std::uniform_int_distribution<int64_t> coord(0, 4052555153018976266);  // 3^39 - 1
  std::vector<NodeAddress> nodes(4096);
  for (NodeAddress& n : nodes) n = {39, coord(rng), coord(rng), coord(rng)};
  size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(menger.classify(nodes[i++ & 4095]));
  }
  state.SetItemsProcessed(int64_t(state.iterations()));
}

/// A stored 64^3 volume sampled trilinearly, like the cache-backed sampler the renderer uses.
struct TrilinearGrid {
  static constexpr int kSize = 64;
  std::vector<float> values;
  TrilinearGrid() : values(size_t(kSize) * kSize * kSize) {
    for (int k = 0; k < kSize; ++k)
      for (int j = 0; j < kSize; ++j)
        for (int i = 0; i < kSize; ++i)
          values[(size_t(k) * kSize + size_t(j)) * kSize + size_t(i)] =
              float(0.5 + 0.4 * std::sin(0.2 * i) * std::cos(0.15 * j) * std::sin(0.1 * k + 1));
  }
  float operator()(double ux, double uy, double uz) const {
    auto axis = [](double u, int& i0, double& t) {
      const double x = std::clamp(u * kSize - 0.5, 0.0, kSize - 1.0);
      i0 = std::min(int(x), kSize - 2);
      t = x - i0;
    };
    int i, j, k;
    double tx, ty, tz;
    axis(ux, i, tx);
    axis(uy, j, ty);
    axis(uz, k, tz);
    auto at = [&](int di, int dj, int dk) {
      return double(values[(size_t(k + dk) * kSize + size_t(j + dj)) * kSize + size_t(i + di)]);
    };
    auto lerp = [](double a, double b, double t) { return a + t * (b - a); };
    return float(lerp(lerp(lerp(at(0, 0, 0), at(1, 0, 0), tx), lerp(at(0, 1, 0), at(1, 1, 0), tx), ty),
                      lerp(lerp(at(0, 0, 1), at(1, 0, 1), tx), lerp(at(0, 1, 1), at(1, 1, 1), tx), ty), tz));
  }
};

void amplified_benchmark(benchmark::State& state) {
  const int octaves = int(state.range(0));
  AmplifiedParams params;
  params.brick_size = 32;
  params.stored_depth = 1;  // 64^3 voxels stored in 2^3 bricks of 32^3
  params.max_depth = params.stored_depth + std::max(octaves, 3);
  params.amplitude = 0.1;
  params.gain = 0.5;
  const TrilinearGrid grid;
  const AmplifiedProducer amp([&grid](double x, double y, double z) { return grid(x, y, z); }, params);
  const int depth = params.stored_depth + octaves;
  const int64_t mid = (int64_t(1) << depth) / 2;
  const NodeAddress node{depth, mid, mid / 2, mid + 1 < (int64_t(1) << depth) ? mid + 1 : 0};
  std::vector<float> out(34 * 34 * 34);
  for (auto _ : state) {
    amp.produce(node, out.data());
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(int64_t(state.iterations()));
  state.counters["voxels/s"] = benchmark::Counter(double(state.iterations()) * double(out.size()),
                                                  benchmark::Counter::kIsRate);
}

// --- feedback: recording and compaction of one frame's use buffer ---------------------

/// A 512x512 frame's ray lists, coherent as an octree descent makes them: six levels of descent
/// shared by ever smaller pixel squares (the root by all, the last by 16x16 pixels), then 10 to
/// 17 fine nodes shared by 4x4-pixel tiles, each reported for two samples (an immediate repeat).
/// Every 4x4 tile's pixels on one diagonal request the same node, with a tag bit. The node ids
/// are computed while recording, as a renderer computes its node addresses, so that the
/// benchmark measures the recorder rather than streaming stored lists from memory.
struct FrameLists {
  static constexpr int kSize = 512;
  static uint32_t fine_count(uint32_t tile) { return 10 + (tile * 2654435761u >> 29); }
  static uint32_t fine_node(uint32_t tile, uint32_t s) { return 4096 + tile * 32 + s; }

  template <typename Recorder>
  static void trace(int x, int y, Recorder& rec) {
    uint32_t base = 0;
    for (int level = 0; level < 6; ++level) {
      const int shift = 9 - level;
      rec.used(base + uint32_t((y >> shift) << level) + uint32_t(x >> shift));
      base += uint32_t(1) << (2 * level);
    }
    const uint32_t tile = uint32_t((y / 4) * (kSize / 4) + x / 4);
    const uint32_t fine = fine_count(tile);
    for (uint32_t s = 0; s < fine; ++s) {
      rec.used(fine_node(tile, s));
      rec.used(fine_node(tile, s));
    }
    if (x % 4 == y % 4) rec.request(0x80000000u | fine_node(tile, fine));
  }

  static void record(UseBuffer& buffer) {
    brickyard::parallel_for<int>(0, kSize, 8, [&](int y0, int y1) {
      for (int y = y0; y < y1; ++y)
        for (int x = 0; x < kSize; ++x) {
          RayRecorder rec = buffer.recorder(x, y);
          trace(x, y, rec);
          rec.finish();
        }
    });
  }

  /// Distinct-consecutive uses per pixel, averaged over the frame.
  static double uses_per_pixel() {
    double sum = 0;
    for (uint32_t tile = 0; tile < uint32_t(kSize / 4) * uint32_t(kSize / 4); ++tile)
      sum += 16.0 * (6 + fine_count(tile));
    return sum / (double(kSize) * kSize);
  }
};

/// The same ids with no recording: what trace() itself costs, to subtract from Record.
struct NullRecorder {
  uint32_t sum = 0;
  void used(uint32_t e) { sum += e; }
  void request(uint32_t e) { sum ^= e; }
};

constexpr double kPixels = double(FrameLists::kSize) * FrameLists::kSize;

void per_pixel_counters(benchmark::State& state, int threads) {
  const double pixels = double(state.iterations()) * kPixels;
  state.counters["pixels/s/core"] = benchmark::Counter(pixels / threads, benchmark::Counter::kIsRate);
  // Core-seconds per pixel: wall time per pixel times the threads.
  state.counters["s/pixel/core"] =
      benchmark::Counter(pixels / threads, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

/// begin_frame() and every ray of the frame recorded, rows spread over `threads` threads.
void feedback_record_benchmark(benchmark::State& state) {
  const int threads = int(state.range(0));
  UseBuffer buffer(FrameLists::kSize, FrameLists::kSize, 4);
  tbb::task_arena arena(threads);
  uint64_t frame = 0;
  arena.execute([&] {  // warm-up: page in the buffer and the recorders' spill pools
    buffer.begin_frame(frame++);
    FrameLists::record(buffer);
  });
  for (auto _ : state) {
    arena.execute([&] {
      buffer.begin_frame(frame++);
      FrameLists::record(buffer);
    });
    benchmark::DoNotOptimize(buffer.entries().data());
  }
  per_pixel_counters(state, threads);
  state.counters["uses/pixel"] = FrameLists::uses_per_pixel();
}

/// One compaction of a recorded frame (K = 4) on `threads` threads; what it removes.
void feedback_compact_benchmark(benchmark::State& state) {
  const int threads = int(state.range(0));
  UseBuffer buffer(FrameLists::kSize, FrameLists::kSize, 4);
  buffer.begin_frame(0);
  FrameLists::record(buffer);
  Compactor compactor;
  std::vector<uint32_t> uses, requests;
  tbb::task_arena arena(threads);
  CompactionReport report;
  arena.execute([&] { report = compactor.compact(buffer, uses, requests); });  // warm-up
  for (auto _ : state) {
    arena.execute([&] { report = compactor.compact(buffer, uses, requests); });
    benchmark::DoNotOptimize(uses.data());
  }
  per_pixel_counters(state, threads);
  const double used = double(report.uses.slots - report.uses.empty);
  const double requested = double(report.requests.slots - report.requests.empty);
  state.counters["uses_in"] = used;
  state.counters["uses_out"] = double(report.uses.out);
  state.counters["uses_removed"] = double(report.uses.local_duplicates) / used;
  // What a full (non-local) duplicate removal would leave: the rest is left to the loader.
  std::sort(uses.begin(), uses.end());
  state.counters["uses_distinct"] = double(std::unique(uses.begin(), uses.end()) - uses.begin());
  state.counters["requests_in"] = requested;
  state.counters["requests_out"] = double(report.requests.out);
  state.counters["requests_removed"] = double(report.requests.local_duplicates) / requested;
}

/// trace() alone on one thread: the share of Record that is not the recorder's.
void feedback_trace_only_benchmark(benchmark::State& state) {
  for (auto _ : state) {
    NullRecorder rec;
    for (int y = 0; y < FrameLists::kSize; ++y)
      for (int x = 0; x < FrameLists::kSize; ++x) FrameLists::trace(x, y, rec);
    benchmark::DoNotOptimize(rec.sum);
  }
  per_pixel_counters(state, 1);
}

void register_feedback() {
  benchmark::RegisterBenchmark("GigavoxelsFeedback/TraceOnly", feedback_trace_only_benchmark)
      ->UseRealTime()
      ->Unit(benchmark::kMillisecond);
  using Function = void (*)(benchmark::State&);
  for (auto [name, function] : {std::pair<const char*, Function>{"GigavoxelsFeedback/Record", feedback_record_benchmark},
                                {"GigavoxelsFeedback/Compact", feedback_compact_benchmark}})
    benchmark::RegisterBenchmark(name, function)
        ->Arg(1)
        ->Arg(2)
        ->ArgName("threads")
        ->UseRealTime()
        ->Unit(benchmark::kMillisecond);
}

void register_all() {
  register_feedback();
  for (int64_t M : {9, 27, 81})
    benchmark::RegisterBenchmark(fmt::format("GigavoxelsProcedural/Menger/M:{}", M).c_str(), menger_benchmark)
        ->Arg(M)
        ->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("GigavoxelsProcedural/MengerClassify", menger_classify_benchmark)
      ->Unit(benchmark::kNanosecond);
  for (int64_t octaves : {0, 1, 3, 10})
    benchmark::RegisterBenchmark(fmt::format("GigavoxelsProcedural/Amplified/octaves:{}", octaves).c_str(),
                                 amplified_benchmark)
        ->Arg(octaves)
        ->Unit(benchmark::kMicrosecond);
}

}  // namespace

int main(int argc, char** argv) { return brickyard::bench::run_benchmarks(argc, argv, register_all); }
