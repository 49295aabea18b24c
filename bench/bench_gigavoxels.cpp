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
//   GigavoxelsBrickLayout/L/step:S/rays:K      DVR sample runs along the rays of the bench
//                                              scene's view of a 1024^3 volume of 34^3 u16
//                                              bricks in a 2.6 GB pool, on 2 threads: the
//                                              pool's rows (L = rows, the renderer's corner
//                                              gathers) or 64-byte 4x4x2 tiles (L = tiles), a
//                                              step of S voxels, K rays of a thread marched in
//                                              turn; ns/sample/core
//
//   build/bench/bench_gigavoxels

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <random>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "bench_util.h"
#include "core/parallel.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/gigavoxels/corner_lanes.h"
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

// --- brick layout: what a brick pool's voxel order costs the DVR sample runs -------------

/// A pool of the 32^3 bricks (M = 32, 34^3 voxels with the apron) of a 1024^3 u16 volume at
/// shuffled slots, as the renderer's pool holds fBm 1024^3: voxel rows along x (the
/// renderer's layout), or 4x4x2 tiles of 32 voxels, one 64-byte cache line each, over
/// 36x36x34 voxels. Values are a ramp of the volume coordinates: only the order matters.
struct LayoutPool {
  static constexpr int kM = 32, kEdge = kM + 2, kBricks = 32;  // bricks per axis
  static constexpr int kTilesX = 9, kTilesY = 9, kTilesZ = 17;
  static constexpr int64_t kRowVoxels = int64_t(kEdge) * kEdge * kEdge;
  static constexpr int64_t kTileVoxels = int64_t(kTilesX) * kTilesY * kTilesZ * 32;

  bool tiled;
  int64_t brick_voxels;
  std::vector<int32_t> slot;
  std::unique_ptr<uint16_t[]> voxels;

  static int32_t row_index(int x, int y, int z) { return (z * kEdge + y) * kEdge + x; }
  static int32_t tile_index(int x, int y, int z) {
    return ((((z >> 1) * kTilesY + (y >> 2)) * kTilesX + (x >> 2)) << 5) | ((z & 1) << 4) | ((y & 3) << 2) | (x & 3);
  }

  explicit LayoutPool(bool tiles)
      : tiled(tiles), brick_voxels(tiles ? kTileVoxels : kRowVoxels), slot(size_t(kBricks) * kBricks * kBricks) {
    const int64_t count = int64_t(slot.size());
    // + 2 voxels: a row gather's 32-bit read of the last voxel's pair.
    voxels.reset(new uint16_t[size_t(count * brick_voxels + 2)]());
    for (int32_t i = 0; i < int32_t(count); ++i) slot[size_t(i)] = i;
    std::shuffle(slot.begin(), slot.end(), std::mt19937(7));
    brickyard::parallel_for<int64_t>(0, count, 64, [&](int64_t b0, int64_t b1) {
      for (int64_t b = b0; b < b1; ++b) {
        const int bx = int(b % kBricks), by = int(b / kBricks % kBricks), bz = int(b / (kBricks * kBricks));
        uint16_t* brick = voxels.get() + slot[size_t(b)] * brick_voxels;
        for (int z = 0; z < kEdge; ++z)
          for (int y = 0; y < kEdge; ++y)
            for (int x = 0; x < kEdge; ++x)
              brick[tiled ? tile_index(x, y, z) : row_index(x, y, z)] =
                  uint16_t((bx * kM + x) * 7 + (by * kM + y) * 13 + (bz * kM + z) * 29);
      }
    });
  }

  /// The 8 corners (dx + 2 dy + 4 dz) of 8 cells of one brick: the renderer's row gathers,
  /// or one 32-bit gather a corner in tiles (a pair along x may straddle two tiles).
  void corners(const uint16_t* brick, const int32_t (&cell)[3][8], float (&corner)[8][8]) const {
    if (!tiled) {
      int32_t offset[8];
      for (int k = 0; k < 8; ++k) offset[k] = row_index(cell[0][k], cell[1][k], cell[2][k]);
      load_cell_corners(brick, offset, kEdge, corner);
      return;
    }
    for (int c = 0; c < 8; ++c) {
      int32_t offset[8];
      for (int k = 0; k < 8; ++k) offset[k] = tile_index(cell[0][k] + (c & 1), cell[1][k] + (c >> 1 & 1), cell[2][k] + (c >> 2));
#if defined(__AVX2__)
      __m256i at;
      std::memcpy(&at, offset, sizeof at);
      const __m256i value = _mm256_and_si256(_mm256_i32gather_epi32(reinterpret_cast<const int*>(brick), at, 2),
                                             _mm256_set1_epi32(0xffff));
      _mm256_storeu_ps(corner[c], _mm256_cvtepi32_ps(value));
#else
      for (int k = 0; k < 8; ++k) corner[c][k] = float(brick[offset[k]]);
#endif
    }
  }
};

/// The pool of the layout asked for; the other one is freed first (2.6 GB each).
const LayoutPool& layout_pool(bool tiled) {
  static std::unique_ptr<LayoutPool> pool;
  if (!pool || pool->tiled != tiled) {
    pool.reset();
    pool = std::make_unique<LayoutPool>(tiled);
  }
  return *pool;
}

/// One ray of the view, in voxels of the 1024^3 volume.
struct LayoutRay {
  float org[3], dir[3];
  float t, t_end;
  float sum = 0;
};

/// The bench DVR scene's camera (eye (1.6, -1.1, 1.4), target (0.5, 0.5, 0.45), 35 degrees)
/// at 512x512, each ray's first 320 voxels inside the volume (about where that scene's rays
/// reach full opacity), in 8x8-pixel tiles.
std::vector<std::vector<LayoutRay>> layout_view_tiles() {
  constexpr int kSize = 512, kTile = 8;
  constexpr double kVolume = 1024, kPath = 320;
  const double eye[3] = {1.6 * kVolume, -1.1 * kVolume, 1.4 * kVolume};
  const double target[3] = {0.5 * kVolume, 0.5 * kVolume, 0.45 * kVolume};
  auto normalize = [](double (&v)[3]) {
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (double& x : v) x /= n;
  };
  double forward[3], right[3], up[3];
  for (int a = 0; a < 3; ++a) forward[a] = target[a] - eye[a];
  normalize(forward);
  right[0] = forward[1], right[1] = -forward[0], right[2] = 0;  // forward x (0, 0, 1)
  normalize(right);
  up[0] = right[1] * forward[2] - right[2] * forward[1];
  up[1] = right[2] * forward[0] - right[0] * forward[2];
  up[2] = right[0] * forward[1] - right[1] * forward[0];
  const double half = std::tan(35.0 / 2 * M_PI / 180);
  std::vector<std::vector<LayoutRay>> tiles;
  for (int ty = 0; ty < kSize; ty += kTile)
    for (int tx = 0; tx < kSize; tx += kTile) {
      std::vector<LayoutRay>& tile = tiles.emplace_back();
      for (int y = ty; y < ty + kTile; ++y)
        for (int x = tx; x < tx + kTile; ++x) {
          const double sx = (2 * (x + 0.5) / kSize - 1) * half, sy = (1 - 2 * (y + 0.5) / kSize) * half;
          double dir[3];
          for (int a = 0; a < 3; ++a) dir[a] = forward[a] + sx * right[a] + sy * up[a];
          normalize(dir);
          double t0 = 0, t1 = kVolume * 4;
          for (int a = 0; a < 3; ++a) {
            double near = -eye[a] / dir[a], far = (kVolume - eye[a]) / dir[a];
            if (near > far) std::swap(near, far);
            t0 = std::max(t0, near), t1 = std::min(t1, far);
          }
          if (t0 >= t1) continue;
          LayoutRay& ray = tile.emplace_back();
          for (int a = 0; a < 3; ++a) ray.org[a] = float(eye[a]), ray.dir[a] = float(dir[a]);
          ray.t = float(t0), ray.t_end = float(std::min(t1, t0 + kPath));
        }
    }
  return tiles;
}

/// One run of up to 8 samples, step h, in the brick of the ray's next sample (as sample_run
/// ends a run at the node's face); the ray moves on past the samples taken. Returns them.
int layout_run(const LayoutPool& pool, LayoutRay& ray, float h) {
  constexpr int M = LayoutPool::kM;
  int brick[3];
  for (int a = 0; a < 3; ++a) brick[a] = std::clamp(int(ray.org[a] + ray.dir[a] * ray.t), 0, 1023) / M;
  const uint16_t* voxels =
      pool.voxels.get() + pool.slot[size_t((brick[2] * LayoutPool::kBricks + brick[1]) * LayoutPool::kBricks + brick[0])] * pool.brick_voxels;
  int32_t cell[3][8];
  float u[3][8];
  int n = 8;
  for (int k = 0; k < 8; ++k) {
    const float t = ray.t + float(k) * h;
    for (int a = 0; a < 3; ++a) {
      const float l = ray.org[a] + ray.dir[a] * t - float(brick[a] * M) + 1;  // brick coordinates
      if (k > 0 && k < n && !(l >= 0.5f && l < float(M) + 1.5f)) n = k;      // past the brick's face
      const float x = std::clamp(l, 0.0f, float(LayoutPool::kEdge - 1));
      cell[a][k] = std::min(int(x), LayoutPool::kEdge - 2);
      u[a][k] = x - float(cell[a][k]);
    }
  }
  float corner[8][8];
  pool.corners(voxels, cell, corner);
  float sum = 0;
  for (int k = 0; k < n; ++k) {
    float c[8];
    for (int i = 0; i < 8; ++i) c[i] = corner[i][k];
    sum += brickyard::trilinear(c, u[0][k], u[1][k], u[2][k]);
  }
  ray.sum += sum;
  // The next position waits on this run's values, as the renderer's adaptive step and leaps do.
  ray.t += float(n) * h + 0.0f * ray.sum;
  return n;
}

void brick_layout_benchmark(benchmark::State& state, bool tiled, float h, int interleaved) {
  constexpr int kThreads = 2;
  const LayoutPool& pool = layout_pool(tiled);
  const std::vector<std::vector<LayoutRay>> view = layout_view_tiles();
  tbb::task_arena arena(kThreads);
  std::atomic<int64_t> samples{0};
  std::atomic<double> value_sum{0};
  for (auto _ : state) {
    arena.execute([&] {
      brickyard::parallel_for<size_t>(0, view.size(), 1, [&](size_t t0, size_t t1) {
        int64_t taken = 0;
        double sum = 0;
        for (size_t t = t0; t < t1; ++t) {
          std::vector<LayoutRay> rays = view[t];
          for (size_t first = 0; first < rays.size(); first += size_t(interleaved)) {
            const size_t last = std::min(rays.size(), first + size_t(interleaved));
            for (bool any = true; any;) {
              any = false;
              for (size_t i = first; i < last; ++i)
                if (rays[i].t < rays[i].t_end) taken += layout_run(pool, rays[i], h), any = true;
            }
            for (size_t i = first; i < last; ++i) sum += rays[i].sum;
          }
        }
        samples += taken;
        value_sum += sum;
      });
    });
  }
  state.counters["samples/frame"] = double(samples.load()) / double(state.iterations());
  // Core-seconds per sample: wall time per sample times the threads.
  state.counters["s/sample/core"] =
      benchmark::Counter(double(samples.load()) / kThreads, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  // The same in both layouts (they hold the same values): that the tiles' corners are right.
  state.counters["mean_value"] = value_sum.load() / double(samples.load());
}

void register_brick_layout() {
  for (bool tiled : {false, true})
    for (int step : {1, 2, 16})
      for (int rays : {1, 2})
        benchmark::RegisterBenchmark(fmt::format("GigavoxelsBrickLayout/{}/step:{}/rays:{}", tiled ? "tiles" : "rows", step, rays).c_str(),
                                     brick_layout_benchmark, tiled, float(step), rays)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
}

void register_all() {
  register_feedback();
  register_brick_layout();
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
