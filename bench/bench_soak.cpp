// Memory soak (issue 42, item 5): each back end flies a random camera, a jump every frame, with
// random zoom so that some frames need far more pages than the L1 and L2 budgets hold (thrash),
// for thousands of frames; every frame the cache's resident bytes per level and the process's
// RSS are sampled (bench/soak.h says what is counted). Figures are printed and written as CSV,
// never asserted; the quick version that asserts is tests/renderers/test_soak.cpp.
//
//   build/bench/bench_soak --grid STORE [--mesh STORE] [--backends raymarch,...,tet_bvh]
//       [--frames 2000] [--frames-for NAME=N ...] [--size 96] [--l1 16MiB] [--l2 64MiB]
//       [--loader-threads 2] [--upload-budget 0] [--lod-ratio 0.1] [--seed 1] [--warmup 100]
//       [--rss-slack 16MiB] [--set BACKEND:NAME=VALUE ...] [--csv DIR] [--summary FILE]
//
// Back ends that render meshes only (tet_bvh) fly over --mesh, the others over --grid;
// NAME@mesh or NAME@grid chooses (reference@mesh). bench/soak.sh imports the stores and runs
// one process per back end, so that each RSS starts from a fresh process.

#include <cstdio>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "apps/parse.h"
#include "bench/soak.h"
#include "core/error.h"
#include "core/units.h"

namespace {

using namespace brickyard;

struct Options {
  std::string grid, mesh, backends = "raymarch,reference,gobbetti,gigavoxels,octree_cgt,tet_bvh";
  std::vector<std::string> frames_for, sets;
  int frames = 2000, size = 96, loader_threads = 2, warmup = 100;
  uint32_t upload_budget = 0;
  std::string l1 = "16MiB", l2 = "64MiB", rss_slack = "16MiB", csv, summary;
  double lod_ratio = 0.1;
  uint64_t seed = 1;
};

std::string mib(uint64_t bytes) { return fmt::format("{:.1f}", double(bytes) / double(1 << 20)); }

void write_csv(const std::string& path, const soak::SoakResult& r) {
  std::ofstream csv(path);
  csv << "frame,ms,l1_slots,l1_bytes,l2_bytes,waiting_bytes,backend_bytes,metadata_bytes,resident,bound,rss_anon,rss_file,heap,requests,uploads,"
         "l3_bytes_read\n";
  for (const soak::SoakSample& s : r.samples)
    csv << fmt::format("{},{:.3f},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", s.frame, s.ms, s.l1_slots, s.l1_bytes, s.l2_bytes,
                       s.waiting_bytes, s.backend_bytes, s.metadata_bytes, s.resident, r.bound(), s.rss, s.rss_file, s.heap, s.requests,
                       s.uploads,
                       s.l3_bytes_read);
}

int run(const Options& o) {
  const uint64_t l1 = parse_bytes(o.l1, "--l1"), l2 = parse_bytes(o.l2, "--l2"), slack = parse_bytes(o.rss_slack, "--rss-slack", true);
  std::map<std::string, int> frames_for;
  for (const std::string& a : o.frames_for) {
    const auto [name, n] = cli::parse_assignment(a, "--frames-for");
    frames_for[name] = int(n);
  }
  std::map<std::string, std::map<std::string, double>> params;
  for (const std::string& a : o.sets) {
    const size_t colon = a.find(':');
    if (colon == std::string::npos) throw Error(Errc::invalid_argument, "--set takes BACKEND:NAME=VALUE").with_field("--set");
    const auto [name, v] = cli::parse_assignment(a.substr(colon + 1), "--set");
    params[a.substr(0, colon)][name] = v;
  }
  std::vector<soak::SoakResult> results;
  std::vector<uint64_t> rss100;  // anonymous RSS at frame --warmup
  for (const std::string& spec : cli::split_list(o.backends)) {
    const size_t at = spec.find('@');
    const std::string name = spec.substr(0, at);
    const BackendInfo& info = backends().find(name).info;
    const bool grids = std::find(info.kinds.begin(), info.kinds.end(), DataKind::structured) != info.kinds.end();
    const std::string on = at != std::string::npos ? spec.substr(at + 1) : grids ? "grid" : "mesh";
    if (on != "grid" && on != "mesh") throw Error(Errc::invalid_argument, fmt::format("{}: @grid or @mesh", spec)).with_field("--backends");
    const std::string& dataset = on == "grid" ? o.grid : o.mesh;
    if (dataset.empty()) throw Error(Errc::invalid_argument, fmt::format("{} needs --{}", spec, on)).with_field("--backends");
    soak::SoakOptions so;
    so.dataset = dataset;
    so.backend = name;
    so.params = params[name];
    so.frames = frames_for.count(name) ? frames_for[name] : o.frames;
    so.size = o.size;
    so.l1_bytes = l1;
    so.l2_bytes = l2;
    so.loader_threads = o.loader_threads;
    so.upload_pages_per_frame = o.upload_budget;
    so.lod_ratio = o.lod_ratio;
    so.seed = o.seed;
    so.warmup = o.warmup;
    fmt::print("{} over {}: {} frames of {}x{}, L1 {}, L2 {}, lod_ratio {}\n", spec, dataset, so.frames, o.size, o.size, o.l1, o.l2,
               o.lod_ratio);
    std::fflush(stdout);
    soak::SoakResult r = soak::run_soak(so, [&](const soak::SoakSample& s, const soak::SoakResult& so_far) {
      if (s.frame == 0)
        fmt::print("  budget {} MiB (L1 {} + L2 {}{}), fixed overhead {} MiB: {}\n", mib(so_far.budget()), mib(so_far.l1_budget),
                   mib(so_far.l2_budget), so_far.own_budget ? fmt::format(" + {} {}", so_far.own_what, mib(so_far.own_budget)) : "",
                   mib(so_far.overhead.total()), so_far.overhead.describe());
      if ((s.frame + 1) % 500 == 0)
        fmt::print("  frame {:>5}: resident {} MiB (L1 {} slots {} MiB, L2 {} MiB, waiting {} MiB, own {} MiB), RSS anon {} MiB, "
                   "file {} MiB, {:.1f} ms\n",
                   s.frame + 1, mib(s.resident), s.l1_slots, mib(s.l1_bytes), mib(s.l2_bytes), mib(s.waiting_bytes),
                   mib(s.backend_bytes), mib(s.rss), mib(s.rss_file), s.ms);
      std::fflush(stdout);
    });
    r.backend = spec;
    fmt::print("  {} frames in {:.1f} s (median {:.1f} ms, p95 {:.1f} ms); read {} MiB from the store; L1 evictions {}, L2 {}\n",
               r.frames, r.seconds, r.ms_median, r.ms_p95, mib(r.l3_bytes_read), r.l1_evictions, r.l2_evictions);
    fmt::print("  peak resident {} MiB at frame {} (bound {} MiB), L2 peak {} MiB, waiting peak {} MiB\n", mib(r.peak_resident),
               r.peak_frame, mib(r.bound()), mib(r.l2_peak), mib(r.peak_waiting));
    const auto rss_at = [&](int f) { return mib(r.samples[size_t(std::min(f, r.frames - 1))].rss); };
    fmt::print("  RSS (anonymous) start {} MiB, frame {} {} MiB, warm (frame {}) {} MiB, frame 1000 {} MiB, end {} MiB, peak {} MiB; "
               "file-backed (the store's map) at the end {} MiB\n",
               mib(r.rss_start), o.warmup, rss_at(o.warmup), r.warm_frame, mib(r.rss_warm), rss_at(1000), mib(r.rss_end), mib(r.rss_peak),
               mib(r.rss_file_end));
    fmt::print("  heap in use (mallinfo2): warm {} MiB, end {} MiB\n", mib(r.heap_warm), mib(r.heap_end));
    fmt::print("  {}: resident <= budget + overhead at every frame{}\n", r.resident_ok() ? "PASS" : "FAIL",
               r.resident_ok() ? "" : fmt::format(" ({} frames over, the first {}; L2 peak {} of {})", r.frames_over, r.first_over,
                                                  r.l2_peak, r.l2_budget));
    fmt::print("  {}: anonymous RSS at the end <= at the warm frame {} + {}\n", r.rss_flat(slack) ? "PASS" : "FAIL", r.warm_frame,
               o.rss_slack);
    if (!o.csv.empty()) {
      const std::string path = fmt::format("{}/soak-{}.csv", o.csv, spec);
      write_csv(path, r);
      fmt::print("  per-frame samples: {}\n", path);
    }
    rss100.push_back(r.samples[size_t(std::min(o.warmup, r.frames - 1))].rss);
    r.samples.clear();
    results.push_back(std::move(r));
  }

  // The table (one line per back end; soak.sh joins the processes' lines).
  const std::string header =
      "backend,frames,budget_mib,overhead_mib,peak_resident_mib,l2_peak_mib,waiting_peak_mib,rss_start_mib,rss_at_warmup_mib,warm_frame,"
      "rss_warm_mib,rss_end_mib,rss_peak_mib,rss_file_end_mib,heap_warm_mib,heap_end_mib,median_ms,seconds,resident_ok,rss_flat,overhead";
  std::string table;
  for (size_t i = 0; i < results.size(); ++i) {
    const soak::SoakResult& r = results[i];
    table += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.1f},{:.0f},{},{},\"{}\"\n", r.backend, r.frames,
                         mib(r.budget()), mib(r.overhead.total()), mib(r.peak_resident), mib(r.l2_peak), mib(r.peak_waiting),
                         mib(r.rss_start), mib(rss100[i]), r.warm_frame, mib(r.rss_warm), mib(r.rss_end), mib(r.rss_peak),
                         mib(r.rss_file_end), mib(r.heap_warm), mib(r.heap_end), r.ms_median, r.seconds,
                         r.resident_ok() ? "PASS" : "FAIL", r.rss_flat(slack) ? "PASS" : "FAIL", r.overhead.describe());
  }
  fmt::print("\n{}\n{}", header, table);
  if (!o.summary.empty()) {
    const bool fresh = !std::ifstream(o.summary).good();
    std::ofstream out(o.summary, std::ios::app);
    if (fresh) out << header << '\n';
    out << table;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Memory soak: random camera jumps with thrash, resident bytes and RSS every frame, per back end"};
  app.add_option("--grid", o.grid, "Grid store (with an octree volume for octree_cgt)");
  app.add_option("--mesh", o.mesh, "Tetrahedral store (tet_bvh)");
  app.add_option("--backends", o.backends, "Back ends, comma-separated; NAME@grid or NAME@mesh chooses the store");
  app.add_option("--frames", o.frames, "Frames per back end")->check(CLI::Range(1, 10000000));
  app.add_option("--frames-for", o.frames_for, "NAME=N: frames for one back end (repeatable)");
  app.add_option("--size", o.size, "Image width and height")->check(CLI::Range(8, 4096));
  app.add_option("--l1", o.l1, "L1 budget (bytes, e.g. 16MiB)");
  app.add_option("--l2", o.l2, "L2 budget");
  app.add_option("--loader-threads", o.loader_threads, "Cache loader threads")->check(CLI::Range(1, 64));
  app.add_option("--upload-budget", o.upload_budget, "The cache's uploads per frame (0: unlimited)");
  app.add_option("--lod-ratio", o.lod_ratio, "quality.lod_ratio (small: fine levels wanted, thrash)")->check(CLI::Range(0.001, 1000.0));
  app.add_option("--seed", o.seed, "Camera seed");
  app.add_option("--warmup", o.warmup, "Frames before RSS must stay flat")->check(CLI::Range(0, 10000000));
  app.add_option("--rss-slack", o.rss_slack, "RSS growth allowed after the warm-up");
  app.add_option("--set", o.sets, "BACKEND:NAME=VALUE back-end parameter (repeatable)");
  app.add_option("--csv", o.csv, "Directory for one CSV of samples per back end");
  app.add_option("--summary", o.summary, "Append the table's lines to this CSV");
  CLI11_PARSE(app, argc, argv);
  try {
    return run(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_soak: %s\n", e.what());
    return 1;
  }
}
