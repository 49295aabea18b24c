// The memory soak, quick (issue 42, item 5): every back end flies a random camera, a jump every
// frame with thrash, over a 128^3 grid (or a small tetrahedral mesh) with L1 and L2 budgets a
// fraction of the data, and every frame the cache's resident bytes stay within the budget plus
// the fixed overhead stated before the first frame (bench/soak.h says what both count). The
// full soak, thousands of frames over 1024^3, is bench/soak.sh.

#include <gtest/gtest.h>

#include "bench/soak.h"
#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/tet_builder.h"
#include "preprocess/volume_source.h"
#include "shared_suite.h"
#include "test_util.h"

namespace brickyard {
namespace {

#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
constexpr int kFrames = 120;  // instrumented builds run 5-15x slower (60 left gigavoxels short of thrashing)
#else
constexpr int kFrames = 250;
#endif

/// A gyroid (isosurfaces everywhere) of 128^3 u8 in 16^3 bricks, with an octree volume, and a
/// gyroid mesh of 24^3 cubes in clusters of 512 tets (162 clusters).
class Soak : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    BuildOptions o;
    o.brick_size = 16;
    build_store(*make_field_source(make_field("gyroid", {{"periods", 3}}), {128, 128, 128}, ValueType::u8), grid(), o);
    build_octree(grid(), {});
    ProceduralMeshSpec mesh;
    mesh.field = "gyroid";
    mesh.cells = 24;
    mesh.jitter = 0.1;
    TetBuildOptions t;
    t.cluster_tets = 512;
    build_tet_store(*make_procedural_mesh(mesh, t.cluster_tets), Soak::mesh(), t);
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string grid() { return dir_->file("gyroid.store"); }
  static std::string mesh() { return dir_->file("mesh.store"); }

  /// L1 of 256 KiB and L2 of 512 KiB (45 and 90 of the grid's 585 bricks), 32x32 frames.
  static void expect_within_budget(const std::string& dataset, const std::string& backend) {
    SCOPED_TRACE(backend + " over " + dataset);
    soak::SoakOptions o;
    o.dataset = dataset;
    o.backend = backend;
    o.frames = kFrames;
    o.size = 32;
    o.l1_bytes = 256 << 10;
    o.l2_bytes = 512 << 10;
    o.warmup = 20;
    int reported = 0;
    const soak::SoakResult r = soak::run_soak(o, [&](const soak::SoakSample& s, const soak::SoakResult& so_far) {
      if (s.resident > so_far.bound() && reported++ < 3)
        ADD_FAILURE() << "frame " << s.frame << ": resident " << s.resident << " bytes above the budget " << so_far.budget()
                      << " + overhead " << so_far.overhead.total() << " (" << so_far.overhead.describe() << "): L1 " << s.l1_bytes
                      << ", L2 " << s.l2_bytes << ", waiting " << s.waiting_bytes << ", own " << s.backend_bytes << ", metadata "
                      << s.metadata_bytes;
      EXPECT_LE(s.l2_bytes, so_far.l2_budget) << "frame " << s.frame;
    });
    EXPECT_EQ(r.frames, kFrames);
    EXPECT_EQ(r.frames_over, 0);
    EXPECT_LE(r.l2_peak, r.l2_budget);
    // The thrash was real: more was read than the two levels hold.
    EXPECT_GT(r.l3_bytes_decoded, r.l1_budget + r.l2_budget) << "the flight never thrashed";
  }
  static testing::TempDir* dir_;
};
testing::TempDir* Soak::dir_ = nullptr;

TEST_F(Soak, EveryGridBackEndStaysWithinItsBudgetsThroughRandomJumps) {
  const std::vector<std::string> names = testing::backends_for(RenderMode::iso, DataKind::structured);
  EXPECT_GE(names.size(), 5u);
  for (const std::string& b : names) expect_within_budget(grid(), b);
}

TEST_F(Soak, EveryMeshBackEndStaysWithinItsBudgetsThroughRandomJumps) {
  const std::vector<std::string> names = testing::backends_for(RenderMode::iso, DataKind::tetrahedral);
  EXPECT_GE(names.size(), 2u);
  for (const std::string& b : names) expect_within_budget(mesh(), b);
}

}  // namespace
}  // namespace brickyard
