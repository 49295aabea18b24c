// A scene's camera path flown by one back end, frame by frame, as a user would see it: frame
// times (median, p95), the back end's own figures per frame (pool occupancy, subdivisions,
// uploads, ...), frames to converge after a camera jump, the converged frame time, and the
// error of converged frames against the reference renderer (or, for data only the back end can
// produce, against its own exact mode). Figures are reported, never asserted.
//
//   build/bench/bench_flight SCENE [--dataset STORE] [--backend NAME] [--set NAME=VALUE ...]
//       [--size 512] [--frames N] [--jump A,B] [--error-frames F,...] [--truth reference|exact]
//       [--csv FILE]
//
// The CSV has one row per flown frame: frame, ms, converged, then every figure the back end
// reports, by name (plot it with gnuplot).

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "apps/parse.h"
#include "core/error.h"
#include "renderers/common/metrics.h"
#include "session/render_session.h"
#include "renderers/common/scene.h"

namespace {

using namespace brickyard;

/// Nearest-rank percentile (metrics.h) of a copy, p in [0, 100].
double pct(std::vector<double> v, double p) { return percentile(v, p); }

double mean(const std::vector<double>& v) {
  double sum = 0;
  for (double x : v) sum += x;
  return v.empty() ? 0 : sum / double(v.size());
}

std::vector<int> frame_list(const std::string& text, std::string_view option) {
  std::vector<int> out;
  for (const std::string& item : cli::split_list(text)) out.push_back(int(cli::parse_int_list(item, 1, option)[0]));
  return out;
}

struct Options {
  std::string scene, dataset, backend, jump, error_frames, truth = "reference", csv;
  std::vector<std::string> sets;
  int size = 512, frames = 0;
};

int run(const Options& o) {
  Scene scene = load_scene(o.scene);
  if (!o.dataset.empty()) scene.dataset = o.dataset;
  if (!o.backend.empty()) scene.backend = o.backend;
  scene.width = scene.height = o.size;
  scene.camera.width = scene.camera.height = o.size;
  RenderSession::Options so;
  so.backend = scene.backend;
  so.params = scene.backend_params;
  for (const std::string& s : o.sets) so.params.insert_or_assign(cli::parse_assignment(s, "--set").first, cli::parse_assignment(s, "--set").second);
  RenderSession session(scene, so);
  const int frames = o.frames > 0 ? std::min(o.frames, scene.frames()) : scene.frames();
  fmt::print("{} over {} with {}, {}x{}, {} frames\n", o.scene, scene.dataset, so.backend, o.size, o.size, frames);

  // The flight.
  std::vector<std::string> names;
  std::vector<std::vector<double>> rows;
  std::vector<double> ms;
  FrameBuffers fb;
  for (int f = 0; f < frames; ++f) {
    const FrameStats st = session.render(f, fb, {});
    if (names.empty())
      for (const auto& [name, value] : st.backend) names.push_back(name);
    std::vector<double> row{double(f), st.seconds * 1e3, session.converged() ? 1.0 : 0.0};
    for (const std::string& n : names) row.push_back(st.backend_value(n));
    rows.push_back(row);
    ms.push_back(st.seconds * 1e3);
  }
  int converged = 0;
  for (const auto& r : rows) converged += r[2] != 0;
  fmt::print("flight: frame time median {:.1f} ms, p95 {:.1f} ms, mean {:.1f} ms; converged frames {}/{}\n", pct(ms, 50), pct(ms, 95),
             mean(ms), converged, frames);
  for (size_t i = 0; i < names.size(); ++i) {
    std::vector<double> v;
    for (const auto& r : rows) v.push_back(r[3 + i]);
    fmt::print("  {:<32} mean {:>12.1f}  median {:>12.1f}  p95 {:>12.1f}  max {:>12.1f}\n", names[i], mean(v), pct(v, 50), pct(v, 95),
               pct(v, 100));
  }
  if (!o.csv.empty()) {
    std::ofstream csv(o.csv);
    csv << "frame,ms,converged";
    for (const std::string& n : names) csv << ',' << n;
    csv << '\n';
    for (const auto& r : rows) {
      for (size_t i = 0; i < r.size(); ++i) csv << (i ? "," : "") << fmt::format("{}", r[i]);
      csv << '\n';
    }
    fmt::print("per-frame figures: {}\n", o.csv);
  }

  // A camera jump, in a new session (pools hold frame A's working set only): settled on A, how
  // many frames until B is complete.
  if (!o.jump.empty()) {
    const std::vector<int64_t> ab = cli::parse_int_list(o.jump, 2, "--jump");
    RenderSession fresh(scene, so);
    fresh.settle(int(ab[0]), {});
    std::vector<double> jump_ms;
    int n = 0;
    do {
      jump_ms.push_back(fresh.render(int(ab[1]), fb, {}).seconds * 1e3);
      fresh.pages().wait_idle();
    } while (!fresh.converged() && ++n < 200);
    fmt::print("jump {} -> {}: {} frames to converge ({}), first {:.1f} ms, max {:.1f} ms\n", ab[0], ab[1], jump_ms.size(),
               fresh.converged() ? "converged" : "NOT converged", jump_ms.front(), pct(jump_ms, 100));
  }

  // Converged frames: their time and their error.
  std::vector<int> error_frames = o.error_frames.empty() ? std::vector<int>{frames - 1} : frame_list(o.error_frames, "--error-frames");
  for (int f : error_frames) {
    const int settle_frames = session.settle(f, {});
    std::vector<double> t;
    for (int i = 0; i < 5; ++i) t.push_back(session.render(f, fb, {}).seconds * 1e3);
    FrameBuffers truth;
    std::string against;
    if (o.truth == "exact") {
      RenderSession::Options eo = so;
      eo.params["exact"] = 1;
      RenderSession exact(scene, eo);
      exact.render(f, truth, {});
      against = "its exact mode";
    } else {
      RenderSession::Options ro;
      ro.backend = "reference";
      RenderSession ref(scene, ro);
      ref.render(f, truth, {});
      against = "the reference";
    }
    const ImageError e = compare_frames(fb, truth, session.context().geometry().voxel_size);
    fmt::print("frame {}: converged after {} frames; converged frame time median {:.1f} ms ({:.1f} fps); RMSE {:.5f} against {}, "
               "coverage mismatch {:.4f}\n",
               f, settle_frames, pct(t, 50), 1e3 / pct(t, 50), e.rmse, against, e.coverage_mismatch_fraction);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Fly a scene's camera path with one back end and report per-frame figures"};
  app.add_option("scene", o.scene, "Scene file with a camera path")->required();
  app.add_option("--dataset", o.dataset, "Store instead of the scene's dataset");
  app.add_option("--backend", o.backend, "Back end instead of the scene's");
  app.add_option("--set", o.sets, "Back-end parameter NAME=VALUE (repeatable)");
  app.add_option("--size", o.size, "Image width and height")->check(CLI::Range(1, 16384));
  app.add_option("--frames", o.frames, "Fly only the first N frames (default: the whole path)");
  app.add_option("--jump", o.jump, "A,B: settle on frame A, then count frames until frame B converges");
  app.add_option("--error-frames", o.error_frames, "Frames to settle, time and compare (default: the last)");
  app.add_option("--truth", o.truth, "Compare against the reference renderer or the back end's exact mode")
      ->check(CLI::IsMember({"reference", "exact"}));
  app.add_option("--csv", o.csv, "Per-frame figures");
  CLI11_PARSE(app, argc, argv);
  try {
    return run(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_flight: %s\n", e.what());
    return 1;
  }
}
