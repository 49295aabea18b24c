// Cache figures (reported, never asserted):
//   HitPath/<policy>/threads:N   cost of an L1 hit (lookup + release), 1 and 2 threads
//   Loader/u8/32                 decoded MB/s the asynchronous loader reaches from a warm store
//   MissRatio/<trace>/<size>     every policy's miss ratio next to OPT's, and the best one's gap
// Stores are built once into $BRICKYARD_BENCH_DIR (default /tmp/brickyard-bench). The flight
// runs over a 512^3 fBm store, or 1024^3 with BRICKYARD_BENCH_LARGE=1.

#include <benchmark/benchmark.h>

#include "bench_util.h"

#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <thread>
#include <chrono>
#include <atomic>
#include <vector>

#include <fmt/format.h>

#include "cache/brick_cache.h"
#include "session/grid_cache.h"
#include "cache/flight.h"
#include "cache/policy.h"
#include "cache/replay.h"
#include "cache/trace.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"

namespace {

using namespace brickyard;
namespace fs = std::filesystem;

using bench::bench_dir;

std::string store_of(const std::string& field, int64_t n, int brick) {
  const std::string dir = fmt::format("{}/{}-{}-u8-m{}.store", bench_dir(), field, n, brick);
  BuildOptions o;
  o.brick_size = brick;
  auto source = make_field_source(make_field(field), Vec3s(n), ValueType::u8);
  build_store(*source, dir, o);  // no-op when complete and up to date
  return dir;
}

std::vector<BrickKey> payload_keys(const Store& s, int level) {
  std::vector<BrickKey> keys;
  for (int64_t i = 0; i < s.layout().brick_count(level); ++i) {
    const BrickKey k = s.layout().key_at(level, i);
    if (s.nodes().at(k).has_payload()) keys.push_back(k);
  }
  return keys;
}

// ------------------------------------------------------------------------------- hit path

struct HitFixture {
  std::unique_ptr<Store> store;
  std::unique_ptr<GridCache> cache;
  std::vector<BrickKey> keys;
};

HitFixture& hit_fixture(const std::string& policy) {
  static std::mutex mutex;
  static std::map<std::string, std::unique_ptr<HitFixture>> fixtures;
  std::lock_guard lock(mutex);
  auto& f = fixtures[policy];
  if (!f) {
    f = std::make_unique<HitFixture>();
    f->store = std::make_unique<Store>(store_of("fbm", 256, 16));
    f->keys = payload_keys(*f->store, f->store->layout().finest());
    CacheConfig c;
    c.l1_slots = uint32_t(f->keys.size() * 2);  // shards fill unevenly: headroom so every key stays resident
    c.l2_bytes = f->store->format().bytes() * 64;
    c.l1_policy = policy;
    f->cache = std::make_unique<GridCache>(*f->store, c);
    for (const auto& k : f->keys) f->cache->bricks().fetch(k);  // everything resident: every lookup hits
  }
  return *f;
}

// Runs `threads` std::threads doing random hits for a fixed time per iteration (manual time):
// Google Benchmark's own multi-threaded runs measured this machine's 2 cores erratically.
void BM_HitPath(benchmark::State& state, const std::string& policy) {
  HitFixture& f = hit_fixture(policy);
  const int threads = int(state.range(0));
  uint64_t total = 0, misses = 0;
  double seconds = 0;
  for (auto _ : state) {
    std::atomic<bool> go{false};
    std::vector<std::thread> pool;
    std::vector<uint64_t> counts(static_cast<size_t>(threads)), missed(static_cast<size_t>(threads));
    std::vector<double> elapsed(static_cast<size_t>(threads));
    for (int t = 0; t < threads; ++t)
      pool.emplace_back([&, t] {
        std::mt19937 rng(uint32_t(t) + 1);
        std::vector<uint32_t> order(1 << 16);
        for (auto& o : order) o = uint32_t(rng() % f.keys.size());
        while (!go.load()) {
        }
        const auto t0 = std::chrono::steady_clock::now();
        uint64_t n = 0, m = 0;
        while (std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(200))
          for (int i = 0; i < 1024; ++i) {
            BrickHandle h = f.cache->bricks().lookup(f.keys[order[n++ & 0xffff]], 0, false);
            m += !h.resident();
            benchmark::DoNotOptimize(h.bytes());
          }
        counts[size_t(t)] = n;
        missed[size_t(t)] = m;
        elapsed[size_t(t)] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      });
    go = true;
    for (auto& t : pool) t.join();
    double longest = 0;
    for (int t = 0; t < threads; ++t) {
      total += counts[size_t(t)];
      misses += missed[size_t(t)];
      longest = std::max(longest, elapsed[size_t(t)]);
    }
    seconds += longest;
    state.SetIterationTime(longest);
  }
  state.counters["lookups/s"] = double(total) / seconds;
  state.counters["ns/lookup/thread"] = seconds * 1e9 * threads / double(total);
  state.counters["misses"] = double(misses);
}

// --------------------------------------------------------------------------------- loader

void BM_Loader(benchmark::State& state) {
  Store store(store_of("fbm", 512, 32));
  const auto keys = payload_keys(store, store.layout().finest());
  uint64_t bytes = 0;
  for (auto _ : state) {
    CacheConfig c;
    c.l1_slots = uint32_t(keys.size()) * 2;
    c.l2_bytes = store.format().bytes() * 64;
    c.loader_threads = int(state.range(0));
    state.PauseTiming();  // allocating and faulting in the pool is not loading
    auto cache = std::make_unique<GridCache>(store, c);
    state.ResumeTiming();
    cache->bricks().frame_begin();
    for (const auto& k : keys) cache->bricks().request(k, 1);
    cache->bricks().wait_idle();
    bytes += cache->bricks().stats().l3_bytes_decoded;
    state.PauseTiming();  // the cache's destruction is not loading
    cache.reset();
    state.ResumeTiming();
  }
  state.SetBytesProcessed(int64_t(bytes));
  state.counters["decoded_MB/s"] = benchmark::Counter(double(bytes) / 1e6, benchmark::Counter::kIsRate);
}

// ----------------------------------------------------------------------------- miss ratios

const Trace& flight_trace() {
  static Trace trace = [] {
    const int64_t n = bench::large_inputs() ? 1024 : 512;
    const std::string path = fmt::format("{}/flight-fbm{}.bytrace", bench_dir(), n);
    if (!fs::exists(path)) {
      Store store(store_of("fbm", n, 32));
      CacheConfig c;
      c.l1_bytes = uint64_t(256) << 20;
      c.l2_bytes = uint64_t(1) << 30;
      c.trace_path = path;
      GridCache cache(store, c);
      fly(cache.bricks(), CameraPath::load(BRICKYARD_SOURCE_DIR "/scenes/flight-orbit.json"), {});
      cache.close();  // writes the trace, or says why it cannot
    }
    return read_trace(path);
  }();
  return trace;
}

void BM_MissRatio(benchmark::State& state, const std::string& name, double fraction) {
  static std::map<std::string, Trace> traces;
  if (!traces.contains(name)) {
    if (name == "zipf0.9") traces[name] = zipf_trace(100000, 2000000, 0.9, 1);
    else if (name == "zipf1.2") traces[name] = zipf_trace(100000, 2000000, 1.2, 1);
    else if (name == "scan+hot") {
      Trace t;
      uint64_t fresh = 1 << 30;
      std::mt19937 rng(3);
      for (int i = 0; i < 2000000; ++i)
        t.records.push_back({i % 5 < 3 ? uint64_t(rng() % 20000) : fresh++, uint32_t(i / 20000), 1});
      traces[name] = t;
    } else if (name == "loop") traces[name] = loop_trace(50000, 20);
    else traces[name] = flight_trace();
  }
  const Trace& t = traces[name];
  const auto next = next_demand_access(t);
  const uint64_t capacity = std::max<uint64_t>(1, uint64_t(double(t.unique_bytes()) * fraction));
  std::map<std::string, double> ratio;
  for (auto _ : state)
    for (const auto& p : policy_names())
      if (p != "lru-frame") ratio[p] = replay(t, next, p, capacity).miss_ratio();
  double best = 2;
  for (const auto& [p, r] : ratio) {
    state.counters[p] = r;
    if (p != "opt") best = std::min(best, r);
  }
  state.counters["best-opt"] = best - ratio["opt"];
}

void register_all() {
  for (const auto& p : policy_names()) {
    if (p == "opt") continue;
    benchmark::RegisterBenchmark(fmt::format("HitPath/{}", p).c_str(), BM_HitPath, p)
        ->Arg(1)->Arg(2)->ArgName("threads")->UseManualTime()->Iterations(5)->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark("Loader/u8/32", BM_Loader)->Arg(1)->Arg(2)->ArgName("loaders")->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);
  for (const char* t : {"zipf0.9", "zipf1.2", "scan+hot", "loop", "flight"})
    for (double f : {0.01, 0.02, 0.05, 0.1, 0.2, 0.5})
      benchmark::RegisterBenchmark(fmt::format("MissRatio/{}/{:g}%", t, f * 100).c_str(), BM_MissRatio, std::string(t), f)
          ->Iterations(1)
          ->Unit(benchmark::kMillisecond);
}

}  // namespace

int main(int argc, char** argv) { return brickyard::bench::run_benchmarks(argc, argv, register_all); }
