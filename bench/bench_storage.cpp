// Storage and preprocessing figures (reported, never asserted):
//   Import/...            import throughput in MB/s of raw input, from raw files in the page cache,
//                         on 1 and 2 threads (512^3 always; 1024^3 with BRICKYARD_BENCH_LARGE=1)
//   DecodeVsMemcpy/...    LZ4 decode throughput per core next to memcpy on the same bytes, as a ratio
//   Compression/...       compression ratio per field, type, codec and shuffle (and per level, in CSV)
//   RandomRead/...        random brick read + decode latency from a warm store: p50 and p99
// Inputs are generated once into $BRICKYARD_BENCH_DIR (default /tmp/brickyard-bench) and reused.

#include <benchmark/benchmark.h>

#include "bench_util.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <vector>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "core/raw_volume.h"
#include "fields/field.h"
#include "fields/grid.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"

namespace {

using namespace brickyard;
namespace fs = std::filesystem;

using bench::bench_dir;

/// A raw file of `field` at n^3, generated on first use.
std::string raw_input(const std::string& field, int64_t n, ValueType type) {
  const std::string path = fmt::format("{}/{}-{}-{}.raw", bench_dir(), field, n, to_string(type));
  if (!fs::exists(raw_sidecar_path(path))) {
    auto f = make_field(field);
    write_raw_grid(GridSampler(*f, Vec3s(n), type), path);
  }
  return path;
}

/// A store of `field` at n^3, built on first use.
std::string store_of(const std::string& field, int64_t n, ValueType type, const BuildOptions& options = {}) {
  const std::string dir = fmt::format("{}/{}-{}-{}.store", bench_dir(), field, n, to_string(type));
  auto source = make_field_source(make_field(field), Vec3s(n), type);
  build_store(*source, dir, options);  // a no-op when it is complete and up to date
  return dir;
}

void BM_Import(benchmark::State& state, const std::string& field, ValueType type) {
  const int64_t n = state.range(0);
  const int threads = int(state.range(1));
  const std::string raw = raw_input(field, n, type);
  const RawVolumeInfo info = read_raw_sidecar(raw_sidecar_path(raw));
  RawFileSpec spec;
  spec.dims = info.dims;
  spec.type = element_type(info.type);
  spec.range = ValueRange{info.min_value, info.max_value};
  {  // warm the page cache: the figure is import work, not disk speed
    std::ifstream in(raw, std::ios::binary);
    std::vector<char> buf(1 << 24);
    while (in.read(buf.data(), std::streamsize(buf.size())) || in.gcount() > 0) {}
  }
  const std::string out = fmt::format("{}/import-out.store", bench_dir());
  tbb::task_arena arena(threads);
  double stored = 0;
  for (auto _ : state) {
    state.PauseTiming();
    fs::remove_all(out);
    state.ResumeTiming();
    arena.execute([&] {
      auto source = open_raw_source(raw, spec);
      const BuildResult r = build_store(*source, out, {});
      stored = double(r.stored_bytes);
    });
  }
  fs::remove_all(out);
  const double bytes = double(info.bytes) * double(state.iterations());
  state.SetBytesProcessed(int64_t(bytes));
  state.counters["MB/s"] = benchmark::Counter(bytes / 1e6, benchmark::Counter::kIsRate);
  state.counters["MB/s/core"] = benchmark::Counter(bytes / 1e6 / threads, benchmark::Counter::kIsRate);
  state.counters["ratio"] = double(info.bytes) / stored;
}

/// Encoded bricks of a real store, and their decoded size.
struct BrickSet {
  BrickFormat format;
  std::vector<BrickKey> keys;
  std::vector<std::vector<std::byte>> records;
};

BrickSet brick_set(const std::string& field, ValueType type, size_t count) {
  Store store(store_of(field, 256, type));
  BrickSet set{store.format(), {}, {}};
  auto txn = store.begin_read();
  store.for_each_record(txn, [&](const BrickKey& k, std::span<const std::byte> r) {
    if (int(k.level) == store.layout().finest()) {
      set.keys.push_back(k);
      set.records.emplace_back(r.begin(), r.end());
    }
    return set.keys.size() < count;
  });
  return set;
}

/// memcpy throughput on buffers far larger than the caches, as LZ4's and lzbench's reference
/// figures measure it (a 39 KB brick copied from cache would flatter memcpy several times).
double memcpy_gbps() {
  static const double gbps = [] {
    std::vector<std::byte> a(size_t(256) << 20, std::byte{1}), b(a.size());
    std::memcpy(b.data(), a.data(), a.size());  // fault the pages in
    const auto t0 = std::chrono::steady_clock::now();
    for (int r = 0; r < 8; ++r) std::memcpy(b.data(), a.data(), a.size());
    benchmark::DoNotOptimize(b.data());
    return 8.0 * double(a.size()) / std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / 1e9;
  }();
  return gbps;
}

// Decoding (LZ4, unshuffle, XXH3 check) of real bricks, one core, next to memcpy.
void BM_DecodeVsMemcpy(benchmark::State& state, const std::string& field, ValueType type) {
  const BrickSet set = brick_set(field, type, 256);
  const size_t bytes = set.format.bytes();
  std::vector<std::byte> out(bytes);
  size_t i = 0;
  for (auto _ : state) {
    decode_brick(set.format, set.keys[i], set.records[i], out);
    benchmark::DoNotOptimize(out.data());
    i = (i + 1) % set.records.size();
  }
  const double decode = double(bytes) * double(state.iterations());
  state.SetBytesProcessed(int64_t(decode));
  state.counters["decode_GB/s"] = benchmark::Counter(decode / 1e9, benchmark::Counter::kIsRate);
  state.counters["memcpy_GB/s"] = memcpy_gbps();
  uint64_t stored = 0;
  for (const auto& r : set.records) stored += r.size();
  state.counters["ratio"] = double(bytes * set.records.size()) / double(stored);
}

void BM_Compression(benchmark::State& state, const std::string& field, ValueType type, Codec codec, bool shuffle) {
  BuildOptions o;
  o.codec = codec;
  o.shuffle = shuffle;
  const std::string dir = fmt::format("{}/ratio-{}-{}-{}-{}.store", bench_dir(), field, to_string(type),
                                      to_string(codec), shuffle ? "shuffle" : "plain");
  BuildResult r;
  for (auto _ : state) {
    auto source = make_field_source(make_field(field), Vec3s(128), type);
    o.force = true;
    r = build_store(*source, dir, o);
  }
  uint64_t raw = 0, stored = 0;
  for (const auto& s : r.manifest.stats) {
    raw += s.raw_bytes;
    stored += s.stored_bytes;
  }
  const double input = double(volume(r.manifest.dims)) * double(size_of(type));
  state.counters["input/disk"] = input / double(std::max<uint64_t>(stored, 1));
  state.counters["brick_ratio"] = double(raw) / double(std::max<uint64_t>(stored, 1));
  const auto& fine = r.manifest.stats.back();
  state.counters["finest_ratio"] = double(fine.raw_bytes) / double(std::max<uint64_t>(fine.stored_bytes, 1));
  const auto& coarse = r.manifest.stats.front();
  state.counters["level0_ratio"] = double(coarse.raw_bytes) / double(std::max<uint64_t>(coarse.stored_bytes, 1));
  std::ofstream csv(bench_dir() + "/compression.csv", std::ios::app);
  for (size_t l = 0; l < r.manifest.stats.size(); ++l)
    csv << fmt::format("{},{},{},{},{},{},{}\n", field, to_string(type), to_string(codec), shuffle ? "shuffle" : "plain", l,
                       r.manifest.stats[l].raw_bytes, r.manifest.stats[l].stored_bytes);
  fs::remove_all(dir);
}

void BM_RandomRead(benchmark::State& state, ValueType type) {
  Store store(store_of("fbm", 256, type));
  std::vector<BrickKey> keys;
  const GridLayout& l = store.layout();
  for (int64_t i = 0; i < l.brick_count(l.finest()); ++i) {
    const BrickKey k = l.key_at(l.finest(), i);
    if (store.nodes().at(k).has_payload()) keys.push_back(k);
  }
  std::vector<std::byte> out(store.format().bytes());
  std::mt19937 rng(1);
  std::vector<double> ns;
  ns.reserve(1 << 20);
  for (auto _ : state) {
    const BrickKey& k = keys[rng() % keys.size()];
    auto t0 = std::chrono::steady_clock::now();
    auto txn = store.begin_read();  // per read, as a cache miss would
    store.read_brick(txn, k, out);
    ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ns.begin(), ns.end());
  state.counters["p50_us"] = ns[ns.size() / 2] / 1e3;
  state.counters["p99_us"] = ns[ns.size() * 99 / 100] / 1e3;
  state.SetBytesProcessed(int64_t(state.iterations()) * int64_t(out.size()));
}

void register_all() {
  const bool large = bench::large_inputs();
  for (ValueType t : {ValueType::u8, ValueType::u16, ValueType::f32}) {
    auto* b = benchmark::RegisterBenchmark(fmt::format("Import/fbm/{}", to_string(t)).c_str(), BM_Import, "fbm", t);
    for (int64_t n : {int64_t(512), int64_t(1024)}) {
      if (n == 1024 && !large) continue;
      for (int threads : {1, 2}) b->Args({n, threads});
    }
    b->ArgNames({"n", "threads"})->Iterations(1)->Repetitions(2)->ReportAggregatesOnly(false)->UseRealTime()->Unit(benchmark::kSecond);
  }
  for (const char* field : {"fbm", "marschner-lobb", "sparse-blobs"})
    for (ValueType t : {ValueType::u8, ValueType::u16, ValueType::f32})
      benchmark::RegisterBenchmark(fmt::format("DecodeVsMemcpy/{}/{}", field, to_string(t)).c_str(), BM_DecodeVsMemcpy,
                                   std::string(field), t)
          ->Unit(benchmark::kMicrosecond);
  for (const auto& field : field_names())
    for (ValueType t : {ValueType::u8, ValueType::u16, ValueType::f32}) {
      for (auto [codec, shuffle] : {std::pair{Codec::lz4, true}, std::pair{Codec::lz4, false}, std::pair{Codec::lz4hc, true}}) {
        if (t == ValueType::u8 && !shuffle) continue;  // shuffling a byte stream changes nothing
        benchmark::RegisterBenchmark(fmt::format("Compression/{}/{}/{}{}", field, to_string(t), to_string(codec),
                                                 shuffle && t != ValueType::u8 ? "+shuffle" : "")
                                         .c_str(),
                                     BM_Compression, field, t, codec, shuffle)
            ->Iterations(1)
            ->Unit(benchmark::kMillisecond);
      }
    }
  for (ValueType t : {ValueType::u8, ValueType::u16})
    benchmark::RegisterBenchmark(fmt::format("RandomRead/fbm256/{}", to_string(t)).c_str(), BM_RandomRead, t)
        ->Unit(benchmark::kMicrosecond);
}

}  // namespace

int main(int argc, char** argv) { return brickyard::bench::run_benchmarks(argc, argv, register_all); }
