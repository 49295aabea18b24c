// The `gigavoxels` back end rendering: exact mode against the reference, approximate mode
// converging to exact mode after a camera jump, adaptive steps and leaps, quadrilinear
// filtering against nearest-level sampling, and N = 3 on the instanced Menger sponge. Its parts
// one at a time (node tree, preintegration, lighting, bounds) are in test_gigavoxels_parts.cpp.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <tbb/global_control.h>

#include "core/error.h"
#include "core/units.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/metrics.h"
#include "renderers/common/pixel.h"
#include "session/render_session.h"
#include "renderers/common/scene.h"
#include "renderers/common/shading.h"
#include "renderers/gigavoxels/field_bounds.h"
#include "renderers/gigavoxels/renderer.h"
#include "renderers/render_test_util.h"
#include "test_util.h"

namespace brickyard {
namespace {

using testing::all_finite;
using testing::backend_options;
using testing::dvr_scene;
using testing::expect_as_good_as_raymarch;
using testing::hit_pixels;
using testing::iso_scene;
using testing::reference_frame;

/// Marschner-Lobb and a sphere's distance, 64^3 f32 in 8^3 bricks (4 levels).
class GigaVoxels : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    field_store("marschner-lobb", 64, "ml.store");
    field_store("sphere", 64, "sphere.store");
  }
  static void TearDownTestSuite() { delete dir_; }
  /// A procedural field sampled on n^3 as f32 in brick_size^3 bricks, as dir_'s store `name`; its path.
  static std::string field_store(const std::string& field, int64_t n, const std::string& name, const FieldParamValues& params = {},
                                 int brick_size = 8) {
    BuildOptions o;
    o.brick_size = brick_size;
    build_store(*make_field_source(make_field(field, params), {n, n, n}, ValueType::f32), dir_->file(name), o);
    return dir_->file(name);
  }

  static Scene scene(const std::string& extra, int size = 64, const std::string& camera = kCamera) {
    const std::string text = R"({"dataset": "ml.store", "image": {"width": )" + std::to_string(size) + R"(, "height": )" +
                             std::to_string(size) + R"(}, "cache": {"l1": "64MiB", "l2": "64MiB"}, )" + camera + ", " + extra + "}";
    return parse_scene(text, dir_->file("scene.json"));
  }
  static constexpr const char* kCamera = R"("camera": {"eye": [1.8, -1.2, 1.5], "target": [0.5, 0.5, 0.45], "fov_degrees": 35})";
  /// Iso at 64x64 on a 2-frame path: kCamera's view, then a jump to the other side.
  static Scene camera_jump_scene() {
    const std::string path = R"("camera_path": {"frames": 2, "fov_degrees": 35, "keyframes": [
      {"eye": [1.8, -1.2, 1.5], "target": [0.5, 0.5, 0.45]}, {"eye": [-0.9, 1.9, -0.4], "target": [0.5, 0.5, 0.5]}]})";
    return scene(iso_scene() + R"(, "quality": {"lod_ratio": 0.5})", 64, path);
  }
  static testing::TempDir* dir_;
};
testing::TempDir* GigaVoxels::dir_ = nullptr;

const FrameOutputs kAll{.depth = true, .normals = true};

TEST_F(GigaVoxels, ExactModeMatchesTheReferenceInOneFrame) {
  // lod_ratio 0.25: every ray reaches the finest level, so what remains is the sampling error.
  for (const std::string& mode : {iso_scene(), dvr_scene()}) {
    const Scene sc = scene(mode + R"(, "quality": {"lod_ratio": 0.25})", 96);
    FrameBuffers fb;
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.0625}, {"refine", 20}}));
    const FrameStats st = g.render(0, fb, kAll);
    EXPECT_TRUE(g.converged());
    ASSERT_TRUE(all_finite(fb));
    EXPECT_GT(st.backend_value("passes"), 1);  // the first pass found nothing loaded
    expect_as_good_as_raymarch(sc, fb, 0.0625, 0.02);
  }
}

TEST_F(GigaVoxels, LitDvrMatchesTheReferenceUnderEveryKindOfLight) {
  // Under a headlight or a directional light a ray's light direction and half vector are the
  // same at every sample, and computed once per ray; a point light's change along it. A fixed
  // step, to compare with raymarch's at the same step.
  for (const char* light : {R"({"light": "headlight"})", R"({"light": "directional", "light_direction": [1, 0.3, -0.5]})",
                                   R"({"light": "point", "light_position": [1.4, 0.5, 0.2]})"}) {
    SCOPED_TRACE(light);
    const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25}, "shading": )" + std::string(light), 64);
    FrameBuffers fb;
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.25}, {"adaptive_step", 1}}));
    g.render(0, fb, kAll);
    ASSERT_TRUE(all_finite(fb));
    expect_as_good_as_raymarch(sc, fb, 0.25, 0.02);
  }
}

TEST_F(GigaVoxels, AdaptiveStepSpendsSamplesWhereTheyCount) {
  // A step growing as T^-1/2 with the light left to the ray spends fewer samples where they
  // count less. Against fixed steps at the same error (log-log between the two fixed steps
  // around it), it takes about 0.84x their samples here, at a coarse and a fine step (0.86 and
  // 0.84 with face_lighting, 0.78 before it, when lit DVR converged to first order).
  const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25, "termination_opacity": 0.999}, "shading": {"light": "headlight"})", 64);
  const FrameBuffers truth = reference_frame(sc);
  struct Run {
    double rmse;
    double samples;
  };
  const auto run = [&](double step, double adaptive) {
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", step}, {"adaptive_step", adaptive}}));
    FrameBuffers fb;
    const uint64_t samples = g.render(0, fb, kAll).counters.samples;
    EXPECT_TRUE(g.converged());
    EXPECT_TRUE(all_finite(fb));
    return Run{compare_frames(fb, truth, 1.0).rmse, double(samples)};
  };
  const std::vector<Run> fixed = {run(0.5, 1), run(0.35, 1), run(0.25, 1)};
  for (size_t i = 0; i + 1 < fixed.size(); ++i) ASSERT_LT(fixed[i + 1].rmse, 0.95 * fixed[i].rmse) << "fixed step " << i;
  for (const double adaptive_step : {0.35, 0.2}) {
    const Run adaptive = run(adaptive_step, 8);
    // The two fixed steps around its error, or the nearest two (extrapolated) outside them.
    size_t i = 0;
    while (i + 2 < fixed.size() && adaptive.rmse < fixed[i + 1].rmse) ++i;
    const Run &a = fixed[i], &b = fixed[i + 1];
    ASSERT_LE(adaptive.rmse, a.rmse) << "adaptive at " << adaptive_step << " is less accurate than the coarsest fixed step";
    const double f = std::log(a.rmse / adaptive.rmse) / std::log(a.rmse / b.rmse);
    const double fixed_samples = a.samples * std::pow(b.samples / a.samples, f);
    EXPECT_LT(adaptive.samples, 0.92 * fixed_samples) << "adaptive at " << adaptive_step << ": RMSE " << adaptive.rmse << ", "
                                                      << adaptive.samples << " samples; fixed steps at that RMSE: "
                                                      << fixed_samples << " samples";
  }
  // The cap bounds the growth: capped at 2, the same base step takes more samples.
  EXPECT_GT(run(0.2, 2).samples, run(0.2, 8).samples);
}

TEST_F(GigaVoxels, FaceLightingLowersLitDvrErrorWhereSegmentsCrossCellFaces) {
  // Lighting a segment with the mean of its ends' errs by the share of it on the wrong side of
  // a cell face, first order in the step (0.0076, 0.0039, 0.0024 at steps 0.5, 0.25, 0.125
  // here). Weighted by the faces it crosses (face_lighting.h): 0.0064, 0.0024, 0.0015. At step
  // 1 most segments cross several faces and the cells between are not sampled, so it gains
  // little there.
  const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25, "termination_opacity": 0.999}, "shading": {"light": "headlight"})", 64);
  const FrameBuffers truth = reference_frame(sc);
  const auto rmse = [&](const Scene& s, const FrameBuffers& t, double step, bool face_lighting) {
    RenderSession g(s, backend_options("gigavoxels", {{"exact", 1}, {"step", step}, {"adaptive_step", 1}, {"face_lighting", face_lighting ? 1.0 : 0.0}}));
    FrameBuffers fb;
    g.render(0, fb, kAll);
    EXPECT_TRUE(g.converged());
    EXPECT_TRUE(all_finite(fb));
    return compare_frames(fb, t, 1.0).rmse;
  };
  for (const auto& [step, most] : {std::pair{0.5, 0.9}, std::pair{0.25, 0.75}, std::pair{0.125, 0.75}}) {
    const double mean = rmse(sc, truth, step, false), weighted = rmse(sc, truth, step, true);
    EXPECT_LT(weighted, most * mean) << "step " << step << ": face-weighted " << weighted << ", mean of the ends " << mean;
  }
  // Where levels blend (lod_ratio 2 at 48x48: most samples blend two levels), a segment is
  // weighted only within one level's cells, and takes the mean elsewhere: never worse.
  const Scene blended = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 2, "termination_opacity": 0.999}, "shading": {"light": "headlight"})", 48);
  const FrameBuffers blended_truth = reference_frame(blended);
  const double mean = rmse(blended, blended_truth, 0.25, false), weighted = rmse(blended, blended_truth, 0.25, true);
  EXPECT_LE(weighted, mean * 1.001) << "blended levels: face-weighted " << weighted << ", mean of the ends " << mean;
}

TEST_F(GigaVoxels, TerminationFillGivesTheLightLeftTheMediumsColour) {
  // Early termination at 0.9 leaves up to a tenth of a ray's light to what lies behind. The
  // reference integrates it; the background stands in for it unless termination_fill gives it
  // the last segment's colour, the medium's behind. Rays that are not stopped are unchanged.
  const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25, "termination_opacity": 0.9}, "shading": {"light": "headlight"})", 64);
  const FrameBuffers truth = reference_frame(sc);
  FrameBuffers fb[2];
  double rmse[2];
  for (int fill = 0; fill < 2; ++fill) {
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.5}, {"termination_fill", double(fill)}}));
    g.render(0, fb[fill], kAll);
    EXPECT_TRUE(g.converged());
    EXPECT_TRUE(all_finite(fb[fill]));
    rmse[fill] = compare_frames(fb[fill], truth, 1.0).rmse;
  }
  // Against the error of the same step with no termination at all: the fill takes back most of
  // what stopping cost (here 0.0191 and 0.0102 against 0.0075).
  Scene whole = sc;
  whole.quality.termination_opacity = 1;
  RenderSession g(whole, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.5}}));
  FrameBuffers unstopped;
  g.render(0, unstopped, kAll);
  const double floor = compare_frames(unstopped, truth, 1.0).rmse;
  std::cout << "[ measured ] termination at 0.9: RMSE " << rmse[0] << " with the background behind, " << rmse[1]
            << " with the last segment's colour; " << floor << " with no termination\n";
  EXPECT_LT(rmse[1] - floor, 0.3 * (rmse[0] - floor));
  int stopped = 0, passed = 0;
  for (int y = 0; y < fb[0].height(); ++y)
    for (int x = 0; x < fb[0].width(); ++x) {
      const Rgbaf background_behind = fb[0].color(x, y), filled = fb[1].color(x, y);
      if (std::abs(background_behind.a - 0.9f) < 1e-5f) continue;  // stopped or not, as the double rounded
      if (background_behind.a >= 0.9f) {  // stopped: opaque now, its colour moved off the background's way
        ++stopped;
        EXPECT_EQ(filled.a, 1.0f);
      } else {
        ++passed;
        EXPECT_EQ(filled.r, background_behind.r);
        EXPECT_EQ(filled.g, background_behind.g);
        EXPECT_EQ(filled.b, background_behind.b);
        EXPECT_EQ(filled.a, background_behind.a);
      }
    }
  EXPECT_GT(stopped, 100);
  EXPECT_GT(passed, 100);
}

TEST_F(GigaVoxels, MiddleLightingLowersLitDvrErrorWhereSegmentsCrossSeveralCells) {
  // A segment that crosses two cell faces or more passes cells where the ray takes no sample;
  // face_lighting alone lights them with its ends' mean. middle_lighting takes one more
  // gradient, in their middle, and lights them with it: the error falls most where segments
  // are longest (here 0.0134 -> 0.0114 at step 1, 0.0054 -> 0.0047 at step 0.5 under a
  // headlight; the ends' mean was 0.0150 and 0.0064 before samples were clamped to the
  // volume's voxels and flat ones lit as facing the ray). One at a time and in sample runs alike.
  const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25, "termination_opacity": 0.999}, "shading": {"light": "headlight"})", 64);
  const FrameBuffers truth = reference_frame(sc);
  const auto render = [&](double step, bool middle, bool runs) {
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", step}, {"adaptive_step", 1},
                                                       {"middle_lighting", middle ? 1.0 : 0.0}, {"sample_runs", runs ? 1.0 : 0.0}}));
    FrameBuffers fb;
    const FrameStats st = g.render(0, fb, kAll);
    EXPECT_TRUE(g.converged());
    EXPECT_TRUE(all_finite(fb));
    return std::pair{compare_frames(fb, truth, 1.0).rmse, st.counters};
  };
  for (const auto& [step, most] : {std::pair{1.0, 0.88}, std::pair{0.5, 0.92}})
    for (const bool runs : {false, true}) {
      const auto [ends, ends_counters] = render(step, false, runs);
      const auto [middle, middle_counters] = render(step, true, runs);
      EXPECT_LT(middle, most * ends) << "step " << step << (runs ? " in runs" : "") << ": lit in the middle " << middle
                                     << ", by the ends' mean " << ends;
      // The same samples, and a gradient more for some segments: at most one more per sample.
      EXPECT_EQ(middle_counters.samples, ends_counters.samples);
      EXPECT_GT(middle_counters.gradients, ends_counters.gradients);
      EXPECT_LE(middle_counters.gradients, ends_counters.gradients + ends_counters.samples);
      std::cout << "[ measured ] step " << step << (runs ? " in runs" : "") << ": RMSE " << ends << " by the ends' mean, "
                << middle << " lit in the middle\n";
    }
}

TEST_F(GigaVoxels, AdaptiveStepStillSeesAThinSheetPastEmptySpace) {
  // The step grows with the opacity gathered, never over a stretch of nothing visible (which
  // says nothing about what lies past it): a shell about 1.5 voxels thick around a sphere,
  // behind empty space (leapt, or marched with skip_cells=0), at a base step of one voxel, is
  // seen as well by the adaptive step as by a fixed one. A step that also grew where the
  // extinction met was low, (T tau)^-1/2, reached the cap (8 voxels) there and missed most of
  // the shell: RMSE 0.021 against 0.0025.
  const std::string store = field_store("sphere", 64, "sphere64.store");
  Scene sc = scene(R"("mode": "dvr", "values": "stored", "quality": {"lod_ratio": 0.25}, "shading": {"light": "headlight"},
      "transfer_function": {"points": [{"value": -0.012, "color": [0.2, 0.4, 0.9], "opacity": 0},
      {"value": 0, "color": [1, 0.4, 0.2], "opacity": 0.8}, {"value": 0.012, "color": [0.2, 0.4, 0.9], "opacity": 0}]})", 64);
  sc.dataset = store;
  const FrameBuffers truth = reference_frame(sc);
  for (int skip = 0; skip < 2; ++skip) {
    double rmse[2];
    for (int adaptive = 0; adaptive < 2; ++adaptive) {
      RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", 1}, {"skip_cells", double(skip)}, {"adaptive_step", adaptive ? 8.0 : 1.0}}));
      FrameBuffers fb;
      g.render(0, fb, kAll);
      EXPECT_TRUE(g.converged());
      ASSERT_TRUE(all_finite(fb));
      rmse[adaptive] = compare_frames(fb, truth, 1.0).rmse;
    }
    EXPECT_LE(rmse[1], 1.25 * rmse[0] + 1e-3) << "skip_cells " << skip << ": adaptive " << rmse[1] << ", fixed " << rmse[0];
  }
}

TEST_F(GigaVoxels, LeapChainsLeaveOutOnlySamplesThatShowNothing) {
  // A leap that ends in clear groups again leaps on with no sample there (chain_leaps) when the
  // values at both ends lie in one interval the transfer function hides; each such leap leaves
  // out two samples (the one where it ends and the value where the next begins), and the image
  // and every other sample stay as they were, under a fixed step and the adaptive one (whose
  // step the chain takes as the sample before it left it). A shell around a sphere, visible only
  // between two hidden intervals (inside and outside), in 8^3 and 32^3 bricks, at steps up to 9
  // voxels; then the sphere at the test's transfer function, one hidden interval. A chain must
  // also stop where a leap from outside lands in clear groups inside, past the shell, where
  // pre-integration sees the shell between the two values: no case here reaches that guard (a
  // clear group past the shell lies too near it for its own leap to reach 2 steps), and it stays.
  struct Case {
    const char* what;
    std::string scene_text, store;
    double step, adaptive_step, runs;
  };
  const std::string shell = R"("mode": "dvr", "values": "stored", "quality": {"lod_ratio": 0.25}, "shading": {"light": "headlight"},
      "transfer_function": {"points": [{"value": -0.02, "color": [0.2, 0.4, 0.9], "opacity": 0},
      {"value": 0, "color": [1, 0.4, 0.2], "opacity": 0.8}, {"value": 0.02, "color": [0.2, 0.4, 0.9], "opacity": 0}]})";
  const std::string sphere_store = dir_->file("sphere.store");
  const std::string large_bricks = field_store("sphere", 96, "sphere-32.store", {{"radius", 0.4}}, 32);
  const std::string sphere = dvr_scene() + R"(, "values": "normalized", "quality": {"lod_ratio": 0.25})";
  for (const Case& c : {Case{"shell, fixed step 3, one at a time", shell, sphere_store, 3, 1, 0},
                        Case{"shell, fixed step 3, in runs", shell, sphere_store, 3, 1, 1},
                        Case{"shell in 32^3 bricks, fixed step 6", shell, large_bricks, 6, 1, 1},
                        Case{"shell in 32^3 bricks, fixed step 9", shell, large_bricks, 9, 1, 0},
                        Case{"shell, adaptive step 2", shell, sphere_store, 2, 8, 1},
                        Case{"sphere, step 1, one at a time", sphere, sphere_store, 1, 8, 0},
                        Case{"sphere, step 1, in runs", sphere, sphere_store, 1, 8, 1}}) {
    SCOPED_TRACE(c.what);
    Scene sc = scene(c.scene_text, 96);
    sc.dataset = c.store;
    FrameBuffers fb[2];
    FrameStats stats[2];
    for (int chains = 0; chains < 2; ++chains) {
      RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", c.step}, {"adaptive_step", c.adaptive_step},
                                                         {"sample_runs", c.runs}, {"leap_chains", double(chains)}}));
      stats[chains] = g.render(0, fb[chains], kAll);
      EXPECT_TRUE(g.converged());
      ASSERT_TRUE(all_finite(fb[chains]));
    }
    const double chained = stats[1].backend_value("leaps_chained");
    EXPECT_EQ(stats[0].backend_value("leaps_chained"), 0);
    EXPECT_GT(chained, 0);
    // Exactly two samples fewer a chained leap: the positions after a chain are those of leaping
    // one leap at a time, under the adaptive step too (the chain steps by the step the sample
    // before it left).
    EXPECT_EQ(double(stats[1].counters.samples), double(stats[0].counters.samples) - 2 * chained);
    const ImageError e = compare_frames(fb[1], fb[0], 1.0);
    EXPECT_LT(e.rmse, 1e-6) << e.to_json();
    EXPECT_EQ(e.coverage_mismatch, 0u) << e.to_json();
    EXPECT_LT(e.depth_max, 1e-6) << e.to_json();
    size_t shown = 0;
    for (size_t i = 0; i < fb[1].color.size(); ++i) shown += fb[1].color.data()[i].a > 0.1f;
    EXPECT_GT(shown, fb[1].color.size() / 10);  // the shell or the sphere is seen
    std::cout << "[ measured ] " << c.what << ": " << chained << " leaps chained, samples " << stats[0].counters.samples << " -> "
              << stats[1].counters.samples << "\n";
  }
}

TEST_F(GigaVoxels, LeapingClearCellGroupsKeepsTheImageAndSavesSamples) {
  // A 4^3-cell group whose voxels cannot show anything, with the clear groups around it, is
  // leapt to the first sample position past them, so the samples that remain are the ones marching every step takes: the same image
  // (iso: bit for bit here; DVR: up to the pre-integration table's slight opacity next to a
  // zero-opacity range, which the leap does not add), with fewer samples. Marschner-Lobb at
  // 64^3 has ripples in nearly every group; a sphere's distance leaves most groups clear. The
  // adaptive step grows with the opacity gathered, which a clear group does not change. At
  // lod_ratio 0.25 the footprint stays finer than the finest level, so DVR takes march_dvr's
  // one-level path, which looks a group up only when the sample's group index changes. Its
  // sample runs fix the adaptive step across a run, and a leap ends a run: the same samples
  // with leaps and without there under a fixed step.
  struct Case {
    bool iso, runs;
  };
  for (const char* store : {"ml.store", "sphere.store"})
    for (const Case c : {Case{true, false}, Case{false, false}, Case{false, true}}) {
      const std::string what = fmt::format("{}, {}", store, c.iso ? "iso" : c.runs ? "dvr in sample runs" : "dvr");
      Scene sc = scene((c.iso ? iso_scene() : dvr_scene()) + R"(, "values": "normalized", "quality": {"lod_ratio": 0.25})", 96);
      sc.dataset = dir_->file(store);
      FrameBuffers fb[2];
      uint64_t samples[2];
      for (int skip = 0; skip < 2; ++skip) {
        RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"skip_cells", double(skip)}, {"step", 0.25},
                                                           {"sample_runs", c.runs ? 1.0 : 0.0}, {"adaptive_step", c.runs ? 1.0 : 8.0}}));
        samples[skip] = g.render(0, fb[skip], kAll).counters.samples;
        EXPECT_TRUE(g.converged());
        ASSERT_TRUE(all_finite(fb[skip]));
      }
      const ImageError e = compare_frames(fb[1], fb[0], 1.0);
      EXPECT_LT(e.rmse, 1e-6) << what << ": " << e.to_json();
      EXPECT_EQ(e.coverage_mismatch, 0u) << what << ": " << e.to_json();
      if (c.iso) {
        EXPECT_LT(e.depth_max, 1e-6) << what << ": " << e.to_json();
      }
      if (c.runs) continue;  // under a fixed step the sphere's leaps save nothing (1.01x the samples)
      // Measured: iso 0.91 (ML) and 0.46 (sphere), DVR 0.81 and 0.93. A look skipped where a
      // group should be looked up leaps less, and takes more samples.
      const bool sphere = store == std::string("sphere.store");
      const double most = c.iso ? (sphere ? 0.6 : 1.0) : (sphere ? 0.96 : 0.85);
      EXPECT_LT(double(samples[1]), most * double(samples[0]))
          << what << ": " << samples[1] << " samples with leaps, " << samples[0] << " without";
    }
}

TEST_F(GigaVoxels, SampleRunsTakeTheSamplesOneAtATimeTakes) {
  // DVR at one level takes runs of 8 samples side by side (vector lanes): under a fixed step
  // the same samples and arithmetic as one at a time, lit by a headlight, a directional light
  // or none, with normals and depth out, face lighting or not; a point light's direction
  // changes along the ray, and it keeps to one at a time. Under the adaptive step a run keeps
  // its first step, so it samples a little more densely and the error stays as low.
  struct Case {
    const char* shading;
    double face_lighting;
  };
  for (const Case c : {Case{R"({"light": "headlight"})", 1}, Case{R"({"light": "headlight"})", 0},
                       Case{R"({"light": "directional", "light_direction": [1, 0.3, -0.5]})", 1}, Case{R"({"light": "none"})", 1},
                       Case{R"({"light": "point", "light_position": [1.4, 0.5, 0.2]})", 1}}) {
    SCOPED_TRACE(fmt::format("{}, face_lighting {}", c.shading, c.face_lighting));
    const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25}, "shading": )" + std::string(c.shading), 64);
    const auto render = [&](double runs, double adaptive_step, FrameBuffers& fb) {
      RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.5}, {"adaptive_step", adaptive_step},
                                                         {"face_lighting", c.face_lighting}, {"sample_runs", runs}}));
      const FrameStats st = g.render(0, fb, kAll);
      EXPECT_TRUE(g.converged());
      EXPECT_TRUE(all_finite(fb));
      return st;
    };
    const bool point_light = std::string(c.shading).find("point") != std::string::npos;
    FrameBuffers one, run;
    const FrameStats one_stats = render(0, 1, one), run_stats = render(1, 1, run);
    const RayCounters &one_counters = one_stats.counters, &run_counters = run_stats.counters;
    EXPECT_EQ(run_counters.samples, one_counters.samples);
    // Runs take the samples where a leap starts and a node's exit too, so that most are theirs
    // (measured: 0.91 of them here).
    EXPECT_EQ(one_stats.backend_value("samples_in_runs"), 0);
    if (point_light) EXPECT_EQ(run_stats.backend_value("samples_in_runs"), 0);
    else EXPECT_GT(run_stats.backend_value("samples_in_runs"), 0.88 * double(run_counters.samples));
    EXPECT_EQ(run_counters.gradients, one_counters.gradients);
    const ImageError e = compare_frames(run, one, 1.0);
    EXPECT_EQ(e.coverage_mismatch, 0u) << e.to_json();
    EXPECT_LT(e.depth_max, 1e-6) << e.to_json();
    EXPECT_LT(e.normal_p99_deg, 1e-3) << e.to_json();
    float worst = 0;  // the lanes' fused arithmetic may round apart from the scalar's
    for (size_t i = 0; i < one.color.size(); ++i) {
      const auto &a = one.color.data()[i], &b = run.color.data()[i];
      worst = std::max({worst, std::abs(a.r - b.r), std::abs(a.g - b.g), std::abs(a.b - b.b), std::abs(a.a - b.a)});
    }
    EXPECT_LE(worst, 1e-6f);

    const FrameBuffers truth = reference_frame(sc);
    FrameBuffers one_adaptive, run_adaptive;
    const RayCounters one_adaptive_counters = render(0, 8, one_adaptive).counters, run_adaptive_counters = render(1, 8, run_adaptive).counters;
    const double one_rmse = compare_frames(one_adaptive, truth, 1.0).rmse, run_rmse = compare_frames(run_adaptive, truth, 1.0).rmse;
    EXPECT_LE(run_rmse, 1.02 * one_rmse);
    EXPECT_LE(run_adaptive_counters.samples, 1.15 * double(one_adaptive_counters.samples));
    // Runs hold the adaptive step, so they take other samples: proof that they ran at all.
    EXPECT_EQ(run_adaptive_counters.samples == one_adaptive_counters.samples, point_light);
    std::cout << "[ measured ] " << c.shading << ", adaptive step: one at a time RMSE " << one_rmse << " in "
              << one_adaptive_counters.samples << " samples, in runs " << run_rmse << " in " << run_adaptive_counters.samples << "\n";
  }
  // A termination opacity of 0 ends a ray at its first sample, in a run as one at a time.
  const Scene stop_at_once = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25, "termination_opacity": 0})", 32);
  FrameBuffers fb[2];
  uint64_t samples[2];
  for (int runs = 0; runs < 2; ++runs) {
    RenderSession g(stop_at_once, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.5}, {"adaptive_step", 1}, {"sample_runs", double(runs)}}));
    samples[runs] = g.render(0, fb[runs], kAll).counters.samples;
  }
  EXPECT_EQ(samples[1], samples[0]);
  EXPECT_LT(compare_frames(fb[1], fb[0], 1.0).rmse, 1e-6);
}

TEST_F(GigaVoxels, DvrLeapsClearGroupsWhereTwoLevelsBlend) {
  // At lod_ratio 2 every sample blends two levels. Two clear groups blend to a clear value when
  // both lie in the same interval of values the transfer function hides, so such samples are
  // leapt too; a clear group inside the sphere and one outside it are not (the shell between
  // them shows). Sample positions past a leap follow the footprint where the leap began rather
  // than step by step, so the image is another sampling of the same integral: as close to the
  // reference as marching every step, with fewer samples. A 128^3 sphere, so that the blended
  // levels have groups finer than the shell's distance to the nodes' corners.
  const std::string store = field_store("sphere", 128, "sphere128.store");
  Scene sc = scene(R"("mode": "dvr", "values": "stored", "quality": {"lod_ratio": 2}, "transfer_function": {"points": [
      {"value": -0.03, "color": [0.2, 0.4, 0.9], "opacity": 0}, {"value": 0, "color": [1, 0.4, 0.2], "opacity": 0.5},
      {"value": 0.03, "color": [0.2, 0.4, 0.9], "opacity": 0}]})", 128);
  sc.dataset = store;
  const FrameBuffers truth = reference_frame(sc);
  double rmse[2];
  uint64_t samples[2];
  for (int skip = 0; skip < 2; ++skip) {
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"skip_cells", double(skip)}, {"step", 0.5}}));
    FrameBuffers fb;
    samples[skip] = g.render(0, fb, kAll).counters.samples;
    ASSERT_TRUE(all_finite(fb));
    rmse[skip] = compare_frames(fb, truth, 1.0).rmse;
  }
  EXPECT_LE(rmse[1], 1.05 * rmse[0] + 1e-4) << "with leaps " << rmse[1] << ", without " << rmse[0];
  EXPECT_LT(double(samples[1]), 0.95 * double(samples[0])) << samples[1] << " samples with leaps, " << samples[0] << " without";
}

TEST_F(GigaVoxels, DvrIntegratesEveryPartOfTheRayOnce) {
  // Constant opacity a and colour over every value: a ray that crosses L voxels has opacity
  // 1 - (1 - a)^L whatever the field, so every part-step must count once: the one before the
  // ray leaves the volume, and those where constant nodes (integrated whole) meet bricks
  // (sampled). The sphere's distance is bricks everywhere; sparse blobs lie in a constant
  // background. Steps that divide nothing.
  const std::string blobs = field_store("sparse-blobs", 64, "blobs.store");
  Scene sc = scene(R"("mode": "dvr", "values": "stored", "shading": {"light": "none"}, "transfer_function": {"points": [
      {"value": -10, "color": [0.8, 0.6, 0.2], "opacity": 0.02}, {"value": 10, "color": [0.8, 0.6, 0.2], "opacity": 0.02}]})", 32);
  // The sponge (source 1): its empty nodes are constant, and its box is the tree's, so the
  // ray's exit lies on node faces.
  const std::map<std::string, double> sponge = {{"source", 1}, {"menger_brick", 9}};
  for (const auto& [store, source] : {std::pair{dir_->file("sphere.store"), std::map<std::string, double>{}}, {blobs, {}},
                                      {dir_->file("ml.store"), sponge}}) {
    sc.dataset = store;
    for (double step : {0.7, 1.3, 2.9}) {
      std::map<std::string, double> params = source;
      params["exact"] = 1, params["step"] = step;
      RenderSession g(sc, backend_options("gigavoxels", params));
      FrameBuffers fb;
      g.render(0, fb, kAll);
      const ImageRays rays(g.camera(0), 32, 32);
      for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 32; ++x) {
          const PrimaryRay ray = primary_ray(rays, g.context().geometry(), x, y);
          const double voxels = ray.hits() ? (ray.span.t1 - ray.span.t0) * length(ray.dir) : 0;
          ASSERT_NEAR(fb.color(x, y).a, 1 - std::pow(1 - 0.02, voxels), 2e-4)
              << store << (source.empty() ? "" : " (sponge)") << " step " << step << " pixel " << x << "," << y;
        }
    }
  }
}

TEST_F(GigaVoxels, SearchingBetweenSamplesFindsTheSurfacesAStepSkips) {
  // A step skips over surfaces it grazes: rays near a silhouette, ripples thinner than the
  // step. Halving a step wherever the brick's bounds let the field reach an isovalue and come
  // back finds them: only crossings closer than 2^-5 voxels can still hide. Marschner-Lobb at
  // 64^3 is ripples everywhere; close up, even the default half-voxel step skips some.
  struct Case {
    const char* what;
    const char* store;
    std::string mode, camera;
    double step, max_rmse_ratio;
  };
  const std::string sphere = R"("mode": "iso", "isosurfaces": [{"value": 0.0}], "shading": {"light": "headlight"})";
  const std::string close = R"("camera": {"eye": [0.95, -0.25, 0.85], "target": [0.5, 0.5, 0.45], "fov_degrees": 35})";
  const Case cases[] = {{"sphere, step 4", "sphere.store", sphere, kCamera, 4, 0.8},
                        {"Marschner-Lobb, step 4", "ml.store", iso_scene(), kCamera, 4, 0.5},
                        {"Marschner-Lobb close up, step 0.5", "ml.store", iso_scene(), close, 0.5, 0.2}};
  for (const Case& c : cases) {
    Scene sc = scene(c.mode + R"(, "quality": {"lod_ratio": 0.25})", 96, c.camera);
    sc.dataset = dir_->file(c.store);
    RenderSession ref(sc, backend_options("reference"));
    FrameBuffers truth;
    ref.render(0, truth, kAll);
    const double voxel = ref.context().geometry().voxel_size;
    ImageError e[2];
    uint64_t samples[2];
    int false_hits[2] = {0, 0};  // pixels hit where the reference sees nothing
    for (int search = 0; search < 2; ++search) {
      RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", c.step}, {"hidden_crossings", search ? 5.0 : 0.0}}));
      FrameBuffers fb;
      samples[search] = g.render(0, fb, kAll).counters.samples;
      ASSERT_TRUE(all_finite(fb));
      e[search] = compare_frames(fb, truth, voxel);
      for (int y = 0; y < fb.height(); ++y)
        for (int x = 0; x < fb.width(); ++x) false_hits[search] += std::isfinite(fb.depth(x, y)) && !std::isfinite(truth.depth(x, y));
    }
    std::cout << "[ measured ] " << c.what << ": RMSE " << e[0].rmse << " -> " << e[1].rmse << ", coverage mismatch "
              << e[0].coverage_mismatch << " -> " << e[1].coverage_mismatch << " (false hits " << false_hits[0] << " -> "
              << false_hits[1] << "), samples " << samples[0] << " -> " << samples[1] << "\n";
    EXPECT_GT(e[0].coverage_mismatch, 0u) << c.what << ": the step must skip something for this test to mean anything";
    EXPECT_LT(e[1].coverage_mismatch, e[0].coverage_mismatch) << c.what;
    EXPECT_LT(e[1].rmse, c.max_rmse_ratio * e[0].rmse) << c.what;
    // What the search finds is a sign change of the field between two of its samples: never a
    // surface the reference does not see (sampling outside the brick's node once did that).
    EXPECT_EQ(false_hits[1], false_hits[0]) << c.what;
  }
}

TEST_F(GigaVoxels, AStepLongerThanANodeStillEntersAndSearchesEveryNodeItCrosses) {
  // A sphere of radius 6.4 voxels around the corner where eight finest nodes (8 voxels wide)
  // meet, marched with steps of 8 and 3 voxels: most rays cross some of those nodes for less
  // than a step. Three things once lost it:
  // - coarse nodes took their own level's range, which averaging had moved off the isovalue,
  //   so the whole sphere was an invisible constant;
  // - the position a step reached past a node's exit decided the next node, so a node the ray
  //   left within that step was never entered;
  // - a step from one cube of clear cell groups into another was not searched between them.
  const std::string corner = field_store("sphere", 64, "corner-sphere.store", {{"radius", 0.1}});
  const std::string close = R"("camera": {"eye": [0.95, -0.1, 0.9], "target": [0.5, 0.5, 0.5], "fov_degrees": 35})";
  Scene sc = scene(R"("mode": "iso", "isosurfaces": [{"value": 0.0}], "quality": {"lod_ratio": 0.25})", 96, close);
  sc.dataset = corner;
  const FrameBuffers truth = reference_frame(sc);
  const int sphere_pixels = hit_pixels(truth);
  ASSERT_GT(sphere_pixels, 500);
  for (double step : {8.0, 3.0}) {
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"step", step}}));
    FrameBuffers fb;
    g.render(0, fb, kAll);
    ASSERT_TRUE(all_finite(fb));
    const ImageError e = compare_frames(fb, truth, g.context().geometry().voxel_size);
    std::cout << "[ measured ] step " << step << ": coverage mismatch " << e.coverage_mismatch << " of " << sphere_pixels
              << " sphere pixels, depth p99 " << e.depth_p99 << " voxels\n";
    // Only a silhouette graze shallower than the search's resolution (2^-5 voxels) may hide.
    EXPECT_LE(e.coverage_mismatch, 2u) << "step " << step;
    // A crossing is bisected to 2^-refine voxels whatever the step, so hits are as precise.
    EXPECT_LT(e.depth_p99, 1e-3) << "step " << step;
  }
}

TEST_F(GigaVoxels, ApproximateModeConvergesToExactModeAfterACameraJump) {
  const Scene sc = camera_jump_scene();
  RenderSession exact(sc, backend_options("gigavoxels", {{"exact", 1}}));
  FrameBuffers want, fb;
  exact.render(1, want, kAll);
  RenderSession approx(sc, backend_options("gigavoxels"));
  approx.settle(0, kAll);
  int frames = 0;
  double rmse = 1;
  for (; frames < 40 && rmse > 1e-6; ++frames) {
    approx.render(1, fb, kAll);
    ASSERT_TRUE(all_finite(fb));
    approx.bricks().wait_idle();
    rmse = compare_frames(fb, want, 1.0).rmse;
  }
  EXPECT_LE(rmse, 1e-6);
  EXPECT_LE(frames, 12) << "frames to converge after the jump";
}

TEST_F(GigaVoxels, SettlingWithCompleteFramesTakesExactPassesAndShowsTheSameImage) {
  // A still image's warm-up frames are not shown: completed at once (exact passes), one
  // converges where approximate ones take several, to the same image; the frames
  // shown afterwards are approximate again (a jump's first frame is one pass, unconverged).
  const Scene sc = camera_jump_scene();
  RenderSession refined(sc, backend_options("gigavoxels"));
  const int refine_frames = refined.settle(0, kAll);
  RenderSession completed(sc, backend_options("gigavoxels"));
  const int complete_frames = completed.settle(0, kAll, RenderSession::kMaxSettleFrames, RenderSession::Settle::complete);
  EXPECT_GE(refine_frames, 3);
  EXPECT_EQ(complete_frames, 2);  // one complete frame, then one as shown, already converged
  EXPECT_TRUE(completed.converged());
  FrameBuffers a, b;
  refined.render(0, a, kAll);
  const FrameStats still = completed.render(0, b, kAll);
  EXPECT_EQ(still.backend_value("passes"), 1);
  EXPECT_TRUE(completed.converged());
  EXPECT_EQ(a.color, b.color);
  const FrameStats jump = completed.render(1, b, kAll);
  EXPECT_EQ(jump.backend_value("passes"), 1);
  EXPECT_GT(jump.backend_value("feedback_requests"), 0);
  EXPECT_FALSE(completed.converged());
}

TEST_F(GigaVoxels, CompleteFromEmptyCachesGivesTheConvergedImageInOneFrame) {
  // A still camera's image asked for at once (bench's "still" time): from empty caches, one
  // complete frame of exact passes, the image the frames shown converge to.
  const Scene sc = camera_jump_scene();
  RenderSession refined(sc, backend_options("gigavoxels"));
  refined.settle(0, kAll);
  FrameBuffers want, got;
  refined.render(0, want, kAll);
  RenderSession still(sc, backend_options("gigavoxels"));
  EXPECT_EQ(still.complete(still.setup(0, kAll), got), 1);
  EXPECT_TRUE(still.converged());
  EXPECT_EQ(got.color, want.color);
  // Each exact pass read its bricks ahead, side by side (Source::read_ahead): the reads are
  // the stalls, and every blocking fill then found its brick in the L1.
  const CacheStats cs = still.pages().stats();
  EXPECT_GT(cs.stalls, 0u);
  EXPECT_GE(cs.l1.hits, cs.stalls);
  // And again after the caches are dropped; the frames shown afterwards are approximate.
  still.reset_cache();
  EXPECT_EQ(still.complete(still.setup(0, kAll), got), 1);
  EXPECT_EQ(got.color, want.color);
  EXPECT_EQ(still.render(1, got, kAll).backend_value("passes"), 1);
  EXPECT_FALSE(still.converged());
}

TEST_F(GigaVoxels, BrickPoolAndCacheShareTheL1BudgetAndStillConverge) {
  // The cache's L1 keeps only the slots the loader stages its copies through (2 x upload_budget);
  // the brick pool takes the rest of the budget, not a second budget of its own. The loader asks
  // the cache for no more bricks a frame than half those slots (a frame's loads fit beside the
  // last frame's until both are copied), and approximate mode still
  // converges to exact mode's image. A pool sized by hand leaves the cache the whole budget.
  Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.5})", 64);
  const uint64_t budget = uint64_t(4) << 20;
  sc.cache.l1_bytes = budget;
  RenderSession exact(sc, backend_options("gigavoxels", {{"upload_budget", 32}, {"exact", 1}}));
  FrameBuffers want, fb;
  exact.render(0, want, kAll);
  RenderSession approx(sc, backend_options("gigavoxels", {{"upload_budget", 32}}));
  FrameStats st;
  int frames = 0;
  double rmse = 1;
  uint64_t most_requests = 0;
  for (; frames < 60 && rmse > 1e-6; ++frames) {
    st = approx.render(0, fb, kAll);
    most_requests = std::max(most_requests, st.requests);
    approx.bricks().wait_idle();
    rmse = compare_frames(fb, want, 1.0).rmse;
  }
  EXPECT_LE(rmse, 1e-6) << "after " << frames << " frames";
  EXPECT_GT(frames, 1);  // the first frame had nothing loaded
  EXPECT_GT(most_requests, 0u);
  EXPECT_LE(most_requests, approx.bricks().pool_slots() / 2);
  const uint64_t staged = approx.bricks().stats().l1_pool_bytes, pool = uint64_t(st.backend_value("brick_pool_bytes"));
  EXPECT_LT(staged, budget / 4);
  EXPECT_LE(staged + pool, budget);
  EXPECT_GT(staged + pool, budget * 99 / 100);  // the pool takes what the cache's L1 left

  RenderSession by_hand(sc, backend_options("gigavoxels", {{"brick_slots", 100}}));
  by_hand.render(0, fb, kAll);
  EXPECT_EQ(by_hand.bricks().stats().l1_pool_bytes, budget / by_hand.bricks().shape().bytes() * by_hand.bricks().shape().bytes());
}

TEST_F(GigaVoxels, OnlyIsoBricksKeepTheDifferencesItsSearchReads) {
  // A brick's differences bound the field for iso's search for hidden crossings; DVR never
  // reads them, so its slots are that much smaller and the same budget holds more of them.
  struct Pool {
    double slots = 0, slot_bytes = 0;
  };
  const auto pool = [&](const std::string& mode, const RenderSession::Options& options) {
    RenderSession session(scene(mode), options);
    FrameBuffers fb;
    const FrameStats st = session.render(0, fb, kAll);
    const double slots = st.backend_value("brick_slots");
    return Pool{slots, st.backend_value("brick_pool_bytes") / slots};
  };
  const Pool iso = pool(iso_scene(), backend_options("gigavoxels"));
  const Pool dvr = pool(dvr_scene(), backend_options("gigavoxels"));
  EXPECT_EQ(iso.slot_bytes - dvr.slot_bytes, double(sizeof(gigavoxels::BrickDifferences)));
  EXPECT_GT(dvr.slots, iso.slots);  // the same L1 budget
  // Iso without a search: none (hidden_crossings 0), or a step so fine that 2^-1 voxels of it
  // need no halving.
  EXPECT_EQ(pool(iso_scene(), backend_options("gigavoxels", {{"hidden_crossings", 0}})).slot_bytes, dvr.slot_bytes);
  EXPECT_EQ(pool(iso_scene(), backend_options("gigavoxels", {{"hidden_crossings", 1}, {"step", 0.25}})).slot_bytes, dvr.slot_bytes);
  EXPECT_EQ(pool(iso_scene(), backend_options("gigavoxels", {{"hidden_crossings", 1}, {"step", 1}})).slot_bytes, iso.slot_bytes);
}

TEST_F(GigaVoxels, ABrickTheLoaderAskedForIsCopiedWhenItArrivesAndReadOnce) {
  // A ray asks only for the first thing it misses, which moves as other data arrives: a brick
  // loaded for it may not be asked for again the next frame. The loader copies what it asked
  // for when it arrives all the same, so no brick is read twice (none is pushed out of the
  // cache's few L1 stages before it is copied, to be loaded again from L2), and the bricks come
  // in at no less than half of upload_budget a frame.
  Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25})", 64);
  sc.cache.l1_bytes = uint64_t(4) << 20;
  const int budget = 8;
  RenderSession approx(sc, backend_options("gigavoxels", {{"upload_budget", budget}}));
  FrameBuffers fb;
  FrameStats st;
  int frames = 0;
  for (; frames < 200; ++frames) {
    st = approx.render(0, fb, kAll);
    approx.bricks().wait_idle();
    if (st.backend_value("feedback_requests") == 0) break;
  }
  const double bricks = st.backend_value("bricks_in_use");
  ASSERT_LT(frames, 200);
  ASSERT_GT(bricks, 20 * budget);  // many frames' worth
  const CacheStats cs = approx.bricks().stats();
  EXPECT_EQ(cs.l2.hits, 0u) << "bricks loaded into L1 again";
  EXPECT_EQ(cs.l1.inserts, cs.l3.hits);  // l3.hits: bricks read from the store
  EXPECT_LE(frames, int(bricks / budget * 2) + 12) << bricks << " bricks";
}

TEST_F(GigaVoxels, AnL1TooSmallForItsPoolIsRefusedNamingTheLeastThatWorks) {
  // The brick pool takes what the cache's L1 leaves of the budget, and needs kMinBrickSlots: a
  // budget that leaves it fewer is refused before the first frame, naming the least L1 that
  // does, instead of a pool allocated past the budget (8 slots over an L1 of one brick, once).
  // At that least L1 the volume still loads: the cache's L1 stages a quarter of the budget,
  // and the loader may have one brick asked for at a time (half of a few slots must not round
  // to none, which would load nothing and call the empty image converged).
  Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.5})", 32);
  RenderSession probe(sc, backend_options("gigavoxels"));
  const uint64_t brick = probe.bricks().shape().bytes();
  uint64_t least = 0;
  std::vector<std::string> refusals;
  for (uint64_t n = 1; n < 64 && least == 0; ++n) {
    sc.cache.l1_bytes = n * brick;
    try {
      RenderSession session(sc, backend_options("gigavoxels"));
      least = n;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument) << e.what();
      EXPECT_EQ(e.field(), "cache.l1") << e.what();
      EXPECT_EQ(e.file(), dir_->file("scene.json")) << e.what();
      EXPECT_NE(e.message().find(fmt::format("cache.l1 holds {} (", n)), std::string::npos) << e.what();
      refusals.push_back(e.message());
    }
  }
  ASSERT_GT(least, 1u) << "an L1 of one brick was accepted";
  for (const std::string& m : refusals)
    EXPECT_NE(m.find(fmt::format("gigavoxels needs an L1 of at least {} bricks ({})", least, format_bytes(double(least * brick)))),
              std::string::npos)
        << m;
  sc.cache.l1_bytes = least * brick;
  RenderSession approx(sc, backend_options("gigavoxels"));
  EXPECT_EQ(approx.bricks().pool_slots(), std::max<uint64_t>(least / 4, 1));
  FrameBuffers fb;
  FrameStats st;
  int held_back = 0;  // frames that said the pools held them back: the view wants far more than 8 bricks
  for (int frame = 0; frame < 16; ++frame) {
    st = approx.render(0, fb, kAll);
    approx.bricks().wait_idle();
    held_back += st.below_quality.find("gigavoxels' pools held back refinement") != std::string::npos;
  }
  EXPECT_EQ(st.backend_value("brick_slots"), double(gigavoxels::kMinBrickSlots));
  EXPECT_LE(double(approx.bricks().stats().l1_pool_bytes) + st.backend_value("brick_pool_bytes"), double(least * brick));
  EXPECT_EQ(st.backend_value("bricks_in_use"), st.backend_value("brick_slots")) << "the pool fills";
  EXPECT_GT(held_back, 0);
}

TEST_F(GigaVoxels, AFrameBelowTheQualityAskedSaysWhy) {
  // Exact mode with one pass: the first pass finds nothing loaded, and the rest of the frame
  // takes coarser data. With its passes and an ample pool, the frame is as asked.
  const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.5})", 32);
  FrameBuffers fb;
  RenderSession one_pass(sc, backend_options("gigavoxels", {{"exact", 1}, {"max_passes", 1}}));
  const FrameStats cut = one_pass.render(0, fb, kAll);
  EXPECT_EQ(cut.backend_value("passes"), 2);
  EXPECT_NE(cut.below_quality.find("gigavoxels' exact mode ran out of passes (max_passes 1)"), std::string::npos)
      << cut.below_quality;
  RenderSession exact(sc, backend_options("gigavoxels", {{"exact", 1}}));
  const FrameStats full = exact.render(0, fb, kAll);
  EXPECT_TRUE(exact.converged());
  EXPECT_EQ(full.below_quality, "");
}

TEST_F(GigaVoxels, DifferenceNormalsAreTheReferencesOwn) {
  // Central and forward differences one voxel apart, within the store brick holding the
  // sample's cell, one-sided at its faces and the volume's, as the reference takes them. Iso
  // normals and lit DVR match the reference with the same normals far better than with
  // analytic ones (whose error against it would otherwise be blamed on sampling). In the half
  // voxel below a store brick's first voxel, the lower difference reaches the brick border's
  // voxel, one voxel short of the reference's: in 32^3 bricks, the stores' default, that is
  // 1/64 of each axis; in 8^3 bricks 1/16 (on a 45^3 volume, whose last brick is partial).
  struct Case {
    int n, brick;
    double most_deg;  // mean iso normal error
  };
  for (const Case& k : {Case{64, 32, 0.4}, Case{45, 8, 2.5}}) {
    BuildOptions o;
    o.brick_size = k.brick;
    const std::string store = dir_->file(fmt::format("ml-{}-{}.store", k.n, k.brick));
    build_store(*make_field_source(make_field("marschner-lobb", {}), {k.n, k.n, k.n}, ValueType::f32), store, o);
    for (const std::string method : {"central", "forward"}) {
      SCOPED_TRACE(fmt::format("{} on {}^3 in {}^3 bricks", method, k.n, k.brick));
      const std::string shading = R"(, "shading": {"light": "headlight", "normals": ")" + method + R"("})";
      Scene iso = scene(iso_scene() + R"(, "quality": {"lod_ratio": 0.25})" + shading, 64);
      Scene dvr = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.25, "termination_opacity": 0.999})" + shading, 64);
      iso.dataset = dvr.dataset = store;
      const FrameBuffers iso_truth = reference_frame(iso), dvr_truth = reference_frame(dvr);
      double normal_deg[2], dvr_rmse[2];  // [0]: analytic normals, [1]: the scene's
      for (int own = 0; own < 2; ++own) {
        Scene si = iso, sd = dvr;
        if (!own) si.shading.normals = sd.shading.normals = NormalMethod::analytic;
        RenderSession gi(si, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.25}, {"refine", 20}}));
        RenderSession gd(sd, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.125}, {"adaptive_step", 1}}));
        FrameBuffers fi, fd;
        gi.render(0, fi, kAll);
        gd.render(0, fd, kAll);
        ASSERT_TRUE(all_finite(fi));
        ASSERT_TRUE(all_finite(fd));
        normal_deg[own] = compare_frames(fi, iso_truth, 1.0).normal_mean_deg;
        dvr_rmse[own] = compare_frames(fd, dvr_truth, 1.0).rmse;
      }
      EXPECT_LT(normal_deg[1], k.most_deg) << "analytic normals: " << normal_deg[0];
      EXPECT_LT(dvr_rmse[1], 0.2 * dvr_rmse[0]) << dvr_rmse[1] << ", analytic normals " << dvr_rmse[0];
      if (k.brick != 32) continue;
      RenderSession g(dvr, backend_options("gigavoxels", {{"exact", 1}, {"step", 0.25}, {"adaptive_step", 1}}));
      FrameBuffers fb;
      g.render(0, fb, kAll);
      expect_as_good_as_raymarch(dvr, fb, 0.25, 0.02);  // at the same fixed step
      // Coarser levels, blended (lod_ratio 4): each level's differences in its own voxels. The
      // levels' error dominates; it is about what it is with analytic normals.
      double blended_rmse[2];
      for (int own = 0; own < 2; ++own) {
        Scene sb = dvr;
        sb.quality.lod_ratio = 4;
        if (!own) sb.shading.normals = NormalMethod::analytic;
        RenderSession gb(sb, backend_options("gigavoxels", {{"exact", 1}}));
        FrameBuffers fbl;
        gb.render(0, fbl, kAll);
        ASSERT_TRUE(all_finite(fbl));
        sb.quality.lod_ratio = dvr.quality.lod_ratio;
        blended_rmse[own] = compare_frames(fbl, own ? dvr_truth : reference_frame(sb), 1.0).rmse;
      }
      EXPECT_LT(blended_rmse[1], 1.5 * blended_rmse[0]) << "analytic normals: " << blended_rmse[0];
    }
  }
  // gobbetti shades with the exact gradient of the interpolant alone, and refuses the others
  // by name rather than render other normals.
  const Scene central = scene(dvr_scene() + R"(, "shading": {"light": "headlight", "normals": "central"})", 16);
  try {
    RenderSession session(central, backend_options("gobbetti"));
    ADD_FAILURE() << "gobbetti accepted central normals";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::unsupported) << e.what();
    EXPECT_EQ(e.field(), "shading.normals") << e.what();
    EXPECT_NE(std::string(e.what()).find("gobbetti does not compute central normals"), std::string::npos) << e.what();
  }
}

TEST_F(GigaVoxels, QuadrilinearFilteringBeatsNearestLevelAgainstASupersampledReference) {
  // Far enough that coarse levels are chosen, the reference supersampled 5x5 and box-filtered.
  // Both light a segment with its ends' mean: face_lighting needs both ends in one level's
  // lattice, which blended samples are not, and would favour nearest level for its lighting.
  const std::string far = R"("camera": {"eye": [3.5, -2.4, 2.9], "target": [0.5, 0.5, 0.45], "fov_degrees": 35})";
  const FrameBuffers truth = resolve_supersampled(reference_frame(scene(dvr_scene(), 160, far), {}), 5);
  const Scene small = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 1})", 32, far);
  double err[2];
  for (int q = 0; q < 2; ++q) {
    RenderSession g(small, backend_options("gigavoxels", {{"exact", 1}, {"quadrilinear", double(q)}, {"step", 0.25}, {"face_lighting", 0}}));
    FrameBuffers fb;
    g.render(0, fb, {});
    err[q] = compare_frames(fb, truth, 1.0).rmse;
  }
  EXPECT_LT(err[1], err[0]) << "quadrilinear " << err[1] << " vs nearest level " << err[0];
  std::cout << "[ measured ] quadrilinear " << err[1] << " vs nearest level " << err[0] << "\n";
}

TEST_F(GigaVoxels, ArityThreeRendersTheInstancedMengerSpongeFromOneBrick) {
  // The volume's box holds the sponge (N = 3, M = 9): every non-empty node at every depth
  // points to the one shared brick; the faces of the solid are surfaces (empty outside).
  const Scene sc = scene(R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "values": "stored", "shading": {"light": "headlight"})", 64);
  RenderSession g(sc, backend_options("gigavoxels", {{"source", 1}, {"menger_brick", 9}, {"exact", 1}}));
  FrameBuffers fb;
  const FrameStats st = g.render(0, fb, kAll);
  ASSERT_TRUE(all_finite(fb));
  EXPECT_TRUE(g.converged());
  EXPECT_GT(st.backend_value("subdivisions"), 0);
  EXPECT_EQ(st.backend_value("bricks_in_use"), 1);
  EXPECT_GT(hit_pixels(fb), 500);
  // Through the middle of a face lies the central tunnel, empty at every depth: a ray along
  // the x axis through the centre of the box sees nothing.
  const Scene through = scene(R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "values": "stored")", 8,
                              R"("camera": {"eye": [-2, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 1})");
  RenderSession t(through, backend_options("gigavoxels", {{"source", 1}, {"menger_brick", 9}, {"exact", 1}}));
  t.render(0, fb, kAll);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_FALSE(std::isfinite(fb.depth(x, y))) << x << "," << y;
}

TEST_F(GigaVoxels, ProceduralAndStoredBricksMixInOneTree) {
  // Close up at a fine lod_ratio, the footprint asks for levels below the finest stored one
  // (depth 3 of 64^3 in 8^3 bricks): those bricks are produced, the others loaded.
  const std::string close = R"("camera": {"eye": [0.95, -0.25, 0.85], "target": [0.5, 0.5, 0.45], "fov_degrees": 35})";
  const Scene sc = scene(iso_scene() + R"(, "quality": {"lod_ratio": 0.25})", 64, close);
  FrameBuffers stored, flat, detailed;
  RenderSession s(sc, backend_options("gigavoxels", {{"exact", 1}}));
  const FrameStats st = s.render(0, stored, kAll);
  EXPECT_EQ(st.backend_value("bricks_produced"), 0);
  const auto amplified = [&](double amplitude, FrameBuffers& fb) {
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}, {"source", 2}, {"amplify_levels", 2}, {"amplify_amplitude", amplitude}}));
    const FrameStats stats = g.render(0, fb, kAll);
    EXPECT_TRUE(g.converged());
    EXPECT_TRUE(all_finite(fb));
    EXPECT_GT(stats.backend_value("bricks_loaded"), 0);
    EXPECT_GT(stats.backend_value("bricks_produced"), 0);
    return stats;
  };
  const FrameStats flat_stats = amplified(0, flat);
  amplified(0.05, detailed);
  // Without detail, a produced brick is the stored level resampled: the surface is the stored
  // one up to re-interpolating the trilinear field (which is not trilinear one level down: its
  // kinks at the stored voxels are smoothed, and Marschner-Lobb at 64^3 is all kinks, so the
  // normals move by several degrees while the surface stays put).
  const ImageError e_flat = compare_frames(flat, stored, 1.0);
  EXPECT_LT(e_flat.depth_p99, 0.25) << e_flat.to_json();
  EXPECT_LT(e_flat.coverage_mismatch_fraction, 0.005) << e_flat.to_json();
  // With detail, the surface moves: by much more than the resampling (which the search for
  // crossings between samples shows more of: the stored field's thinnest crests, which the
  // resampled field smooths away).
  const ImageError e_detail = compare_frames(detailed, stored, 1.0);
  EXPECT_GT(e_detail.depth_mean, 2 * e_flat.depth_mean) << e_detail.to_json();
  EXPECT_GT(e_detail.normal_mean_deg, 2 * e_flat.normal_mean_deg) << e_detail.to_json();
  EXPECT_GT(flat_stats.backend_value("bricks_loaded") + flat_stats.backend_value("bricks_produced"), st.backend_value("uploads"));
}

/// The sponge around a corner of its box is a copy of itself scaled by 3 per level, so a camera
/// zoomed k levels deeper (its offsets from the corner divided by 3^k) must see the same image.
/// The box is 64 voxels wide (65 voxel centres) so that the camera's normalised coordinates are
/// the tree's unit coordinates bit for bit; the reference camera is the deep camera's actual
/// (rounded) offsets scaled back up, so rounding the deep camera cannot fail the test.
class GigaVoxelsZoom : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    BuildOptions o;
    o.brick_size = 16;
    auto box = make_field_source(make_field("sphere"), {65, 65, 65}, ValueType::u8);
    build_store(*box, dir_->file("box65.store"), o);
  }
  static void TearDownTestSuite() { delete dir_; }

  /// Eye and target at corner + sign * offset * 3^-depth, rendered in exact mode.
  static FrameBuffers render(double corner, const Vec3d& eye_offset, const Vec3d& target_offset, FrameStats* stats = nullptr) {
    const auto at = [&](const Vec3d& o) { return fmt::format("[{}, {}, {}]", corner + o.x, corner + o.y, corner + o.z); };
    const std::string text = fmt::format(
        R"({{"dataset": "box65.store", "image": {{"width": 48, "height": 48}}, "mode": "iso", "isosurfaces": [{{"value": 0.5}}],
            "values": "stored", "shading": {{"light": "headlight"}},
            "camera": {{"eye": {}, "target": {}, "up": [0, 0, 1], "fov_degrees": 40}}}})",
        at(eye_offset), at(target_offset));
    const Scene sc = parse_scene(text, dir_->file("zoom.json"));
    RenderSession g(sc, backend_options("gigavoxels", {{"source", 1}, {"menger_brick", 27}, {"exact", 1}}));
    FrameBuffers fb;
    const FrameStats st = g.render(0, fb, kAll);
    EXPECT_TRUE(g.converged());
    if (stats) *stats = st;
    return fb;
  }
  static testing::TempDir* dir_;
};
testing::TempDir* GigaVoxelsZoom::dir_ = nullptr;

TEST_F(GigaVoxelsZoom, ADeepZoomIntoTheSpongeSeesTheSameImageAsAShallowOne) {
  constexpr int kShallow = 6;
  const Vec3d eye_dir(-0.35, -0.25, -0.45), target_dir(0.5, 0.45, 0.55);  // from outside into the corner node
  struct Case {
    double corner;  // 0: offsets are positive into the box; 1: mirrored, negative
    int depth;
  };
  // At the corner (0,0,0) doubles resolve any offset: depth 37 puts the nodes the footprint asks
  // for at the sponge's max depth 39 (64-bit node coordinates); at (1,1,1) the eye itself is
  // quantised to 2^-53 (at depth 33 its offsets have about 2 bits), and the images still agree.
  // Both were bit-identical when this test was written; the tolerance leaves room for libm.
  for (const Case c : {Case{0, 20}, Case{0, 37}, Case{1, 20}, Case{1, 33}}) {
    const double sign = c.corner == 0 ? 1.0 : -1.0;
    const double shrink = std::pow(3.0, -c.depth);
    Vec3d eye, target;
    for (int a = 0; a < 3; ++a) {  // the offsets the deep camera really has, after rounding
      eye[a] = (c.corner + sign * eye_dir[a] * shrink) - c.corner;
      target[a] = (c.corner + sign * target_dir[a] * shrink) - c.corner;
    }
    const double grow = std::pow(3.0, c.depth - kShallow);
    FrameStats deep_stats;
    const FrameBuffers deep = render(c.corner, eye, target, &deep_stats);
    const FrameBuffers shallow = render(c.corner, eye * grow, target * grow);
    ASSERT_TRUE(all_finite(deep));
    EXPECT_GT(hit_pixels(shallow), 48 * 48 / 2) << "the view must be filled by the sponge";
    const ImageError e = compare_frames(deep, shallow, 1.0);
    EXPECT_LT(e.rmse, 1e-5) << "corner " << c.corner << ", depth " << c.depth << ": " << e.to_json();
    EXPECT_EQ(e.coverage_mismatch, 0u) << "corner " << c.corner << ", depth " << c.depth << ": " << e.to_json();
    EXPECT_GT(deep_stats.backend_value("passes"), c.depth) << "the tree was refined down to the camera";
  }
}

TEST_F(GigaVoxels, AStoreWithoutApronIsRefusedByNameUnlessNoBrickIsRead) {
  // Bricks are copied with a 1-voxel border from the store's apron: stored (0) and amplified
  // (2) sources need one; the sponge (1) reads no stored brick and renders.
  BuildOptions o;
  o.brick_size = 8;
  o.apron = 0;
  auto ml = make_field_source(make_field("marschner-lobb"), {32, 32, 32}, ValueType::f32);
  const std::string store = dir_->file("no-apron.store");
  build_store(*ml, store, o);
  Scene sc = scene(iso_scene(), 16);
  sc.dataset = store;
  for (double source : {0.0, 2.0}) {
    try {
      RenderSession g(sc, backend_options("gigavoxels", {{"source", source}}));
      ADD_FAILURE() << "source " << source << " rendered a store without apron";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("apron"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("no-apron.store"), std::string::npos) << e.what();
    }
  }
  RenderSession sponge(sc, backend_options("gigavoxels", {{"source", 1}, {"menger_brick", 9}, {"exact", 1}}));
  FrameBuffers fb;
  sponge.render(0, fb, kAll);
  EXPECT_TRUE(all_finite(fb));
}

TEST_F(GigaVoxels, TheImageDoesNotDependOnTheThreadCount) {
  const Scene sc = scene(dvr_scene() + R"(, "quality": {"lod_ratio": 0.5})", 48);
  FrameBuffers a, b;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}}));
    g.render(0, a, kAll);
  }
  {
    tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    RenderSession g(sc, backend_options("gigavoxels", {{"exact", 1}}));
    g.render(0, b, kAll);
  }
  for (size_t i = 0; i < a.color.size(); ++i) {
    ASSERT_EQ(a.color.data()[i].r, b.color.data()[i].r) << i;
    ASSERT_EQ(a.color.data()[i].a, b.color.data()[i].a) << i;
  }
}

}  // namespace
}  // namespace brickyard
