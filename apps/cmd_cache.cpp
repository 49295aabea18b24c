// cachebench: replays an access trace against cache policies and sizes.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "apps/commands.h"
#include "apps/parse.h"
#include "cache/brick_cache.h"
#include "cache/flight.h"
#include "cache/policy.h"
#include "cache/replay.h"
#include "cache/trace.h"
#include "core/atomic_file.h"
#include "core/error.h"
#include "core/parallel.h"
#include "core/plot.h"
#include "core/raw_volume.h"
#include "core/resources.h"
#include "core/units.h"
#include "session/grid_cache.h"
#include "storage/store.h"

namespace brickyard::cli {
namespace {

struct CachebenchOptions {
  std::string trace;
  std::string format;
  std::string synthetic;
  std::string policies = "lru,clock,arc,s3fifo,sieve,opt";
  std::string sizes = "1%,2%,5%,10%,20%,50%";
  std::string convert, to = "brickyard";
  std::string csv, plot;
  std::string kind;  ///< replay only this record kind's accesses ("": every kind, each (kind, key) an object)
  bool windows = false;
};


/// What replaying a synthetic trace holds in memory, from its parameters, before it is made: its
/// records with their next-access times and object ids, the generator's tables (Zipf: a CDF and
/// a permutation over the objects), the next-access index over the objects, and a resident set
/// per replay running at once (up to `replays`, one per thread).
ResourceNeeds synthetic_trace_needs(const std::string& spec, const std::string& kind, std::map<std::string, double>& p,
                                    double replays) {
  const bool zipf = kind == "zipf";
  const double records = zipf ? p["requests"] : p["objects"] * p["passes"];
  const double objects = kind == "scan" ? records : zipf ? std::min(p["objects"], records) : p["objects"];
  const double tables = zipf ? 16 * p["objects"] : 0;
  constexpr double kPerObject = 64;  // a hash map's slot with its load factor, in the index and in each replay
  ResourceNeeds needs;
  needs.task = fmt::format("cachebench --synthetic {}", spec);
  needs.memory.bytes =
      saturating_bytes(records * (sizeof(TraceRecord) + 16) + tables + objects * kPerObject * (1 + replays));
  needs.memory.why = fmt::format("{} records and {} objects", format_count(records), format_count(objects));
  needs.memory.lower = "fewer requests, objects or passes in --synthetic lower it, as do fewer --threads";
  return needs;
}

/// "zipf:objects=10000,requests=1000000,alpha=0.9,seed=1", "scan:objects=N,passes=P",
/// "loop:objects=N,passes=P" (each may add size=BYTES). Refused before it is generated when the
/// replays would not fit in memory (`replays`: how many run at once).
Trace synthetic_trace(const std::string& spec, double replays) {
  const size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  std::map<std::string, double> p = {{"objects", 10000}, {"requests", 1000000}, {"alpha", 0.9},
                                     {"seed", 1},        {"passes", 10},         {"size", 1}};
  if (colon != std::string::npos)
    for (const auto& kv : split_list(spec.substr(colon + 1), ',')) {
      auto [name, value] = parse_assignment(kv, "--synthetic");
      if (!p.contains(name))
        throw Error(Errc::invalid_argument, fmt::format("'{}' is not a parameter (objects, requests, alpha, seed, passes, size)", name))
            .with_field("--synthetic");
      p[name] = value;
    }
  if (p["objects"] < 1 || p["size"] < 1 || p["size"] > 4e9)
    throw Error(Errc::invalid_argument, "objects and size must be positive").with_field("--synthetic");
  if (p["requests"] < 0 || p["passes"] < 0)
    throw Error(Errc::invalid_argument, "requests and passes must be at least 0").with_field("--synthetic");
  if (kind == "zipf" || kind == "scan" || kind == "loop") check_resources(synthetic_trace_needs(spec, kind, p, replays));
  const uint32_t size = uint32_t(p["size"]);
  if (kind == "zipf") return zipf_trace(uint64_t(p["objects"]), uint64_t(p["requests"]), p["alpha"], uint64_t(p["seed"]), size);
  if (kind == "scan") return scan_trace(uint64_t(p["objects"]), uint64_t(p["passes"]), size);
  if (kind == "loop") return loop_trace(uint64_t(p["objects"]), uint64_t(p["passes"]), size);
  throw Error(Errc::invalid_argument, fmt::format("unknown synthetic trace '{}' (zipf, scan, loop)", kind)).with_field("--synthetic");
}

struct SizeSpec {
  std::string label;
  uint64_t bytes;
  double fraction;  // of the working set
};

std::vector<SizeSpec> parse_sizes(const std::string& text, uint64_t working_set) {
  std::vector<SizeSpec> out;
  for (const auto& s : split_list(text, ',')) {
    if (!s.empty() && s.back() == '%') {
      double pct = 0;
      try {
        size_t used = 0;
        pct = std::stod(s.substr(0, s.size() - 1), &used);
        if (used != s.size() - 1) throw std::invalid_argument(s);
      } catch (const std::exception&) {
        throw Error(Errc::invalid_argument, fmt::format("'{}' is not a percentage", s)).with_field("--sizes");
      }
      if (!(pct > 0 && pct <= 1000))
        throw Error(Errc::invalid_argument, fmt::format("'{}' must be in (0%, 1000%]", s)).with_field("--sizes");
      out.push_back({s, std::max<uint64_t>(1, uint64_t(double(working_set) * pct / 100.0)), pct / 100.0});
    } else {
      const uint64_t b = parse_bytes(s, "--sizes");
      out.push_back({s, b, double(b) / double(std::max<uint64_t>(working_set, 1))});
    }
  }
  return out;
}

void write_plot(const std::string& png, const std::string& csv_for_plot, const std::vector<std::string>& policies,
                const std::string& title) {
  std::string body = "set datafile separator ','\n";
  body += fmt::format("set title {} noenhanced\n", gnuplot_quote(title));
  body += "set logscale x\nset xlabel 'cache size (fraction of the working set)'\nset ylabel 'miss ratio'\n"
          "set yrange [0:1]\nset grid\nset key outside right\nset format x '%g'\n"
          "plot ";
  for (size_t i = 0; i < policies.size(); ++i)
    body += fmt::format("{}{} using (strcol(1) eq {} ? $2 : 1/0):6 with linespoints lw 2 title {}", i ? ", " : "",
                        gnuplot_quote(csv_for_plot), gnuplot_quote(policies[i]), gnuplot_quote(policies[i]));
  body += "\n";
  run_gnuplot(body, png, 900, 600);
}

void run_cachebench(const CachebenchOptions& o) {
  if (o.trace.empty() == o.synthetic.empty())
    throw Error(Errc::invalid_argument, "give a TRACE file or --synthetic (one of them)").with_field("TRACE");
  // The outputs, before a long read and replay.
  for (const std::string* path : {&o.convert, &o.csv, &o.plot})
    if (!path->empty()) check_writable(*path);
  if (!o.plot.empty() && o.csv.empty() && o.convert.empty()) check_writable(o.plot + ".csv");
  const double replays = o.convert.empty() ? std::min<double>(tbb::this_task_arena::max_concurrency(),
                                                               double(split_list(o.policies, ',').size() *
                                                                      split_list(o.sizes, ',').size()))
                                           : 0;
  Trace trace = !o.synthetic.empty() ? synthetic_trace(o.synthetic, replays)
                : o.format.empty()   ? read_trace(o.trace)
                                     : read_trace(o.trace, naming_options({{"trace_format", "--format"}}, [&] {
                                         return parse_trace_format(o.format);
                                       }));
  if (!o.kind.empty()) trace = trace.of_kind(record_kind_from_string(o.kind, "--kind"));
  if (!o.convert.empty()) {
    write_trace(o.convert, trace, naming_options({{"trace_format", "--to"}}, [&] { return parse_trace_format(o.to); }));
    std::cout << fmt::format("wrote {} ({} records, {} format)\n", o.convert, trace.records.size(), o.to);
    return;
  }
  const std::vector<std::string> policies = split_list(o.policies, ',');
  for (const auto& p : policies) make_policy(p, 1);  // unknown names fail before any work
  uint64_t demand = 0, fills = 0;
  for (const auto& r : trace.records) {
    demand += r.kind == AccessKind::demand || r.kind == AccessKind::blocking;
    fills += r.kind == AccessKind::prefetch_fill;
  }
  if (demand == 0) throw Error(Errc::invalid_argument, "the trace has no demand accesses to replay").with_file(o.trace);
  const uint64_t working_set = trace.unique_bytes();
  const std::vector<SizeSpec> sizes = parse_sizes(o.sizes, working_set);
  const std::string name = o.synthetic.empty() ? o.trace : o.synthetic;
  std::cout << fmt::format("trace {}: {} requests, {} prefetch fills, {} objects, working set {}, {} frames\n", name,
                           format_count(double(demand)), format_count(double(fills)), format_count(double(trace.unique_objects())),
                           format_bytes(double(working_set)), trace.frames());
  if (const std::vector<RecordKind> kinds = trace.record_kinds(); kinds.size() > 1 || (kinds.size() == 1 && kinds[0] != RecordKind::brick)) {
    std::string line;
    for (RecordKind k : kinds) {
      const Trace part = trace.of_kind(k);
      line += fmt::format("{}{} {} objects ({})", line.empty() ? "" : ", ", to_string(k), format_count(double(part.unique_objects())),
                          format_bytes(double(part.unique_bytes())));
    }
    std::cout << "  record kinds: " << line << (kinds.size() > 1 ? " (replayed together; --kind replays one)" : "") << "\n";
  }

  const std::vector<uint64_t> next = next_demand_access(trace);
  std::vector<ReplayResult> results(policies.size() * sizes.size());
  parallel_for<size_t>(0, results.size(), 1, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) results[i] = replay(trace, next, policies[i / sizes.size()], sizes[i % sizes.size()].bytes);
  });
  auto at = [&](size_t p, size_t s) -> const ReplayResult& { return results[p * sizes.size() + s]; };

  auto table = [&](const char* title, auto metric) {
    std::cout << fmt::format("\n{:<12}", title);
    for (const auto& s : sizes) std::cout << fmt::format("{:>9}", s.label);
    std::cout << '\n';
    for (size_t p = 0; p < policies.size(); ++p) {
      std::cout << fmt::format("{:<12}", policies[p]);
      for (size_t s = 0; s < sizes.size(); ++s) std::cout << fmt::format("{:>9.4f}", metric(at(p, s)));
      std::cout << '\n';
    }
  };
  table("miss ratio", [](const ReplayResult& r) { return r.miss_ratio(); });
  table("byte miss", [](const ReplayResult& r) { return r.byte_miss_ratio(); });

  // Distance of the best online policy from OPT, when OPT was asked for.
  const auto opt = std::find(policies.begin(), policies.end(), "opt");
  if (opt != policies.end() && policies.size() > 1) {
    std::cout << "\nbest online policy against OPT\n";
    const size_t o_index = size_t(opt - policies.begin());
    bool below_opt = false;
    for (size_t s = 0; s < sizes.size(); ++s) {
      size_t best = policies.size();
      for (size_t p = 0; p < policies.size(); ++p)
        if (p != o_index && (best == policies.size() || at(p, s).miss_ratio() < at(best, s).miss_ratio())) best = p;
      std::cout << fmt::format("  {:>8}: {:<10} {:.4f}  opt {:.4f}  gap {:+.4f}\n", sizes[s].label, policies[best],
                               at(best, s).miss_ratio(), at(o_index, s).miss_ratio(),
                               at(best, s).miss_ratio() - at(o_index, s).miss_ratio());
      below_opt |= at(best, s).miss_ratio() < at(o_index, s).miss_ratio();
    }
    // Said, not hidden: a negative gap reads as a broken replay otherwise.
    if (below_opt)
      std::cout << "  a negative gap: OPT (Belady) is a bound when every object keeps one size and every miss is "
                   "inserted; with sizes that vary, or lru-frame's refused insertions, it is a heuristic\n";
  }
  std::cout << "\nper policy (at the largest size): replay speed, metadata, evictions, prefetch\n";
  for (size_t p = 0; p < policies.size(); ++p) {
    const ReplayResult& r = at(p, sizes.size() - 1);
    std::cout << fmt::format("  {:<10} {:>8} req/s  {:>6.1f} B/entry  {:>8} evictions  {} failed", policies[p],
                             format_count(r.requests_per_second()), r.metadata_bytes_per_entry, r.evictions,
                             r.failed_evictions);
    if (r.prefetches)
      std::cout << fmt::format("  prefetch accuracy {:.3f} coverage {:.3f} late {} wasted {}", r.prefetch_accuracy(),
                               r.prefetch_coverage(), r.late_prefetches, format_bytes(double(r.prefetch_wasted_bytes)));
    std::cout << '\n';
  }
  if (o.windows) {
    std::cout << "\nmiss ratio over time (windows), at the smallest size\n";
    for (size_t p = 0; p < policies.size(); ++p) {
      std::cout << fmt::format("  {:<10}", policies[p]);
      for (double m : at(p, 0).miss_ratio_windows) std::cout << fmt::format(" {:.2f}", m);
      std::cout << '\n';
    }
  }

  const std::string csv = !o.csv.empty() ? o.csv : (!o.plot.empty() ? o.plot + ".csv" : std::string());
  if (!csv.empty()) {
    std::string out = "policy,size_fraction,capacity_bytes,requests,misses,miss_ratio,byte_miss_ratio,evictions,failed_evictions,"
           "prefetches,prefetch_accuracy,prefetch_coverage,late_prefetches,prefetch_wasted_bytes,metadata_bytes_per_entry,"
           "requests_per_second,miss_ratio_windows\n";
    for (size_t p = 0; p < policies.size(); ++p)
      for (size_t s = 0; s < sizes.size(); ++s) {
        const ReplayResult& r = at(p, s);
        std::string windows;
        for (double m : r.miss_ratio_windows) windows += fmt::format("{}{:.4f}", windows.empty() ? "" : ";", m);
        out += fmt::format("{},{:g},{},{},{},{:.6f},{:.6f},{},{},{},{:.4f},{:.4f},{},{},{:.1f},{:.0f},{}\n", policies[p],
                           sizes[s].fraction, r.capacity, r.requests, r.misses, r.miss_ratio(), r.byte_miss_ratio(),
                           r.evictions, r.failed_evictions, r.prefetches, r.prefetch_accuracy(), r.prefetch_coverage(),
                           r.late_prefetches, r.prefetch_wasted_bytes, r.metadata_bytes_per_entry,
                           r.requests_per_second(), windows);
      }
    AtomicFile file(csv);  // (refuses a path that is not a regular file)
    file.write(out.data(), out.size());
    file.commit();
    std::cout << fmt::format("\nwrote {}\n", csv);
  }
  if (!o.plot.empty()) {
    write_plot(o.plot, csv, policies, fmt::format("miss ratio curve: {}", name));
    std::cout << fmt::format("wrote {}\n", o.plot);
  }
}

struct FlightCliOptions {
  std::string store, path = "scenes/flight-orbit.json", trace, stats;
  std::string l1 = "256MiB", l2 = "1GiB", l1_policy = "lru", l2_policy = "lru";
  uint32_t upload_budget = 0;
  int frames = 0, loaders = 2, time_step = 0;
  bool frames_given = false;  ///< --frames on the command line (0 there is not "the path's")
  double lod = 1.0;
  std::string values;
  bool allow_damaged = false;
};

int run_flight(const FlightCliOptions& o) {
  if (!(std::isfinite(o.lod) && o.lod > 0))
    throw Error(Errc::invalid_argument, fmt::format("{} is not a positive, finite number of pixels", o.lod)).with_field("--lod");
  if (o.frames_given && o.frames < 1)
    throw Error(Errc::invalid_argument, fmt::format("{} frames: give at least 1, or leave --frames out for the path's own", o.frames))
        .with_field("--frames");
  // Outputs written after the flight are checked before it (the trace by the cache).
  if (!o.stats.empty()) check_writable(o.stats);
  Store store(o.store);
  CacheConfig c;
  c.l1_bytes = parse_bytes(o.l1, "--l1");
  c.l2_bytes = parse_bytes(o.l2, "--l2");
  c.l1_policy = o.l1_policy;
  c.l2_policy = o.l2_policy;
  c.upload_pages_per_frame = o.upload_budget;
  c.loader_threads = o.loaders;
  c.trace_path = o.trace;
  {
    // The L1 pool is allocated whole when the cache is made; L2 fills only as far as it is used.
    ResourceNeeds needs;
    needs.task = fmt::format("flight with an L1 pool of {}", format_bytes(double(c.l1_bytes)));
    needs.memory = {c.l1_bytes, "the L1 pool, allocated up front", "a smaller --l1"};
    check_resources(needs);
  }
  const CameraPath path = CameraPath::load(o.path);
  FlightOptions f;
  f.lod_ratio = o.lod;
  f.frames = o.frames;
  std::string stats_json;
  std::vector<std::string> unreadable;
  const auto collect_unreadable = [&](const PageCache& cache) {
    for (const PageCache::FailedPage& p : cache.failed_pages()) unreadable.push_back(p.error);
  };
  if (store.kind() == DataKind::tetrahedral) {
    if (o.time_step < 0 || o.time_step >= store.manifest().time_steps)
      throw Error(Errc::invalid_argument, fmt::format("time step {} of a mesh with {}", o.time_step, store.manifest().time_steps))
          .with_field("--time-step");
    f.time_step = o.time_step;
    if (!o.values.empty()) std::tie(f.values_lo, f.values_hi) = parse_range(o.values, "--values");
    PageCache cache(store, c);
    std::cout << fmt::format("flight over {} ({} clusters, {} L1 slots, L2 {}), {} frames at {}x{}\n", o.store,
                             store.clusters().size(), cache.pool_slots(RecordKind::tet_cluster),
                             format_bytes(double(c.l2_bytes)), f.frames ? f.frames : path.frames, path.width, path.height);
    uint64_t used = 0, hits = 0;
    fly_clusters(cache, store.dataset().tets(), store.dataset().info().world, path, f, [&](const FlightFrame& r) {
      used += r.bricks_used;
      hits += r.hits;
      if (r.frame % 10 == 0)
        std::cout << fmt::format("  frame {:>4}: {:>6} clusters, {:>5.1f}% resident, {:>5} requests, {:>5} uploads, {}\n", r.frame,
                                 r.bricks_used, r.bricks_used ? 100.0 * double(r.hits) / double(r.bricks_used) : 100.0,
                                 r.requests, r.uploads, format_duration(r.seconds));
    });
    const CacheStats s = cache.stats(RecordKind::tet_cluster);
    std::cout << fmt::format("clusters looked up {}, resident when asked {:.1f}%; L1 {} evictions; L2 peak {} of {}; "
                             "read {} from the store\n",
                             used, used ? 100.0 * double(hits) / double(used) : 100.0, s.l1.evictions,
                             format_bytes(double(s.l2_peak_bytes)), format_bytes(double(c.l2_bytes)),
                             format_bytes(double(s.l3_bytes_read)));
    stats_json = s.to_json();
    collect_unreadable(cache);
    cache.close();  // writes the trace, or throws before it is reported written
  } else {
    if (!o.values.empty()) throw Error(Errc::invalid_argument, "--values applies to meshes").with_file(o.store);
    if (o.time_step < 0 || o.time_step >= store.time_steps())
      throw Error(Errc::invalid_argument, fmt::format("time step {} of a grid with {}", o.time_step, store.time_steps()))
          .with_field("--time-step");
    GridCache grid_cache(store, c, o.time_step);
    BrickCache& cache = grid_cache.bricks();
    std::cout << fmt::format("flight over {} ({} levels, {} L1 slots, L2 {}), {} frames at {}x{}\n", o.store,
                             store.layout().levels, cache.pool_slots(), format_bytes(double(c.l2_bytes)),
                             f.frames ? f.frames : path.frames, path.width, path.height);
    uint64_t used = 0, hits = 0;
    fly(cache, path, f, [&](const FlightFrame& r) {
      used += r.bricks_used;
      hits += r.hits;
      if (r.frame % 10 == 0)
        std::cout << fmt::format("  frame {:>4}: {:>6} nodes, {:>6} bricks, {:>5.1f}% resident, {:>5} requests, {:>5} uploads, {}\n",
                                 r.frame, r.nodes_visited, r.bricks_used,
                                 r.bricks_used ? 100.0 * double(r.hits) / double(r.bricks_used) : 100.0, r.requests,
                                 r.uploads, format_duration(r.seconds));
    });
    const CacheStats s = cache.stats();
    std::cout << fmt::format("bricks looked up {}, resident when asked {:.1f}%; L1 {} evictions; L2 peak {} of {}; "
                             "read {} from the store; request latency p50 {:.2f} ms p99 {:.2f} ms\n",
                             used, used ? 100.0 * double(hits) / double(used) : 100.0, s.l1.evictions,
                             format_bytes(double(s.l2_peak_bytes)), format_bytes(double(c.l2_bytes)),
                             format_bytes(double(s.l3_bytes_read)), s.latency_p50_ms, s.latency_p99_ms);
    stats_json = s.to_json();
    collect_unreadable(cache.pages());
    grid_cache.close();  // writes the trace, or throws before it is reported written
  }
  if (!o.stats.empty()) {
    write_file_atomically(o.stats, stats_json + "\n");
    std::cout << fmt::format("wrote {}\n", o.stats);
  }
  if (!o.trace.empty()) std::cout << fmt::format("wrote {} (replay it with brickyard cachebench)\n", o.trace);
  return report_unreadable(unreadable, o.allow_damaged);
}

}  // namespace

void add_cache_commands(CLI::App& app, int& exit_status) {
  {
    auto o = std::make_shared<FlightCliOptions>();
    auto* cmd = app.add_subcommand("flight", "Fly a camera path through a store's cache, as a level-of-detail renderer would");
    cmd->add_option("STORE", o->store, "Store directory")->required();
    cmd->add_option("--path", o->path, "Camera path (JSON, normalised to the volume's box)")->capture_default_str();
    CLI::Option* frames = cmd->add_option("--frames", o->frames, "Frames (default: the path's)");
    cmd->add_option("--lod", o->lod, "Refine while a voxel covers more than this many pixels")->capture_default_str();
    cmd->add_option("--l1", o->l1, "L1 pool size")->capture_default_str();
    cmd->add_option("--l2", o->l2, "L2 host cache budget")->capture_default_str();
    cmd->add_option("--l1-policy", o->l1_policy, "L1 policy")->capture_default_str();
    cmd->add_option("--l2-policy", o->l2_policy, "L2 policy")->capture_default_str();
    cmd->add_option("--upload-budget", o->upload_budget, "Bricks uploaded into L1 per frame (0: unlimited)");
    cmd->add_option("--loaders", o->loaders, "Loader threads")->capture_default_str();
    cmd->add_option("--trace", o->trace, "Record every access to this trace file");
    cmd->add_option("--values", o->values, "Meshes: only clusters whose values meet LO,HI (an isovalue: V,V)");
    cmd->add_option("--time-step", o->time_step, "The time step flown over (grids), or whose value ranges --values tests (meshes)")
        ->capture_default_str();
    cmd->add_option("--stats", o->stats, "Write the cache statistics as JSON");
    cmd->add_flag("--allow-damaged", o->allow_damaged,
                  "Exit 0 when records of the store cannot be read (listed; without it the exit status is 3)");
    cmd->callback([o, frames, &exit_status] {
      o->frames_given = frames->count() > 0;
      exit_status = naming_options({{"l1_bytes", "--l1"}, {"l1_slots", "--l1"}, {"slots", "--l1"}, {"l2_bytes", "--l2"},
                                    {"loader_threads", "--loaders"}, {"policy", "--l1-policy"}, {"l2_policy", "--l2-policy"}},
                                   [&] { return run_flight(*o); });
    });
  }
  {
  auto o = std::make_shared<CachebenchOptions>();
  auto* cmd = app.add_subcommand("cachebench", "Replay an access trace against cache policies and sizes");
  cmd->add_option("TRACE", o->trace,
                  "Trace file: brickyard (.bytrace, from a cache's trace_path), libCacheSim oracleGeneral "
                  "(.oracleGeneral), or text (.txt: 'key size [kind]' per line)");
  cmd->add_option("--format", o->format, "Input format when the name does not say: brickyard, oracleGeneral, text");
  cmd->add_option("--synthetic", o->synthetic,
                  "Generate instead of reading: zipf:objects=N,requests=M,alpha=A,seed=S | scan:objects=N,passes=P | "
                  "loop:objects=N,passes=P (each may add size=BYTES)");
  cmd->add_option("--policies", o->policies, "Comma-separated policies (opt is Belady's bound)")->capture_default_str();
  cmd->add_option("--sizes", o->sizes, "Comma-separated sizes: N% of the working set or bytes (64MiB)")->capture_default_str();
  cmd->add_option("--csv", o->csv, "Write every result (and the miss ratio over time) as CSV");
  cmd->add_option("--plot", o->plot, "Draw the miss-ratio curves with gnuplot into this PNG (its CSV goes next to it)");
  cmd->add_option("--kind", o->kind, "Replay only this record kind's accesses: brick, octree_page, tet_cluster");
  cmd->add_flag("--windows", o->windows, "Print the miss ratio over time (frame windows) at the smallest size");
  cmd->add_option("--convert", o->convert, "Write the trace to this file in --to format instead of replaying it");
  cmd->add_option("--to", o->to, "Format for --convert: brickyard, oracleGeneral, text")->capture_default_str();
  cmd->callback([o] { naming_options({{"policy", "--policies"}}, [&] { run_cachebench(*o); }); });
  }
}

}  // namespace brickyard::cli
