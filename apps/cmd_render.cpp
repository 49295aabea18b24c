// `brickyard render` and `brickyard bench`: render a scene with one back end, or every back end
// at a sweep of its quality knob against the reference renderer.

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <string_view>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "apps/parse.h"
#include "core/atomic_file.h"
#include "core/error.h"
#include "core/raw_volume.h"
#include "core/resources.h"
#include "core/timing.h"
#include "core/units.h"
#include "report/bench_report.h"
#include "report/peer_results.h"
#include "renderers/common/metrics.h"
#include "session/render_session.h"

namespace brickyard::cli {
namespace fs = std::filesystem;

namespace {

/// "all", or a comma-separated list of N and A-B (inclusive) -> frame numbers within
/// [0, count), in the order given ("0,90,10-12": a jump, then three frames). `option` is the
/// flag that gave the text, for errors.
std::vector<int> parse_frames(const std::string& text, int count, std::string_view option = "--frames") {
  std::vector<int> out;
  if (text.empty()) return {0};
  if (text == "all") {
    for (int f = 0; f < count; ++f) out.push_back(f);
    return out;
  }
  for (const std::string& item : split_list(text)) {
    const size_t dash = item.find('-', 1);
    std::vector<int64_t> ints;
    try {
      ints = parse_int_list(dash == std::string::npos ? item : item.substr(0, dash) + "," + item.substr(dash + 1),
                            dash == std::string::npos ? 1 : 2, option);
    } catch (const Error&) {
      throw Error(Errc::invalid_argument, fmt::format("'{}' is not a frame N or a range A-B", item)).with_field(option);
    }
    const int64_t a = ints[0], b = ints.size() > 1 ? ints[1] : ints[0];
    if (b < a)
      throw Error(Errc::invalid_argument, fmt::format("'{}' runs backwards: write the first frame first", item))
          .with_field(option);
    if (a < 0 || b >= count)
      throw Error(Errc::invalid_argument, fmt::format("'{}' is outside the scene's frames 0-{}", item, count - 1)).with_field(option);
    for (int64_t f = a; f <= b; ++f) out.push_back(int(f));
  }
  return out;
}

bool has_png_extension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext == ".png";
}

/// A directory outputs go into: absent (it is created) or a directory, never a file.
void check_output_directory(const std::string& dir, std::string_view option) {
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw Error(Errc::invalid_argument, "exists and is not a directory: give a directory for the files it writes")
        .with_field(option)
        .with_file(dir);
}

/// out.png -> out_0007.png when rendering frames of a camera path.
std::string frame_path(const std::string& path, int frame, bool several) {
  if (path.empty() || !several) return path;
  const fs::path p(path);
  return (p.parent_path() / fmt::format("{}_{:04d}{}", p.stem().string(), frame, p.extension().string())).string();
}

std::map<std::string, double> parse_sets(const std::vector<std::string>& sets, const char* option) {
  std::map<std::string, double> out;
  for (const auto& s : sets) {
    auto [k, v] = parse_assignment(s, option);
    out[k] = v;
  }
  return out;
}

void write_text(const std::string& path, const std::string& text) { write_file_atomically(path, text); }

double median_of(std::vector<double> v);
double p95_of(std::vector<double> v);

struct RenderOptions {
  std::string dataset;
  std::string scene, out, depth, normals, stats, frames, backend, error_maps;
  std::vector<std::string> sets;
  std::optional<int> time_step;
  bool list = false;
  bool settle = false;
  bool allow_damaged = false;
};

void print_backends() {
  for (const BackendEntry& e : backends().entries()) {
    std::string modes, kinds;
    for (RenderMode m : e.info.modes) modes += fmt::format("{}{}", modes.empty() ? "" : ",", to_string(m));
    for (DataKind k : e.info.kinds) kinds += fmt::format("{}{}", kinds.empty() ? "" : ",", to_string(k));
    std::cout << fmt::format("{}  ({}; {})\n    {}\n", e.info.name, modes, kinds, e.info.description);
    for (const BackendParam& p : e.info.params)
      std::cout << fmt::format("    {:<10} default {:<8g} [{:g}, {:g}]  {}\n", p.name, p.default_value, p.lo, p.hi, p.doc);
    if (!e.info.quality_param.empty()) {
      std::string sweep;
      for (double v : e.info.quality_sweep) sweep += fmt::format("{}{:g}", sweep.empty() ? "" : ",", v);
      std::cout << fmt::format("    bench sweeps {} = {}\n", e.info.quality_param, sweep);
    }
  }
}

/// Bytes a frame holds per pixel: colour (16), depth (4), normals (12), and the 8-bit copy a
/// PNG is written from (4).
constexpr double kFrameBytesPerPixel = 36;

uint32_t pixel_state_bytes(const std::string& backend) {
  try {
    return backends().find(backend).info.pixel_state_bytes;
  } catch (const Error&) {
    return 0;  // an unknown name: the session refuses it, naming the scene's key
  }
}

/// The memory frames will hold, refused before the store is opened: `frame_pixels` pixels of
/// frame buffers, `state_bytes` of the back ends' per-pixel state, and the L1 pools (allocated
/// when a cache opens; L2 fills only with what the frames read, so its budget is not counted).
void check_frame_memory(const std::string& task, double frame_pixels, double state_bytes, double l1_bytes,
                        const std::string& lower) {
  ResourceNeeds needs;
  needs.task = task;
  needs.memory.bytes = saturating_bytes(frame_pixels * kFrameBytesPerPixel + state_bytes + l1_bytes);
  needs.memory.why = "frame buffers, the back end's per-pixel state and the L1 pool";
  needs.memory.lower = lower;
  check_resources(needs);
}

int run_render(const RenderOptions& o) {
  if (o.list) {
    print_backends();
    return 0;
  }
  if (o.scene.empty()) throw Error(Errc::invalid_argument, "a scene file is required").with_field("SCENE");
  if (o.out.empty()) throw Error(Errc::invalid_argument, "an output PNG is required").with_field("-o");
  for (const auto& [path, option] : {std::pair{&o.out, "-o"}, {&o.depth, "--depth"}, {&o.normals, "--normals"}}) {
    if (path->empty()) continue;
    refuse_to_replace_non_regular(*path);  // (a device or a FIFO is refused as such, whatever its name)
    if (!has_png_extension(*path))
      throw Error(Errc::invalid_argument, "images are written as PNG: give the file a .png name").with_field(option).with_file(*path);
  }
  if (!o.error_maps.empty()) check_output_directory(o.error_maps, "--error-maps");
  Scene scene = load_scene(o.scene);
  if (!o.dataset.empty()) scene.dataset = o.dataset;
  // The time step is the scene's, not a back end's parameter; `--set time_step=K` is taken for
  // --time-step K, as a user reaching for --set first would write it.
  std::vector<std::string> sets;
  std::optional<int> time_step = o.time_step;
  for (const std::string& s : o.sets) {
    if (s.rfind("time_step=", 0) != 0) {
      sets.push_back(s);
      continue;
    }
    const double v = parse_number(s.substr(10), "--set time_step");
    if (!(v >= 0) || v != std::floor(v) || v > double(1 << 20))
      throw Error(Errc::invalid_argument, fmt::format("'{}' is not a time step", s.substr(10))).with_field("--set time_step");
    time_step = int(v);
  }
  if (time_step) {
    if (*time_step < 0) throw Error(Errc::invalid_argument, "a time step is 0 or more").with_field("--time-step");
    scene.time_step = *time_step;
    scene.time_count = 1;
  }
  {
    const double pixels = double(scene.width) * double(scene.height);
    const double sessions = o.error_maps.empty() ? 1 : 2;  // --error-maps renders the reference beside
    const uint32_t state = pixel_state_bytes(o.backend.empty() ? scene.backend : o.backend);
    check_frame_memory(fmt::format("render of {}x{} pixels", scene.width, scene.height), pixels * sessions,
                       pixels * state, double(scene.cache.l1_bytes) * sessions,
                       "a smaller image (the scene's image.width and image.height) or cache.l1 lowers it");
  }
  RenderSession::Options opts;
  opts.backend = o.backend;
  opts.params = parse_sets(sets, "--set");
  RenderSession session(scene, opts);
  const std::vector<int> frames = parse_frames(o.frames, scene.frames());
  for (const std::string* path : {&o.out, &o.depth, &o.normals, &o.stats})
    if (!path->empty() && fs::path(*path).has_parent_path()) fs::create_directories(fs::path(*path).parent_path());
  const bool several = frames.size() > 1 || scene.has_path;  // path frames are always numbered
  FrameOutputs outputs;
  outputs.depth = true;
  outputs.normals = !o.normals.empty() || !o.error_maps.empty();
  std::unique_ptr<RenderSession> reference;
  if (!o.error_maps.empty()) {
    RenderSession::Options ro;
    ro.backend = "reference";
    reference = std::make_unique<RenderSession>(scene, ro);
    fs::create_directories(o.error_maps);
  }
  nlohmann::json all = nlohmann::json::array();
  int below_quality = 0;  // frames delivered below the quality asked (FrameStats::below_quality)
  for (int f : frames) {
    FrameBuffers fb;
    // A still camera shows the converged image (asynchronous back ends refine over frames as
    // their data arrives), and none before it: those are completed at once. A camera path is
    // flown frame by frame unless --settle, which counts the frames a viewer sees converge.
    int settle_frames = 0;
    if (!scene.has_path) settle_frames = session.settle(f, outputs, RenderSession::kMaxSettleFrames, RenderSession::Settle::complete);
    else if (o.settle) settle_frames = session.settle(f, outputs);
    const FrameStats stats = session.render(f, fb, outputs);
    write_png(frame_path(o.out, f, several), to_rgba8(fb.color));
    if (!o.depth.empty()) write_png(frame_path(o.depth, f, several), depth_to_rgba8(fb.depth));
    if (!o.normals.empty()) write_png(frame_path(o.normals, f, several), normals_to_rgba8(fb.normal));
    nlohmann::json j = nlohmann::json::parse(stats.to_json());
    j["settle_frames"] = settle_frames;
    std::string error_line;
    if (reference) {
      FrameBuffers ref;
      reference->render(f, ref, outputs);
      const ImageError err = compare_frames(fb, ref, session.context().geometry().voxel_size);
      const ErrorMaps maps = write_error_maps(fb, ref, session.context().geometry().voxel_size,
                                              (fs::path(o.error_maps) / fmt::format("frame_{:04d}", f)).string());
      j["error"] = nlohmann::json::parse(err.to_json());
      error_line = fmt::format(", RMSE {:.4g}, SSIM {:.4f}, depth p99 {:.3g} voxels, coverage mismatch {}",
                               err.rmse, err.ssim, err.depth_p99, err.coverage_mismatch);
    }
    all.push_back(j);
    // Said once a run on the terminal (each frame's reason is in --stats), then counted.
    if (!stats.below_quality.empty() && below_quality++ == 0)
      std::cerr << fmt::format("brickyard: warning: frame {} is below the quality asked: {}\n", f, stats.below_quality);
    std::cout << fmt::format("frame {}: {} {}x{} in {} ({} rays/s on {} threads, {} samples, {} bricks, {} requests){}\n", f,
                             session.backend().name, stats.width, stats.height, format_duration(stats.seconds),
                             format_count(stats.seconds > 0 ? double(stats.counters.rays) / stats.seconds : 0),
                             stats.threads, format_count(double(stats.counters.samples)),
                             format_count(double(stats.counters.bricks)), stats.requests, error_line);
  }
  if (frames.size() > 1) {
    // A flight's summary: frame time, and the back end's own figures averaged over frames.
    std::vector<double> seconds;
    double bytes = 0, settle = 0;
    std::map<std::string, double> sums;
    for (const auto& j : all) {
      seconds.push_back(j["seconds"].get<double>());
      bytes += j["cache"]["bytes_read"].get<double>();
      settle += j["settle_frames"].get<double>();
      for (auto it = j["backend"].begin(); it != j["backend"].end(); ++it) sums[it.key()] += it->get<double>();
    }
    const double n = double(all.size());
    std::cout << fmt::format("{} frames: median {}, p95 {}, {} read per frame", all.size(), format_duration(median_of(seconds)),
                             format_duration(p95_of(seconds)), format_bytes(bytes / n));
    if (settle > 0)
      std::cout << fmt::format(", {:.1f} frames {} per frame", settle / n,
                               scene.has_path ? "to converge" : "to settle (each completed at once where the back end can)");
    if (below_quality > 0) std::cout << fmt::format(", {} of them below the quality asked", below_quality);
    std::cout << "\n";
    if (!sums.empty()) {
      std::string line;
      for (const auto& [name, sum] : sums) line += fmt::format("{}{} {:.4g}", line.empty() ? "" : ", ", name, sum / n);
      std::cout << "  mean " << line << "\n";
    }
  }
  // Both sessions' caches: the reference's reads the same store.
  std::vector<std::string> unreadable;
  for (RenderSession* s : {&session, reference.get()})
    if (s)
      for (const PageCache::FailedPage& p : s->pages().failed_pages())
        if (std::find(unreadable.begin(), unreadable.end(), p.error) == unreadable.end()) unreadable.push_back(p.error);
  if (!o.stats.empty()) {
    nlohmann::json j;
    j["scene"] = o.scene;
    j["backend"] = session.backend().name;
    j["params"] = session.params().values();
    j["frames"] = all;
    j["frames_below_quality"] = below_quality;
    j["cache"] = nlohmann::json::parse(session.pages().stats().to_json());
    j["unreadable"] = unreadable;
    write_text(o.stats, j.dump(2) + "\n");
  }
  return report_unreadable(unreadable, o.allow_damaged);
}

// --- bench ---------------------------------------------------------------------------------

constexpr int kMaxImageSide = 16384;

struct BenchOptions {
  std::string dataset;
  std::string scene, out = "out/bench", backends = "all", frame = "0";
  std::vector<std::string> quality;
  int warm = 5, cold = 3;
  int reference_supersample = 1;
  std::string size;
  std::string peers;
};

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : (v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]));
}
double p95_of(std::vector<double> v) { return v.empty() ? 0 : percentile(v, 95); }

/// The first frames of a cold run: the first frame from empty caches (its time and error),
/// then the frames a viewer would see, each followed by the loads it asked for, until the back
/// end converges.
struct ColdRun {
  double first_s = 0, converged_s = 0;
  int frames = 0;
  ImageError first_error;
};

ColdRun cold_run(RenderSession& session, const FrameSetup& setup, const FrameBuffers* truth, double voxel_size,
                 FrameBuffers& scratch) {
  ColdRun run;
  Stopwatch wall;
  const FrameStats first = session.render(setup, scratch);
  run.first_s = first.seconds;
  run.frames = 1;
  // The error is computed off the clock: the frames after it start when it is done, and the
  // wall time to convergence counts only rendering and loading.
  const double before_error = wall.seconds();
  if (truth) run.first_error = compare_frames(scratch, *truth, voxel_size);
  double off_clock = wall.seconds() - before_error;
  session.pages().wait_idle();
  while (!session.converged() && run.frames < RenderSession::kMaxSettleFrames) {
    session.render(setup, scratch);
    session.pages().wait_idle();
    ++run.frames;
  }
  run.converged_s = wall.seconds() - off_clock;
  return run;
}

/// From empty caches to a still camera's converged image, asked for at once (no frame shown
/// before it, as `brickyard render` asks): its wall time and frames.
std::pair<double, int> still_run(RenderSession& session, const FrameSetup& setup, FrameBuffers& scratch) {
  session.reset_cache();
  Stopwatch wall;
  const int frames = session.complete(setup, scratch);
  return {wall.seconds(), frames};
}

/// Times `cold` runs from empty caches (cold_run()), as many still ones (still_run()), and
/// `warm` frames on warmed caches;
/// returns the row and the last warm frame. `truth` (null for the reference itself) gives the
/// first frames' error.
BenchRow measure(RenderSession& session, int frame, int cold, int warm, const FrameOutputs& outputs, FrameBuffers& last,
                 const FrameBuffers* truth, double voxel_size) {
  BenchRow row;
  std::vector<double> first_s, converged_s, frames, first_rmse, first_ssim;
  const FrameSetup setup = session.setup(frame, outputs);
  for (int i = 0; i < cold; ++i) {
    if (i > 0) session.reset_cache();
    const ColdRun run = cold_run(session, setup, truth, voxel_size, last);
    first_s.push_back(run.first_s);
    converged_s.push_back(run.converged_s);
    frames.push_back(run.frames);
    first_rmse.push_back(run.first_error.rmse);
    first_ssim.push_back(run.first_error.ssim);
  }
  std::vector<double> still_s, still_frames;
  for (int i = 0; i < cold; ++i) {
    const auto [seconds, n] = still_run(session, setup, last);
    still_s.push_back(seconds);
    still_frames.push_back(n);
  }
  // Warm: the cache filled and the back end converged (asynchronous back ends refine over
  // frames as their data arrives).
  row.settle_frames = session.settle(frame, outputs, RenderSession::kMaxSettleFrames, RenderSession::Settle::complete);
  std::vector<double> warm_s;
  FrameStats stats;
  for (int i = 0; i < warm; ++i) {
    stats = session.render(frame, last, outputs);
    warm_s.push_back(stats.seconds);
  }
  row.cold_median_s = median_of(first_s);
  row.cold_p95_s = p95_of(first_s);
  if (cold > 0) {
    row.converged_median_s = median_of(converged_s);
    row.converged_frames = int(std::lround(median_of(frames)));
    row.still_median_s = median_of(still_s);
    row.still_frames = int(std::lround(median_of(still_frames)));
    if (truth) row.first_rmse = median_of(first_rmse), row.first_ssim = median_of(first_ssim);
  }
  row.warm_median_s = median_of(warm_s);
  row.warm_p95_s = p95_of(warm_s);
  row.cold_runs = cold;
  row.warm_runs = warm;
  row.width = stats.width;
  row.height = stats.height;
  row.threads = stats.threads;
  const double t = warm > 0 ? row.warm_median_s : row.cold_median_s;
  row.rays_per_second_per_core = t > 0 ? double(stats.counters.rays) / t / std::max(1, stats.threads) : 0;
  row.samples = stats.counters.samples;
  row.bricks = stats.counters.bricks;
  row.bytes_read = stats.bytes_read;
  return row;
}

std::string safe_name(const std::string& s) {
  std::string out;
  for (char c : s) out += (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-') ? c : '_';
  return out;
}

void print_equal_error(const std::vector<EqualErrorRow>& rows) {
  for (const EqualErrorRow& e : rows) {
    const char* mark = e.bound == EqualErrorRow::Bound::at_most ? ">= " : e.bound == EqualErrorRow::Bound::at_least ? "<= " : "";
    std::cout << fmt::format("  {:<10} at {} (RMSE {:.4g}): {}{:.2f}x as fast as {}\n", e.backend,
                             e.against_quality.empty() ? e.against : e.against + " " + e.against_quality, e.rmse, mark,
                             e.speedup(), e.against);
  }
}

void run_bench(const BenchOptions& o) {
  if (!o.out.empty()) check_output_directory(o.out, "--out");
  Scene scene = load_scene(o.scene);
  if (!o.dataset.empty()) scene.dataset = o.dataset;
  if (!o.size.empty()) {
    const auto wh = parse_int_list(o.size, 2, "--size");
    if (wh[0] < 1 || wh[1] < 1 || wh[0] > kMaxImageSide || wh[1] > kMaxImageSide)
      throw Error(Errc::invalid_argument, fmt::format("image size must be in 1..{}", kMaxImageSide)).with_field("--size");
    scene.width = scene.camera.width = int(wh[0]);
    scene.height = scene.camera.height = int(wh[1]);
  }
  const int frame = parse_frames(o.frame, scene.frames(), "--frame").front();
  const Manifest dataset_manifest = read_manifest(scene.dataset);
  const DataKind kind = dataset_manifest.kind;
  const int supersample = o.reference_supersample;
  if (supersample < 1 || supersample % 2 == 0)
    throw Error(Errc::invalid_argument,
                fmt::format("{} must be odd and at least 1 (the middle sub-pixel's ray is the pixel's centre ray, which "
                            "gives the reference's depth and normals)", supersample))
        .with_field("--reference-supersample");
  if (int64_t(scene.width) * supersample > kMaxImageSide || int64_t(scene.height) * supersample > kMaxImageSide)
    throw Error(Errc::invalid_argument, fmt::format("{} times {}x{} exceeds {} pixels a side", supersample, scene.width,
                                                    scene.height, kMaxImageSide))
        .with_field("--reference-supersample");
  // --quality NAME=V1,V2,...: the values to sweep for back ends that have the parameter NAME.
  std::map<std::string, std::vector<double>> sweeps;
  for (const std::string& q : o.quality) {
    const size_t eq = q.find('=');
    if (eq == std::string::npos || eq == 0) throw Error(Errc::invalid_argument, fmt::format("'{}' is not NAME=V1,V2,...", q)).with_field("--quality");
    std::vector<double> values;
    for (const std::string& item : split_list(q.substr(eq + 1))) {
      double v = 0;
      const auto [end, ec] = std::from_chars(item.data(), item.data() + item.size(), v);
      if (item.empty() || ec != std::errc() || end != item.data() + item.size() || !std::isfinite(v))
        throw Error(Errc::invalid_argument, fmt::format("'{}' in '{}' is not a finite number", item, q)).with_field("--quality");
      values.push_back(v);
    }
    sweeps[q.substr(0, eq)] = values;
  }

  std::vector<std::string> names;
  if (o.backends == "all") {
    for (const BackendEntry& e : backends().entries())
      if (e.info.name != "reference" && e.info.accepts(kind, scene.mode)) names.push_back(e.info.name);
  } else {
    names = split_list(o.backends);
    for (const auto& n : names) backends().find(n);  // unknown names fail before any rendering
  }
  // A swept parameter that none of these back ends declares is a misspelling, not a no-op.
  for (const auto& [param, vals] : sweeps) {
    const bool declared = std::any_of(names.begin(), names.end(), [&](const std::string& n) {
      const std::vector<BackendParam>& params = backends().find(n).info.params;
      return std::any_of(params.begin(), params.end(), [&](const BackendParam& p) { return p.name == param; });
    });
    if (!declared)
      throw Error(Errc::invalid_argument, fmt::format("no back end benchmarked here has a parameter '{}' "
                                                      "(brickyard render --list-backends lists them)", param))
          .with_field("--quality");
  }

  // Peers are read before anything is rendered: a bad file fails at once.
  const std::vector<PeerResult> peers = o.peers.empty() ? std::vector<PeerResult>{} : read_peer_results(o.peers);
  for (const PeerResult& p : peers) {
    if (backends().contains(p.name))
      throw Error(Errc::format, fmt::format("peer '{}' has a back end's name", p.name)).with_file(o.peers).with_field("name");
    if (!fs::is_regular_file(p.image)) throw Error(Errc::io, "no such image (a peer's \"image\")").with_file(p.image);
  }
  {
    // The supersampled truth and its resolved copy, then each back end's frame beside the truth.
    const double pixels = double(scene.width) * double(scene.height);
    uint32_t state = 0;
    for (const std::string& n : names) state = std::max(state, pixel_state_bytes(n));
    check_frame_memory(fmt::format("bench at {}x{} pixels", scene.width, scene.height),
                       pixels * double(supersample) * double(supersample) + 2 * pixels, pixels * state,
                       double(scene.cache.l1_bytes),
                       "a smaller --size or --reference-supersample, or the scene's cache.l1, lowers it");
  }
  fs::create_directories(fs::path(o.out) / "images");
  FrameOutputs outputs;
  outputs.depth = true;
  outputs.normals = true;
  BenchReport report;
  report.title = fmt::format("{}: {} mode, {}x{}, frame {}, {}", fs::path(o.scene).filename().string(),
                             to_string(scene.mode), scene.width, scene.height, frame, scene.dataset);
  if (supersample > 1)
    report.title += fmt::format(", reference supersampled {0}x{0} (colour box-filtered, depth and normals at pixel "
                                "centres; its times and size are those of the {0}x larger frame)",
                                supersample);

  std::cout << fmt::format("bench {} ({}x{}, {} mode) -> {}\n", o.scene, scene.width, scene.height, to_string(scene.mode), o.out);
  // The truth: the reference renderer, once cold and once warm; supersampled (`supersample`
  // times the size, resolved down by resolve_supersampled), once warm.
  FrameBuffers truth;
  double voxel_size = 1;
  {
    RenderSession::Options ro;
    ro.backend = "reference";
    Scene fine = scene;
    fine.width = fine.camera.width = scene.width * supersample;
    fine.height = fine.camera.height = scene.height * supersample;
    RenderSession ref(fine, ro);
    voxel_size = ref.context().geometry().voxel_size;
    FrameBuffers fine_truth;
    // Supersampled, no cold frame: it would cost N^2 reference frames more, and its time is not compared.
    BenchRow row = measure(ref, frame, supersample > 1 ? 0 : 1, 1, outputs, fine_truth, nullptr, 1);
    truth = supersample > 1 ? resolve_supersampled(fine_truth, supersample) : std::move(fine_truth);
    if (supersample > 1) row.quality = fmt::format("supersample={}", supersample);
    row.backend = "reference";
    row.is_reference = true;
    row.error = compare_frames(truth, truth, voxel_size);
    row.image = "images/reference.png";
    write_png((fs::path(o.out) / row.image).string(), to_rgba8(truth.color));
    std::cout << fmt::format("  reference            {:>10} cold {:>10} warm\n", format_duration(row.cold_median_s),
                             format_duration(row.warm_median_s));
    report.rows.push_back(row);
  }
  for (const std::string& name : names) {
    const BackendInfo& info = backends().find(name).info;
    if (!info.accepts(kind, scene.mode)) {
      std::cout << fmt::format("  {} does not render {} mode on {} datasets: skipped\n", name, to_string(scene.mode),
                               to_string(kind));
      continue;
    }
    // A back end that reads only the grid's octree volume needs one; with every back end
    // benchmarked, a store without it skips that one and says how to include it.
    const bool octree_only = info.records == std::vector<RecordKind>{RecordKind::octree_page};
    if (octree_only && !dataset_manifest.octree && o.backends == "all") {
      std::cout << fmt::format("  {} reads the octree volume, which {} has none of: skipped (brickyard build-octree {})\n",
                               name, scene.dataset, scene.dataset);
      continue;
    }
    std::vector<double> values = info.quality_sweep;
    std::string knob = info.quality_param;
    for (const auto& [param, vals] : sweeps)
      if (std::any_of(info.params.begin(), info.params.end(), [&](const BackendParam& p) { return p.name == param; })) {
        knob = param;
        values = vals;
      }
    if (knob.empty()) values = {0};
    for (double v : values) {
      RenderSession::Options so;
      so.backend = name;
      if (!knob.empty()) so.params[knob] = v;
      RenderSession session(scene, so);
      FrameBuffers fb;
      BenchRow row = measure(session, frame, o.cold, o.warm, outputs, fb, &truth, voxel_size);
      row.backend = name;
      row.quality = knob.empty() ? "" : fmt::format("{}={:g}", knob, v);
      row.quality_value = v;
      row.error = compare_frames(fb, truth, voxel_size);
      row.image = fmt::format("images/{}-{}.png", safe_name(name), safe_name(row.quality));
      write_png((fs::path(o.out) / row.image).string(), to_rgba8(fb.color));
      const bool cold = row.cold_runs > 0;
      std::cout << fmt::format("  {:<10} {:<10} {:>10} first (RMSE {:.3g}) {:>10} converged ({} frames) {:>10} still ({} "
                               "frames) {:>10} warm  RMSE {:.4g}  SSIM {:.4f}  {} rays/s/core\n",
                               name, row.quality, cold ? format_duration(row.cold_median_s) : "-", row.first_rmse,
                               cold ? format_duration(row.converged_median_s) : "-", row.converged_frames,
                               cold ? format_duration(row.still_median_s) : "-", row.still_frames,
                               format_duration(row.warm_median_s), row.error.rmse, row.error.ssim,
                               format_count(row.rays_per_second_per_core));
      report.rows.push_back(row);
    }
  }
  for (const PeerResult& p : peers) {
    BenchRow row = peer_row(p, truth, voxel_size);
    row.image = fmt::format("images/peer-{}-{}.png", safe_name(p.name), safe_name(p.quality));
    fs::copy_file(p.image, fs::path(o.out) / row.image, fs::copy_options::overwrite_existing);
    std::cout << fmt::format("  {:<10} {:<10} {:>10} first {:>10} steady  RMSE {:.4g}  SSIM {:.4f}  (peer)\n", p.name,
                             p.quality, format_duration(row.cold_median_s), format_duration(row.warm_median_s),
                             row.error.rmse, row.error.ssim);
    report.rows.push_back(std::move(row));
  }
  BenchReportPaths paths;
  try {
    paths = write_bench_report(o.out, report);
  } catch (const Error& e) {
    if (e.code() != Errc::unsupported) throw;
    // The data is written; only a chart is missing (no gnuplot): say so, keep the exit code.
    std::cerr << "brickyard: warning: " << e.what() << "\n";
    paths.markdown = (fs::path(o.out) / "bench.md").string();
    paths.csv = (fs::path(o.out) / "bench.csv").string();
    paths.equal_error_csv = (fs::path(o.out) / "equal-error.csv").string();
  }
  for (const BenchTime which : {BenchTime::warm, BenchTime::converged}) {
    const std::vector<EqualErrorRow> equal_error = equal_error_rows(report.rows, which);
    if (!equal_error.empty())
      std::cout << (which == BenchTime::warm ? "at equal error, steady frames:\n"
                                             : "at equal error, from empty caches to the converged image:\n");
    print_equal_error(equal_error);
  }
  std::cout << fmt::format("report: {}\n  table {}\n", paths.markdown, paths.csv);
  if (!paths.equal_error_csv.empty()) std::cout << fmt::format("  equal error {}\n", paths.equal_error_csv);
  if (!paths.error_plot.empty()) std::cout << fmt::format("  chart {}\n", paths.error_plot);
  if (!paths.contact_sheet.empty()) std::cout << fmt::format("  images {}\n", paths.contact_sheet);
}

}  // namespace

void add_render_commands(CLI::App& app, int& exit_status) {
  {
    auto o = std::make_shared<RenderOptions>();
    CLI::App* cmd = app.add_subcommand("render", "Render a scene (JSON) with its back end, or the one --backend names");
    cmd->add_option("SCENE", o->scene, "Scene file (see scenes/example.json)");
    cmd->add_option("-o,--out", o->out, "Colour PNG (camera paths: NAME_0000.png, ...)");
    cmd->add_option("--depth", o->depth, "Depth PNG (near bright, far dark, misses black)");
    cmd->add_option("--normals", o->normals, "Normal PNG ((n + 1) / 2 as RGB)");
    cmd->add_option("--stats", o->stats, "Frame statistics and cache statistics as JSON");
    cmd->add_option("--frames", o->frames, "Frames of a camera path: all, or a list of N and A-B such as 0,90,10-20 (default 0)");
    cmd->add_option("--backend", o->backend, "Back end to use instead of the scene's");
    cmd->add_option("--dataset", o->dataset, "Store to render instead of the scene's dataset");
    cmd->add_option("--set", o->sets, "Back-end parameter NAME=VALUE (repeatable); time_step=K as --time-step");
    cmd->add_option("--time-step", o->time_step,
                    "The dataset's time step to render instead of the scene's time_step or time_series (0-based)");
    cmd->add_option("--error-maps", o->error_maps, "Also render the reference; print the error and write heat maps into this directory");
    cmd->add_flag("--list-backends", o->list, "List the back ends, their modes and parameters");
    cmd->add_flag("--settle", o->settle, "Camera paths: let asynchronous back ends converge on every frame (a still camera always does)");
    cmd->add_flag("--allow-damaged", o->allow_damaged,
                  "Exit 0 when records of the store cannot be read (they are drawn from a coarser level or left empty, "
                  "and listed; without it the exit status is 3)");
    cmd->callback([o, &exit_status] { exit_status = run_render(*o); });
  }
  {
    auto o = std::make_shared<BenchOptions>();
    CLI::App* cmd = app.add_subcommand("bench", "Error against run time: every back end at a sweep of its quality knob, against the reference");
    cmd->add_option("SCENE", o->scene, "Scene file")->required();
    cmd->add_option("--backends", o->backends, "all, or a comma-separated list of back ends");
    cmd->add_option("--quality", o->quality, "NAME=V1,V2,... values of a back-end parameter to sweep (default: each back end's own sweep)");
    cmd->add_option("--warm", o->warm, "Warm-cache frames to time (median, p95)")->check(CLI::Range(1, 1000));
    cmd->add_option("--cold", o->cold, "Cold-cache frames to time (each on a new, empty cache)")->check(CLI::Range(0, 1000));
    cmd->add_option("--frame", o->frame, "Frame of the scene's camera path to render (default 0)");
    cmd->add_option("--size", o->size, "Image size W,H instead of the scene's");
    cmd->add_option("--dataset", o->dataset, "Store to render instead of the scene's dataset");
    cmd->add_option("--reference-supersample", o->reference_supersample,
                    "Render the reference at N times the width and height (N odd, at most 16384 pixels a side) and "
                    "box-filter it down: error against each pixel's mean over its area rather than its centre ray, the "
                    "truth for back ends that filter");
    cmd->add_option("--peers", o->peers,
                    "Other programs' results on the same view (peers.json, written by bench/peers/dvr.sh): their images' "
                    "error against the reference, their times, in the same report");
    cmd->add_option("--out", o->out, "Report directory (bench.md, bench.csv, equal-error.csv, error-vs-time.png, contact-sheet.png, images/)");
    cmd->callback([o] { naming_options({{"backend", "--backends"}}, [&] { run_bench(*o); }); });
  }
}

int report_unreadable(const std::vector<std::string>& errors, bool allow_damaged) {
  if (errors.empty()) return 0;
  constexpr size_t kShown = 8;
  std::string list;
  for (size_t i = 0; i < std::min(errors.size(), kShown); ++i) list += fmt::format("\n  {}", errors[i]);
  if (errors.size() > kShown) list += fmt::format("\n  and {} more", errors.size() - kShown);
  std::cerr << fmt::format("brickyard: {}: {} record{} of the store could not be read; renderers draw such records from "
                           "a coarser level where one can be read, else leave them empty:{}\n",
                           allow_damaged ? "warning" : "error", errors.size(), errors.size() == 1 ? "" : "s", list);
  if (allow_damaged) return 0;
  std::cerr << fmt::format("brickyard: exit status {} (damaged store); --allow-damaged accepts the image; `brickyard verify "
                           "STORE` lists every damaged record\n",
                           kExitDamaged);
  return kExitDamaged;
}

}  // namespace brickyard::cli
