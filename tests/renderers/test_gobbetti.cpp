// The `gobbetti` back end as a renderer: it converges to the reference with an ample pool,
// degrades to coarser levels without holes when the pool is too small, never holds more data
// than the pool, and its visibility feedback never culls what the image shows.

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include <tbb/global_control.h>

#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "renderers/common/metrics.h"
#include "session/render_session.h"
#include "renderers/common/scene.h"
#include "renderers/render_test_util.h"
#include "test_util.h"

namespace brickyard {
namespace {

using testing::all_finite;
using testing::backend_options;
using testing::dvr_scene;
using testing::expect_as_good_as_raymarch;
using testing::reference_frame;
using testing::hit_pixels;
using testing::iso_scene;

/// Marschner-Lobb 64^3 f32 in 8^3 bricks (4 levels): detail everywhere, no constant bricks.
class Gobbetti : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    BuildOptions o;
    o.brick_size = 8;
    auto ml = make_field_source(make_field("marschner-lobb"), {64, 64, 64}, ValueType::f32);
    build_store(*ml, dir_->file("ml.store"), o);
    auto sphere = make_field_source(make_field("sphere"), {64, 64, 64}, ValueType::f32);
    build_store(*sphere, dir_->file("sphere.store"), o);
  }
  static void TearDownTestSuite() { delete dir_; }

  static Scene scene(const std::string& extra, int size = 64, const std::string& l1 = "64MiB",
                     const std::string& store = "ml.store") {
    const std::string text = R"({"dataset": ")" + store + R"(", "image": {"width": )" + std::to_string(size) + R"(, "height": )" +
                             std::to_string(size) + R"(}, "cache": {"l1": ")" + l1 + R"(", "l2": "64MiB"},
        "camera": {"eye": [1.8, -1.2, 1.5], "target": [0.5, 0.5, 0.45], "fov_degrees": 35}, )" + extra + "}";
    return parse_scene(text, dir_->file("scene.json"));
  }



  static testing::TempDir* dir_;
};
testing::TempDir* Gobbetti::dir_ = nullptr;

const FrameOutputs kAll{.depth = true, .normals = true};

TEST_F(Gobbetti, FirstFrameRequestsTheRootAndConvergesOverFrames) {
  RenderSession s(scene(iso_scene()), backend_options("gobbetti"));
  FrameBuffers fb;
  s.render(0, fb, kAll);
  EXPECT_FALSE(s.converged());  // the root was not resident: requested, nothing drawn yet
  const int frames = s.settle(0, kAll, 200);
  EXPECT_LT(frames, 200);
  EXPECT_TRUE(s.converged());
}

TEST_F(Gobbetti, WithAnAmplePoolAndASettledCameraMatchesTheReference) {
  // At lod_ratio 0.25 every leaf on screen is at the finest level, so what remains is the
  // sampling error of fixed steps: as small as the baseline's at the same step, and small.
  for (const std::string& mode : {iso_scene(), dvr_scene()}) {
    const Scene sc = scene(mode + R"(, "quality": {"lod_ratio": 0.25})", 96);
    FrameBuffers fb;
    RenderSession g(sc, backend_options("gobbetti", {{"step", 0.03125}, {"refine", 20}}));
    g.settle(0, kAll);
    const FrameStats st = g.render(0, fb, kAll);
    ASSERT_TRUE(all_finite(fb));
    expect_as_good_as_raymarch(sc, fb, 0.03125, 0.015);
    EXPECT_GT(st.backend_value("working_set"), 0);
  }
}

TEST_F(Gobbetti, WorkingSetNeverExceedsThePoolAndASmallPoolDegradesWithoutHoles) {
  // A sphere (its coarse levels keep its shape) at full resolution, then with a pool of 12
  // slots of 10^3 f32 voxels (8^3 bricks with apron): far fewer than the finest cut needs.
  const std::string sphere_iso = R"("mode": "iso", "isosurfaces": [{"value": 0.0}], "quality": {"lod_ratio": 0.25})";
  RenderSession ample(scene(sphere_iso, 64, "64MiB", "sphere.store"), backend_options("gobbetti"));
  ample.settle(0, kAll);
  FrameBuffers fine;
  const FrameStats fine_stats = ample.render(0, fine, kAll);
  RenderSession tight(scene(sphere_iso, 64, "48000", "sphere.store"), backend_options("gobbetti"));
  ASSERT_LT(tight.bricks().pool_slots(), fine_stats.backend_value("working_set"));
  FrameBuffers coarse;
  for (int f = 0; f < 30; ++f) {
    const FrameStats st = tight.render(0, coarse, kAll);
    tight.bricks().wait_idle();
    EXPECT_LE(st.backend_value("working_set"), double(tight.bricks().pool_slots()));
    ASSERT_TRUE(all_finite(coarse));
  }
  // Coarser, but no holes: wherever the full-resolution image shows the surface, so does the
  // coarse one (at a slightly different depth), and nearly nowhere else.
  int fine_hits = 0, holes = 0, extra = 0;
  for (int y = 0; y < fine.height(); ++y)
    for (int x = 0; x < fine.width(); ++x) {
      const bool f = std::isfinite(fine.depth(x, y)), c = std::isfinite(coarse.depth(x, y));
      fine_hits += f;
      holes += f && !c;
      extra += c && !f;
    }
  ASSERT_GT(fine_hits, 500);
  EXPECT_LT(double(holes), 0.02 * fine_hits) << holes << " of " << fine_hits;
  EXPECT_LT(double(extra), 0.02 * fine_hits) << extra << " of " << fine_hits;
}

TEST_F(Gobbetti, ACutHeldBackByThePoolSaysSoInItsFrameStatistics) {
  // An L1 of one brick holds the root and nothing to refine into: the cut stays at one leaf,
  // as converged as this pool allows, and every frame says it is below the quality asked.
  // With an ample pool, a settled frame is as asked.
  RenderSession ample(scene(iso_scene()), backend_options("gobbetti"));
  const uint64_t brick = ample.bricks().shape().bytes();
  RenderSession starved(scene(iso_scene(), 64, std::to_string(brick)), backend_options("gobbetti"));
  ASSERT_EQ(starved.bricks().pool_slots(), 1u);
  EXPECT_LT(starved.settle(0, kAll, 20), 20);
  FrameBuffers fb;
  const FrameStats st = starved.render(0, fb, kAll);
  EXPECT_EQ(st.backend_value("leaves"), 1);
  EXPECT_GT(st.backend_value("pool_full_not_refined"), 0);
  EXPECT_NE(st.below_quality.find("gobbetti's cut was held back by the L1 pool"), std::string::npos) << st.below_quality;
  ample.settle(0, kAll);
  const FrameStats fine = ample.render(0, fb, kAll);
  EXPECT_GT(fine.backend_value("leaves"), 1);
  EXPECT_EQ(fine.below_quality, "");
}

TEST_F(Gobbetti, VisibilityFeedbackNeverCullsWhatTheImageShows) {
  for (const std::string& mode : {iso_scene(), dvr_scene()}) {
    const Scene sc = scene(mode + R"(, "quality": {"lod_ratio": 0.5})", 96);
    RenderSession on(sc, backend_options("gobbetti", {{"visibility", 1}}));
    RenderSession off(sc, backend_options("gobbetti", {{"visibility", 0}}));
    on.settle(0, kAll);
    off.settle(0, kAll);
    // Let every tile group be queried, then settle again.
    for (int f = 0; f < 8; ++f) {
      FrameBuffers scratch;
      on.render(0, scratch, kAll);
      on.bricks().wait_idle();
    }
    on.settle(0, kAll);
    FrameBuffers a, b;
    const FrameStats sa = on.render(0, a, kAll);
    const FrameStats sb = off.render(0, b, kAll);
    EXPECT_LE(sa.backend_value("working_set"), sb.backend_value("working_set"));
    const ImageError e = compare_frames(a, b, 1.0);
    EXPECT_LT(e.rmse, 0.01) << e.to_json();
    EXPECT_LT(e.coverage_mismatch_fraction, 0.002) << e.to_json();
  }
}

TEST_F(Gobbetti, AnObjectSmallerThanTheCoarseLevelsVoxelsIsStillSeen) {
  // A sphere of radius 6.4 voxels around the corner of eight finest bricks: averaging moves
  // every coarse level's range off the isovalue, so the nodes above it look empty by their own
  // range. Whether a node can be skipped is a question about everything below it.
  BuildOptions o;
  o.brick_size = 8;
  auto corner = make_field_source(make_field("sphere", {{"radius", 0.1}}), {64, 64, 64}, ValueType::f32);
  build_store(*corner, dir_->file("corner-sphere.store"), o);
  const Scene sc = scene(R"("mode": "iso", "isosurfaces": [{"value": 0.0}], "quality": {"lod_ratio": 0.25})", 96, "64MiB",
                         "corner-sphere.store");
  const FrameBuffers truth = reference_frame(sc);
  FrameBuffers fb;
  RenderSession g(sc, backend_options("gobbetti"));
  g.settle(0, kAll);
  g.render(0, fb, kAll);
  ASSERT_TRUE(all_finite(fb));
  const int sphere_pixels = hit_pixels(truth);
  ASSERT_GT(sphere_pixels, 20);
  EXPECT_LE(compare_frames(fb, truth, 1.0).coverage_mismatch, uint64_t(sphere_pixels / 50)) << sphere_pixels << " sphere pixels";
}

TEST_F(Gobbetti, TheImageDoesNotDependOnTheThreadCount) {
  const Scene sc = scene(dvr_scene());
  RenderSession s(sc, backend_options("gobbetti", {{"visibility", 0}}));
  s.settle(0, kAll);
  FrameBuffers one, two;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    s.render(0, one, kAll);
  }
  s.render(0, two, kAll);
  EXPECT_TRUE(one.color == two.color);
}

}  // namespace
}  // namespace brickyard
