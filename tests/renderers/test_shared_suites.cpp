// Shared suites over every registered back end (shared_suite.h): each matches the reference at
// full resolution, within the error raymarch makes at the same step, and each renders the
// same bits on one thread and on two.

#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <cstring>

#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/volume_source.h"
#include "render_test_util.h"
#include "shared_suite.h"
#include "test_util.h"

namespace brickyard {
namespace {

using testing::backends_for;

/// Stores the suites share: a sphere's signed distance (iso), fBm (DVR, MIP), in 8^3 bricks.
class SharedSuites : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    BuildOptions o;
    o.brick_size = 8;
    build_store(*make_field_source(make_field("sphere"), {40, 40, 40}, ValueType::f32), dir_->file("sphere.store"), o);
    build_store(*make_field_source(make_field("fbm"), {40, 36, 33}, ValueType::u16), dir_->file("fbm.store"), o);
    // The back ends that read an octree volume (octree_cgt) need one beside the bricks.
    build_octree(dir_->file("sphere.store"), {});
    build_octree(dir_->file("fbm.store"), {});
  }
  static void TearDownTestSuite() { delete dir_; }

  /// A 48x48 scene at full resolution (quality.lod_ratio 0.01 for level-of-detail back ends).
  static Scene scene(const std::string& store, const std::string& backend, const std::string& what, int size = 48) {
    const std::string text = R"({"dataset": ")" + store + R"(", "backend": ")" + backend + R"(", "image": {"width": )" +
                             std::to_string(size) + R"(, "height": )" + std::to_string(size) + R"(},
        "quality": {"lod_ratio": 0.01}, "cache": {"l1": "8MiB", "l2": "8MiB"},
        "camera": {"eye": [1.6, -0.9, 1.3], "target": [0.5, 0.5, 0.45], "fov_degrees": 35}, )" + what + "}";
    return parse_scene(text, dir_->file("scene.json"));
  }
  static testing::TempDir* dir_;
};
testing::TempDir* SharedSuites::dir_ = nullptr;

const std::string kIsoLit = R"("mode": "iso", "isosurfaces": [{"value": 0.0}], "shading": {"light": "headlight"})";
const std::string kDvrLit = R"("mode": "dvr", "values": "normalized", "shading": {"light": "headlight"},
    "transfer_function": {"points": [{"value": 0.3, "color": [0.1, 0.2, 0.9], "opacity": 0},
      {"value": 0.55, "color": [0.9, 0.5, 0.1], "opacity": 0.3}, {"value": 0.8, "color": [1, 1, 0.9], "opacity": 0.9}]})";
const std::string kMip = R"("mode": "mip")";

TEST_F(SharedSuites, EveryBackEndMatchesTheReferenceAtFullResolution) {
  struct Case {
    const char* store;
    const std::string& what;
    RenderMode mode;
    double max_rmse;
  };
  for (const Case& c : {Case{"sphere.store", kIsoLit, RenderMode::iso, 0.02}, Case{"fbm.store", kDvrLit, RenderMode::dvr, 0.02},
                        Case{"fbm.store", kMip, RenderMode::mip, 0.03}}) {
    int compared = 0;
    for (const std::string& backend : backends_for(c.mode)) {
      if (backend == "reference") continue;
      SCOPED_TRACE(backend + " " + std::string(to_string(c.mode)));
      const Scene s = scene(c.store, backend, c.what);
      RenderSession session(s);
      FrameBuffers fb;
      testing::render_settled(session, fb, FrameOutputs{.depth = true, .normals = true});
      ASSERT_TRUE(testing::all_finite(fb));
      // Within the error raymarch makes at the back end's own step (every back end here
      // samples with a step in voxels; the reference's truth is exact or 1/8 voxel).
      const double step = session.params().values().count("step") ? session.params()["step"] : 0.5;
      testing::expect_as_good_as_raymarch(s, fb, step, c.max_rmse);
      ++compared;
    }
    EXPECT_GT(compared, 0) << to_string(c.mode);
  }
}

bool same_bits(const FrameBuffers& a, const FrameBuffers& b) {
  auto eq = [](const auto& x, const auto& y) {
    return x.width() == y.width() && x.height() == y.height() &&
           std::memcmp(x.data(), y.data(), sizeof(*x.data()) * size_t(x.width()) * size_t(x.height())) == 0;
  };
  return eq(a.color, b.color) && eq(a.depth, b.depth) && eq(a.normal, b.normal);
}

TEST_F(SharedSuites, FramesAreBitIdenticalOnOneThreadAndOnTwo) {
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr, RenderMode::mip})
    for (const std::string& backend : backends_for(mode)) {
      SCOPED_TRACE(backend + " " + std::string(to_string(mode)));
      // 96x96: 36 tiles, enough work for a second thread to join.
      const Scene s = scene(mode == RenderMode::iso ? "sphere.store" : "fbm.store", backend,
                            mode == RenderMode::iso ? kIsoLit : mode == RenderMode::dvr ? kDvrLit : kMip, 96);
      FrameBuffers one, two;
      FrameStats one_stats, two_stats;
      // One thread: an arena of one, which no worker can join (a global limit of 1 let a worker
      // still busy from the last arena take tiles, under TSan).
      tbb::task_arena(1).execute([&] {
        RenderSession session(s);
        one_stats = testing::render_settled(session, one, FrameOutputs{.depth = true, .normals = true});
      });
      EXPECT_EQ(one_stats.tile_threads, 1);
      // Two threads: an arena of two, rendered again (on a fresh session) until two threads did
      // render tiles, so that the comparison is not of one thread against itself. On a busy
      // machine the second worker may join a fast frame too late to take a tile: try again.
      tbb::task_arena arena(2);
      for (int attempt = 0; attempt < 100 && two_stats.tile_threads < 2; ++attempt)
        arena.execute([&] {
          RenderSession session(s);
          two_stats = testing::render_settled(session, two, FrameOutputs{.depth = true, .normals = true});
        });
      ASSERT_EQ(two_stats.tile_threads, 2);
      EXPECT_TRUE(same_bits(one, two));
      EXPECT_EQ(one_stats.counters.rays, two_stats.counters.rays);
      EXPECT_EQ(one_stats.counters.samples, two_stats.counters.samples);
      int drawn = 0;  // not vacuous: something was drawn
      for (int i = 0; i < 96 * 96; ++i) drawn += one.color.data()[i].a > 0;
      EXPECT_GT(drawn, 100);
    }
}

}  // namespace
}  // namespace brickyard
