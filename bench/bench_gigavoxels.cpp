// The `gigavoxels` back end's parts: what a procedural brick costs the loader, what feedback
// recording and compaction cost a frame, and what the brick pool's voxel order costs its
// sample runs. Figures are reported, never asserted.
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
//   GigavoxelsBrickLayout/L/P/step:S/rays:K    (BRICKYARD_BENCH_LARGE=1 only: about 3 GB) DVR
//                                              sample runs along the rays of the bench DVR
//                                              scene's view of a 1024^3 volume of 34^3 u16
//                                              bricks, on 2 threads: voxel rows (L = rows, the
//                                              renderer's corner gathers) or 64-byte 4x4x2
//                                              tiles (L = tiles); every brick in a shuffled
//                                              pool (P = pool) or 8 bricks in cache (P =
//                                              resident); a step of S voxels; K rays of a
//                                              thread marched in turn; s/sample/core
//
//   build/bench/bench_gigavoxels
//   BRICKYARD_BENCH_LARGE=1 build/bench/bench_gigavoxels --benchmark_filter=BrickLayout

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <utility>
#include <vector>

#include <fmt/format.h>
#if defined(__AVX2__)
#include <immintrin.h>
#endif
#include <tbb/task_arena.h>

#include "bench_util.h"
#include "core/camera.h"
#include "core/parallel.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/render.h"
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
/// 36x36x34 voxels (12% more bytes). A resident pool keeps 8 bricks and maps every brick to
/// one of them, so that the same runs read a pool that fits in cache: what a run costs beside
/// its misses. Values are a ramp of the volume coordinates: only their order matters.
struct LayoutPool {
  static constexpr int kM = 32, kEdge = kM + 2, kBricks = 1024 / kM;  // bricks per axis
  static constexpr int kTilesX = (kEdge + 3) / 4, kTilesY = (kEdge + 3) / 4, kTilesZ = (kEdge + 1) / 2;
  static constexpr int kTileStride = 32;  // voxels: 64 bytes
  static constexpr int64_t kRowVoxels = int64_t(kEdge) * kEdge * kEdge;
  static constexpr int64_t kTileVoxels = int64_t(kTilesX) * kTilesY * kTilesZ * kTileStride;
  static_assert(kTileVoxels * sizeof(uint16_t) % 64 == 0, "every brick's tiles start on a cache line");
  static constexpr int kResidentSlots = 8;

  bool tiled, resident;
  int64_t brick_voxels;
  std::vector<int32_t> slot;  // brick (x + 32 (y + 32 z)) -> its slot
  std::unique_ptr<uint16_t, decltype(&std::free)> voxels{nullptr, &std::free};

  static int32_t row_index(int x, int y, int z) { return (z * kEdge + y) * kEdge + x; }
  static int32_t tile_index(int x, int y, int z) {
    return ((((z >> 1) * kTilesY + (y >> 2)) * kTilesX + (x >> 2)) * kTileStride) | ((z & 1) << 4) | ((y & 3) << 2) | (x & 3);
  }
  /// A brick's part of its voxels' ramp; value() adds the voxel's.
  static int ramp_base(int64_t brick) {
    const int bx = int(brick % kBricks), by = int(brick / kBricks % kBricks), bz = int(brick / (kBricks * kBricks));
    return bx * kM * 7 + by * kM * 13 + bz * kM * 29;
  }
  static uint16_t value(int base, int x, int y, int z) { return uint16_t(base + x * 7 + y * 13 + z * 29); }

  LayoutPool(bool tiles, bool resident_)
      : tiled(tiles), resident(resident_), brick_voxels(tiles ? kTileVoxels : kRowVoxels), slot(size_t(kBricks) * kBricks * kBricks) {
    const int64_t bricks = int64_t(slot.size()), slots = resident ? kResidentSlots : bricks;
    for (int32_t b = 0; b < int32_t(bricks); ++b) slot[size_t(b)] = b % int32_t(slots);
    if (!resident) std::shuffle(slot.begin(), slot.end(), std::mt19937(7));
    // 64 bytes spare: a corner's 32-bit read may end one voxel past its own.
    const size_t bytes = (size_t(slots * brick_voxels) * sizeof(uint16_t) + 64 + 4095) / 4096 * 4096;
    voxels.reset(static_cast<uint16_t*>(std::aligned_alloc(4096, bytes)));
    if (!voxels) throw std::bad_alloc();
    std::fill_n(voxels.get(), bytes / sizeof(uint16_t), uint16_t(0));  // the tiles' padding too
    brickyard::parallel_for<int64_t>(0, bricks, 64, [&](int64_t b0, int64_t b1) {
      for (int64_t b = b0; b < b1; ++b) {
        if (resident && b >= slots) continue;  // a resident slot holds the brick of its own index
        uint16_t* brick = voxels.get() + slot[size_t(b)] * brick_voxels;
        const int base = ramp_base(b);
        for (int z = 0; z < kEdge; ++z)
          for (int y = 0; y < kEdge; ++y)
            for (int x = 0; x < kEdge; ++x) brick[tiled ? tile_index(x, y, z) : row_index(x, y, z)] = value(base, x, y, z);
      }
    });
  }

  /// The 8 corners (dx + 2 dy + 4 dz) of 8 cells of one brick. Rows: the renderer's gathers
  /// of x pairs. Tiles: one 32-bit gather a corner (an x pair straddles two tiles where
  /// x & 3 = 3), each corner's index the lower corner's plus the step to the next voxel along
  /// the axes it moves on, within the tile or into the next.
  void corners(const uint16_t* brick, const int32_t (&cell)[3][8], float (&corner)[8][8]) const {
    int32_t offset[8];
    if (!tiled) {
      for (int k = 0; k < 8; ++k) offset[k] = row_index(cell[0][k], cell[1][k], cell[2][k]);
      load_cell_corners(brick, offset, kEdge, corner);
      return;
    }
    int32_t step[3][8];
    for (int k = 0; k < 8; ++k) {
      offset[k] = tile_index(cell[0][k], cell[1][k], cell[2][k]);
      step[0][k] = (cell[0][k] & 3) != 3 ? 1 : kTileStride - 3;
      step[1][k] = (cell[1][k] & 3) != 3 ? 4 : kTilesX * kTileStride - 12;
      step[2][k] = (cell[2][k] & 1) == 0 ? 16 : kTilesX * kTilesY * kTileStride - 16;
    }
    for (int c = 0; c < 8; ++c) {
      int32_t at[8];
      for (int k = 0; k < 8; ++k) at[k] = offset[k] + (c & 1 ? step[0][k] : 0) + (c & 2 ? step[1][k] : 0) + (c & 4 ? step[2][k] : 0);
#if defined(__AVX2__)
      __m256i index;
      std::memcpy(&index, at, sizeof index);
      // The 32-bit read of a tile's last voxel ends in the next tile, or the brick's padding.
      const __m256i pair = _mm256_i32gather_epi32(reinterpret_cast<const int*>(brick), index, sizeof(uint16_t));
      _mm256_storeu_ps(corner[c], _mm256_cvtepi32_ps(_mm256_and_si256(pair, _mm256_set1_epi32(0xffff))));
#else
      for (int k = 0; k < 8; ++k) corner[c][k] = float(brick[at[k]]);
#endif
    }
  }

  /// Whether corners() gives every cell of a brick the corners its voxels hold.
  bool corners_exact() const {
    constexpr int kCells = kEdge - 1;
    const uint16_t* brick = voxels.get() + slot[0] * brick_voxels;
    for (int i = 0; i < kCells * kCells * kCells; i += 8) {
      int32_t cell[3][8];
      for (int k = 0; k < 8; ++k) {
        const int c = std::min(i + k, kCells * kCells * kCells - 1);
        cell[0][k] = c % kCells, cell[1][k] = c / kCells % kCells, cell[2][k] = c / (kCells * kCells);
      }
      float corner[8][8];
      corners(brick, cell, corner);
      for (int c = 0; c < 8; ++c)
        for (int k = 0; k < 8; ++k)
          if (corner[c][k] != float(value(ramp_base(0), cell[0][k] + (c & 1), cell[1][k] + (c >> 1 & 1), cell[2][k] + (c >> 2)))) return false;
    }
    return true;
  }
};

/// The pool asked for; the last one is freed first (the large ones take 2.6 and 2.9 GB).
const LayoutPool& layout_pool(bool tiled, bool resident) {
  static std::unique_ptr<LayoutPool> pool;
  if (!pool || pool->tiled != tiled || pool->resident != resident) {
    pool.reset();
    pool = std::make_unique<LayoutPool>(tiled, resident);
  }
  return *pool;
}

/// One ray of the view, in voxels of the 1024^3 volume (voxel i covers [i, i + 1)).
struct LayoutRay {
  float org[3], dir[3];
  float t, t_end;
  float h_wait = 0;  // 0, from the last run's values: the next run's step waits on them
  float sum = 0;
};

/// The bench DVR scene's camera at 512x512, in the renderer's tiles of pixels; each ray's
/// first 320 voxels in the volume: the benchmark frame's 2.62M brick visits over its 262k
/// rays are 10 nodes of 32 voxels a ray.
std::vector<std::vector<LayoutRay>> layout_view_tiles() {
  constexpr int kSize = 512, kTile = brickyard::kTileSize;
  constexpr double kVolume = 1024, kPath = 320;
  brickyard::Camera camera;
  camera.eye = brickyard::Vec3d{1.6, -1.1, 1.4} * kVolume;
  camera.target = brickyard::Vec3d{0.5, 0.5, 0.45} * kVolume;
  camera.fov_degrees = 35;
  const brickyard::ImageRays image(camera, kSize, kSize);
  const brickyard::Box3d volume{brickyard::Vec3d(0), brickyard::Vec3d(kVolume)};
  std::vector<std::vector<LayoutRay>> tiles;
  for (int ty = 0; ty < kSize; ty += kTile)
    for (int tx = 0; tx < kSize; tx += kTile) {
      std::vector<LayoutRay>& tile = tiles.emplace_back();
      for (int y = ty; y < ty + kTile; ++y)
        for (int x = tx; x < tx + kTile; ++x) {
          const brickyard::Rayd ray = image.ray(x + 0.5, y + 0.5);
          const brickyard::Interval<double> span = brickyard::intersect(ray, volume);
          if (span.empty()) continue;
          LayoutRay& r = tile.emplace_back();
          for (int a = 0; a < 3; ++a) r.org[a] = float(ray.org[a]), r.dir[a] = float(ray.dir[a]);
          r.t = float(span.t0), r.t_end = float(std::min(span.t1, span.t0 + kPath));
        }
    }
  return tiles;
}

/// One run of up to 8 samples in the brick of the ray's next sample, ended as sample_run ends
/// one: at the node's face, or at the ray's end. Returns the samples taken.
int layout_run(const LayoutPool& pool, LayoutRay& ray, float h) {
  constexpr int M = LayoutPool::kM;
  int brick[3];
  for (int a = 0; a < 3; ++a) brick[a] = std::clamp(int(ray.org[a] + ray.dir[a] * ray.t), 0, 1023) / M;
  const uint16_t* voxels =
      pool.voxels.get() + pool.slot[size_t((brick[2] * LayoutPool::kBricks + brick[1]) * LayoutPool::kBricks + brick[0])] * pool.brick_voxels;
  // As the renderer's adaptive step, set by the opacity gathered, moves this run's samples
  // after its first. IEEE arithmetic keeps 0 * h_wait's operand (no -ffast-math here).
  const float step = h + ray.h_wait;
  int32_t cell[3][8];
  float u[3][8];
  int n = 8;
  for (int k = 0; k < 8; ++k) {
    const float t = ray.t + float(k) * step;
    if (k > 0 && k < n && !(t < ray.t_end)) n = k;
    for (int a = 0; a < 3; ++a) {
      // Brick coordinates as the renderer's: voxel i's centre at i + 1 (the apron's first).
      const float l = ray.org[a] + ray.dir[a] * t - float(brick[a] * M) + 0.5f;
      if (k > 0 && k < n && !(l >= 0.5f && l < float(M) + 0.5f)) n = k;  // past the node's face
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
  ray.t += float(n) * step;
  ray.h_wait = 0.0f * sum;
  return n;
}

void brick_layout_benchmark(benchmark::State& state, bool tiled, bool resident, float h, int interleaved) {
  constexpr int kThreads = 2;
  const LayoutPool& pool = layout_pool(tiled, resident);
  if (!pool.corners_exact()) {
    state.SkipWithError("a brick's corners differ from its voxels");
    return;
  }
  const std::vector<std::vector<LayoutRay>> view = layout_view_tiles();
  tbb::task_arena arena(kThreads);
  std::atomic<int64_t> samples{0};
  for (auto _ : state) {
    arena.execute([&] {
      brickyard::parallel_for<size_t>(0, view.size(), 1, [&](size_t t0, size_t t1) {
        int64_t taken = 0;
        for (size_t t = t0; t < t1; ++t) {
          std::vector<LayoutRay> rays = view[t];
          for (size_t first = 0; first < rays.size(); first += size_t(interleaved)) {
            const size_t last = std::min(rays.size(), first + size_t(interleaved));
            for (bool any = true; any;) {
              any = false;
              for (size_t i = first; i < last; ++i)
                if (rays[i].t < rays[i].t_end) taken += layout_run(pool, rays[i], h), any = true;
            }
            for (size_t i = first; i < last; ++i) benchmark::DoNotOptimize(rays[i].sum);
          }
        }
        samples += taken;
      });
    });
  }
  state.counters["samples/frame"] = double(samples.load()) / double(state.iterations());
  // Core-seconds per sample: wall time per sample times the threads.
  state.counters["s/sample/core"] =
      benchmark::Counter(double(samples.load()) / kThreads, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

/// Last, and only with BRICKYARD_BENCH_LARGE=1: the large pools take 2.6 and 2.9 GB.
void register_brick_layout() {
  if (!brickyard::bench::large_inputs()) return;
  for (bool tiled : {false, true})
    for (bool resident : {false, true})
      for (int step : {1, 2, 16})
        for (int rays : {1, 2})
          benchmark::RegisterBenchmark(fmt::format("GigavoxelsBrickLayout/{}/{}/step:{}/rays:{}", tiled ? "tiles" : "rows",
                                                   resident ? "resident" : "pool", step, rays)
                                           .c_str(),
                                       brick_layout_benchmark, tiled, resident, float(step), rays)
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
  register_brick_layout();
}

}  // namespace

int main(int argc, char** argv) { return brickyard::bench::run_benchmarks(argc, argv, register_all); }
