// Renderer throughput: rays per second per core for each back end in iso, DVR and MIP mode, on
// 1 and 2 threads, warm cache (every brick resident), one frame per iteration.
//
//   build/bench/bench_render                          # Marschner-Lobb 256^3 f32 (the default dataset)
//   BRICKYARD_BENCH_LARGE=1 build/bench/bench_render  # adds fBm 512^3 u8
// Inputs are generated once under $BRICKYARD_BENCH_DIR (default /tmp/brickyard-bench).

#include <benchmark/benchmark.h>

#include <cstdlib>
#include <map>
#include <memory>

#include <fmt/format.h>
#include <tbb/global_control.h>

#include "bench_util.h"
#include "fields/field.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "session/render_session.h"

namespace {

using namespace brickyard;

std::string store_of(const std::string& field, int64_t n, ValueType type) {
  const std::string dir = fmt::format("{}/{}-{}-{}-m32.store", bench::bench_dir(), field, n, to_string(type));
  auto source = make_field_source(make_field(field), Vec3s(n), type);
  build_store(*source, dir, BuildOptions{});  // no-op when complete and up to date
  return dir;
}

Scene scene_for(const std::string& store, RenderMode mode, double lo, double hi) {
  Scene s;
  s.dataset = store;
  s.width = s.height = s.camera.width = s.camera.height = 256;
  Camera c;
  c.eye = {1.6, -1.1, 1.4};
  c.target = {0.5, 0.5, 0.45};
  c.fov_degrees = 35;
  s.camera.keyframes = {c};
  s.mode = mode;
  const double mid = lo + 0.5 * (hi - lo), top = lo + 0.85 * (hi - lo);
  s.isosurfaces = {{mid, {0.9f, 0.7f, 0.3f}}};
  s.transfer_function = TransferFunction({{mid, Vec3f(0.2f, 0.4f, 0.9f), 0.0f},
                                          {top, Vec3f(0.9f, 0.8f, 0.3f), 0.2f},
                                          {hi, Vec3f(1.0f, 0.4f, 0.2f), 0.6f}});
  s.cache.l1_bytes = s.cache.l2_bytes = uint64_t(2) << 30;  // everything fits: warm frames
  return s;
}

void render_benchmark(benchmark::State& state, std::string store, std::string backend, RenderMode mode, double lo,
                      double hi) {
  const int threads = int(state.range(0));
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
  const Scene scene = scene_for(store, mode, lo, hi);
  RenderSession::Options o;
  o.backend = backend;
  RenderSession session(scene, o);
  FrameBuffers fb;
  session.render(0, fb);  // warm-up: every brick the frame needs becomes resident
  uint64_t rays = 0, samples = 0;
  for (auto _ : state) {
    const FrameStats st = session.render(0, fb);
    rays += st.counters.rays;
    samples += st.counters.samples;
  }
  state.counters["rays/s/core"] = benchmark::Counter(double(rays) / threads, benchmark::Counter::kIsRate);
  state.counters["samples/s/core"] = benchmark::Counter(double(samples) / threads, benchmark::Counter::kIsRate);
  state.counters["samples/ray"] = double(samples) / double(std::max<uint64_t>(rays, 1));
}

void register_all() {
  struct Input {
    std::string name, field;
    int64_t n;
    ValueType type;
    double lo, hi;
  };
  std::vector<Input> inputs = {{"ml256f32", "marschner-lobb", 256, ValueType::f32, 0.0, 1.0}};
  if (bench::large_inputs()) inputs.push_back({"fbm512u8", "fbm", 512, ValueType::u8, 0.0, 255.0});
  for (const Input& in : inputs) {
    const std::string store = store_of(in.field, in.n, in.type);
    for (const char* backend : {"raymarch", "reference"})
      for (RenderMode mode : {RenderMode::iso, RenderMode::dvr, RenderMode::mip}) {
        auto* b = benchmark::RegisterBenchmark(
            fmt::format("Render/{}/{}/{}", backend, in.name, to_string(mode)).c_str(),
            [=](benchmark::State& st) { render_benchmark(st, store, backend, mode, in.lo, in.hi); });
        b->Arg(1)->Arg(2)->ArgName("threads")->Unit(benchmark::kMillisecond)->UseRealTime();
        if (std::string(backend) == "reference" && mode == RenderMode::dvr) b->Iterations(1);
      }
  }
}

}  // namespace

int main(int argc, char** argv) { return brickyard::bench::run_benchmarks(argc, argv, register_all); }
