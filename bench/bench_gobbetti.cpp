// The `gobbetti` spatial index: what its per-frame rebuild costs and how fast rays walk it.
// Figures are reported, never asserted.
//
//   GobbettiIndex/Build/leaves:N     one build() from a cut of N leaves, storage reused as in a
//                                    frame loop; leaves/s and nodes
//   GobbettiIndex/Traverse/leaves:N  one thread walking a 256x256 pinhole frame of rays through
//                                    the same cut; leaf visits per second per core, rays/s
//
// The cuts are view-dependent, like the renderer's: a 2048^3 volume with 32^3 bricks (7
// levels, 64^3 finest bricks), refined greedily by projected brick size from the camera
// until N leaves. Nothing is read from disk.
//
//   build/bench/bench_gobbetti

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <queue>
#include <random>
#include <vector>

#include <fmt/format.h>

#include "bench_util.h"
#include "renderers/gobbetti/spatial_index.h"
#include "dataset/grid.h"

namespace {

using namespace brickyard;
using gobbetti::CutLeaf;
using gobbetti::LeafVisit;
using gobbetti::SpatialIndex;

const GridLayout& bench_layout() {
  static const GridLayout layout = GridLayout::make(Vec3s(2048), 32);
  return layout;
}

const Vec3d kEye(-1400, 3100, 2600);
const Vec3d kTarget(1024, 1024, 1024);

/// Greedy view-dependent refinement: split the leaf with the largest size/distance until the
/// cut has `target` leaves; shuffled, since the renderer's order is not the index's.
std::vector<CutLeaf> view_cut(size_t target) {
  const GridLayout& layout = bench_layout();
  const double M = layout.brick_size;
  auto priority = [&](const BrickKey& k) {
    const double s = std::ldexp(M, layout.finest() - int(k.level));
    const Vec3d centre = (Vec3d(k.x, k.y, k.z) + Vec3d(0.5)) * s;
    return int(k.level) == layout.finest() ? -1.0 : s / std::max(length(centre - kEye), 1.0);
  };
  auto cmp = [](const std::pair<double, BrickKey>& a, const std::pair<double, BrickKey>& b) { return a.first < b.first; };
  std::priority_queue<std::pair<double, BrickKey>, std::vector<std::pair<double, BrickKey>>, decltype(cmp)> heap(cmp);
  heap.push({priority(BrickKey{}), BrickKey{}});
  while (heap.size() < target && heap.top().first >= 0) {
    const BrickKey k = heap.top().second;
    heap.pop();
    for (int c = 0; c < 8; ++c)
      if (layout.contains(k.child(c))) heap.push({priority(k.child(c)), k.child(c)});
  }
  std::vector<CutLeaf> cut;
  while (!heap.empty()) {
    cut.push_back({heap.top().second, uint32_t(cut.size())});
    heap.pop();
  }
  std::shuffle(cut.begin(), cut.end(), std::mt19937_64(7));
  return cut;
}

void build_benchmark(benchmark::State& state) {
  const std::vector<CutLeaf> cut = view_cut(size_t(state.range(0)));
  SpatialIndex index;
  index.build(bench_layout(), cut);  // warm-up: the storage every later frame reuses
  for (auto _ : state) {
    index.build(bench_layout(), cut);
    benchmark::DoNotOptimize(index.node_count());
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * int64_t(cut.size()));
  state.counters["cut_leaves"] = double(cut.size());
  state.counters["nodes"] = double(index.node_count());
  state.counters["KiB"] = double(index.bytes()) / 1024.0;
}

void traverse_benchmark(benchmark::State& state) {
  const std::vector<CutLeaf> cut = view_cut(size_t(state.range(0)));
  SpatialIndex index;
  index.build(bench_layout(), cut);
  // A 256x256 pinhole frame, 40 degrees, looking at the volume's centre.
  constexpr int kSize = 256;
  const Vec3d forward = normalize(kTarget - kEye);
  const Vec3d right = normalize(cross(forward, Vec3d(0, 0, 1)));
  const Vec3d up = cross(right, forward);
  const double half = std::tan(20.0 * kPi / 180.0);
  std::vector<Vec3d> dirs;
  for (int y = 0; y < kSize; ++y)
    for (int x = 0; x < kSize; ++x) {
      const double u = ((x + 0.5) / kSize * 2 - 1) * half, v = ((y + 0.5) / kSize * 2 - 1) * half;
      dirs.push_back(normalize(forward + right * u + up * v));
    }
  uint64_t visits = 0;
  double sum = 0;
  for (auto _ : state) {
    for (const Vec3d& d : dirs)
      index.traverse(kEye, d, 0.0, std::numeric_limits<double>::infinity(), [&](const LeafVisit& v) {
        ++visits;
        sum += v.tb - v.ta;
        return true;
      });
  }
  benchmark::DoNotOptimize(sum);
  state.counters["leaves/s/core"] = benchmark::Counter(double(visits), benchmark::Counter::kIsRate);
  state.counters["rays/s/core"] =
      benchmark::Counter(double(state.iterations()) * double(dirs.size()), benchmark::Counter::kIsRate);
  state.counters["leaves/ray"] = double(visits) / (double(state.iterations()) * double(dirs.size()));
}

void register_all() {
  for (int64_t leaves : {1000, 10000, 50000}) {
    benchmark::RegisterBenchmark(fmt::format("GobbettiIndex/Build/leaves:{}", leaves).c_str(), build_benchmark)
        ->Arg(leaves)
        ->Unit(benchmark::kMicrosecond);
    benchmark::RegisterBenchmark(fmt::format("GobbettiIndex/Traverse/leaves:{}", leaves).c_str(), traverse_benchmark)
        ->Arg(leaves)
        ->Unit(benchmark::kMillisecond);
  }
}

}  // namespace

int main(int argc, char** argv) { return brickyard::bench::run_benchmarks(argc, argv, register_all); }
