// Damaged stores (issue 42, item 3): one policy over every registered back end. A record that
// cannot be read (corrupt or missing) neither stops a frame nor passes in silence: the back end
// draws its region from the nearest coarser level that can be read, else leaves it empty; the
// frame counts it (FrameStats::unreadable) and the cache lists it with its error
// (PageCache::failed_pages), which `brickyard render` and `flight` print before exiting with
// status 3 unless --allow-damaged (tests/cli/test_cli_render.cpp). Before, gobbetti drew the
// parents of an unreadable brick (and a blank image for an unreadable root) with exit 0, and
// every other back end stopped at it.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "array_scene.h"
#include "core/brick_key.h"
#include "renderers/common/metrics.h"
#include "shared_suite.h"
#include "storage/store.h"
#include "store_damage.h"
#include "test_util.h"
#include "tet_test_util.h"

namespace brickyard {
namespace {

using testing::backends_for;
using testing::build_array;
using testing::damage_record;
using testing::expect_sane;
using testing::look;
using testing::make_scene;
using testing::render_world;
using testing::Rendered;

/// Distance from the centre of a 40^3 grid, in voxels: bricks of 8 make 4 levels (40, 20, 10,
/// 5 voxels a side) and put the centre inside brick (2, 2, 2) of the finest.
constexpr int kN = 40;
std::vector<float> distance_field() {
  std::vector<float> v;
  const double c = 0.5 * (kN - 1);
  for (int z = 0; z < kN; ++z)
    for (int y = 0; y < kN; ++y)
      for (int x = 0; x < kN; ++x) v.push_back(float(std::hypot(x - c, y - c, z - c)));
  return v;
}

// The sphere of radius 13 meets the camera (on -y) in finest brick (2, 0, 2): voxels 16-23 in x
// and z, 0-7 in y, around (19.5, 6.5, 19.5).
const BrickKey kFinest{3, 2, 0, 2}, kParent{2, 1, 0, 1}, kGrandparent{1, 0, 0, 0}, kRoot{0, 0, 0, 0};

class Damaged : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    clean_ = build_array(*dir_, "clean", {kN, kN, kN}, distance_field());
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  /// A copy of the clean store with these bricks damaged.
  static std::string damaged(const std::string& name, const std::vector<BrickKey>& keys) {
    const std::string store = build_array(*dir_, name, {kN, kN, kN}, distance_field());
    for (const BrickKey& k : keys) damage_record(store, "bricks", k.code());
    return store;
  }
  static Scene scene(const std::string& store, const std::string& backend, RenderMode mode) {
    Scene s = make_scene(store, backend, mode, 64);
    s.isosurfaces = {Isosurface{13.0}};
    s.transfer_function = TransferFunction({{10.0, Vec3f(0.2f, 0.3f, 0.9f), 0.0f}, {14.0, Vec3f(0.9f, 0.6f, 0.2f), 0.4f},
                                            {20.0, Vec3f(0.9f, 0.6f, 0.2f), 0.0f}});
    return s;
  }
  static Camera camera() { return look({19.5, -40, 19.5}, {19.5, 19.5, 19.5}, {0, 0, 1}, 40); }

  /// Every back end of `mode` on the clean store and on `store`: the damaged frame is sane,
  /// close to the same back end's clean frame, and counts `unreadable` records among `keys`.
  /// octree_cgt reads the octree volume, not the bricks (OctreeCgt below); raymarch and the
  /// reference only the finest level.
  static void expect_drawn_around(const std::string& store, const std::vector<BrickKey>& keys, RenderMode mode,
                                  double rmse_bound, double changed_bound, bool finest_read = true) {
    for (const std::string& backend : backends_for(mode)) {
      if (backend == "octree_cgt") continue;
      const bool must_read = finest_read || (backend != "raymarch" && backend != "reference");
      const std::string what = backend + " " + std::string(to_string(mode));
      const Rendered clean = render_world(scene(clean_, backend, mode), camera());
      RenderSession session(scene(store, backend, mode));
      FrameSetup setup = session.setup(0, FrameOutputs{.depth = true, .normals = true});
      setup.camera = camera();
      FrameBuffers fb;
      FrameStats stats;
      ASSERT_NO_THROW(stats = testing::render_settled(session, setup, fb)) << what;
      const int covered = expect_sane(fb, what);
      EXPECT_GT(covered, 0) << what;
      const auto failed = session.pages().failed_pages();
      EXPECT_EQ(stats.unreadable, failed.size()) << what;
      for (const PageCache::FailedPage& f : failed) {
        EXPECT_NE(std::find_if(keys.begin(), keys.end(), [&](const BrickKey& k) { return BrickCache::page_key(k) == f.key; }),
                  keys.end())
            << what << ": " << f.error;
        EXPECT_NE(f.error.find("checksum"), std::string::npos) << what << ": " << f.error;
      }
      // Only the damaged region changes, and by no more than a coarser level's stand-in.
      int changed = 0;
      for (int y = 0; y < fb.height(); ++y)
        for (int x = 0; x < fb.width(); ++x) {
          const Rgbaf a = fb.color(x, y), b = clean.fb.color(x, y);
          changed += std::max({std::fabs(a.r - b.r), std::fabs(a.g - b.g), std::fabs(a.b - b.b)}) > 4.0f / 255;
        }
      const ImageError e = compare_frames(fb, clean.fb, 1.0);
      EXPECT_LT(e.rmse, rmse_bound) << what << " " << e.to_json();
      EXPECT_LE(changed, changed_bound * fb.width() * fb.height()) << what;
      if (mode == RenderMode::iso && must_read) {
        EXPECT_NE(failed.size(), 0u) << what << ": the damaged bricks were never asked for";
      }
    }
  }

  static testing::TempDir* dir_;
  static std::string clean_;
};
testing::TempDir* Damaged::dir_ = nullptr;
std::string Damaged::clean_;

TEST_F(Damaged, AnUnreadableBrickIsDrawnFromTheLevelAboveAndCounted) {
  const std::string store = damaged("finest", {kFinest});
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr}) expect_drawn_around(store, {kFinest}, mode, 0.02, 0.05);
}

TEST_F(Damaged, UnreadableLevelsInARowAreDrawnFromTheNearestReadableOne) {
  const std::string store = damaged("chain", {kFinest, kParent});
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr}) expect_drawn_around(store, {kFinest, kParent}, mode, 0.03, 0.1);
}

TEST_F(Damaged, AnUnreadableRootLeavesTheFinerLevelsDrawn) {
  // gobbetti drew nothing over an unreadable root; the back ends that read only the finest
  // level never ask for it.
  const std::string store = damaged("root", {kRoot});
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr}) expect_drawn_around(store, {kRoot}, mode, 0.005, 0.01, false);
}

TEST_F(Damaged, ARegionNoLevelCanReadIsLeftEmptyAndTheFrameStaysSane) {
  const std::vector<BrickKey> chain{kFinest, kParent, kGrandparent, kRoot};
  const std::string store = damaged("all_levels", chain);
  // The whole brick's region may go: a 64^2 frame shows it as about a twentieth of the image.
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr}) expect_drawn_around(store, chain, mode, 0.15, 0.12);
}

TEST_F(Damaged, AnUnreadableOctreePageIsLeftEmptyAndCounted) {
  const std::string store = build_array(*dir_, "octree_page", {kN, kN, kN}, distance_field());
  uint64_t page = 0;
  {
    const Store s(store);
    const OctreeLayout& layout = s.dataset().octree().layout();
    const int root = layout.cap_page_root(), shift = layout.depth - root;  // a node at depth d spans 2^(D - d) voxels
    ASSERT_GT(root, 0);
    page = OctreeLayout::page_id(root, {19 >> shift, 6 >> shift, 19 >> shift});
  }
  damage_record(store, "octree", page);
  const Rendered clean = render_world(scene(clean_, "octree_cgt", RenderMode::iso), camera());
  RenderSession session(scene(store, "octree_cgt", RenderMode::iso));
  FrameSetup setup = session.setup(0, FrameOutputs{.depth = true, .normals = true});
  setup.camera = camera();
  FrameBuffers fb;
  FrameStats stats;
  ASSERT_NO_THROW(stats = testing::render_settled(session, setup, fb));
  EXPECT_GT(expect_sane(fb, "octree_cgt"), 0);
  const auto failed = session.pages().failed_pages();
  ASSERT_EQ(failed.size(), 1u);
  EXPECT_EQ(failed[0].key, (PageKey{RecordKind::octree_page, page}));
  EXPECT_EQ(stats.unreadable, 1u);
  // The page's 16^3 voxels are left out: rays see the sphere's far side through them.
  const ImageError e = compare_frames(fb, clean.fb, 1.0);
  EXPECT_GT(e.rmse, 0.01) << e.to_json();
  EXPECT_LT(e.rmse, 0.15) << e.to_json();
  EXPECT_LT(e.coverage_mismatch_fraction, 0.05) << e.to_json();
}

TEST(DamagedMesh, AnUnreadableClusterIsLeftOutAndCounted) {
  testing::TempDir dir;
  const std::string store = dir.file("mesh");
  testing::build(testing::lattice_mesh(6, 0.0, [](const Vec3d& p) { return p.x + p.y + p.z; }), store, 64);
  const std::string clean = dir.file("clean");
  testing::build(testing::lattice_mesh(6, 0.0, [](const Vec3d& p) { return p.x + p.y + p.z; }), clean, 64);
  uint64_t cluster = 0;  // one the isosurface passes through
  {
    const Store s(store);
    const TetView& tets = s.dataset().tets();
    while (cluster < tets.clusters().size() && !(tets.range(cluster, 0).min < 1.5 && tets.range(cluster, 0).max > 1.5)) ++cluster;
    ASSERT_LT(cluster, tets.clusters().size());
  }
  damage_record(store, "tets", cluster);
  for (const std::string& backend : backends_for(RenderMode::iso, DataKind::tetrahedral)) {
    const Scene s = testing::tet_scene(store, R"("mode": "iso", "isosurfaces": [{"value": 1.5}])", 64, backend);
    RenderSession session(s);
    FrameBuffers fb;
    FrameStats stats;
    ASSERT_NO_THROW(stats = testing::render_settled(session, fb, {.depth = true, .normals = true})) << backend;
    expect_sane(fb, backend);
    const auto failed = session.pages().failed_pages();
    ASSERT_EQ(failed.size(), 1u) << backend;
    EXPECT_EQ(failed[0].key, (PageKey{RecordKind::tet_cluster, cluster})) << backend;
    EXPECT_EQ(stats.unreadable, 1u) << backend;
    RenderSession whole(testing::tet_scene(clean, R"("mode": "iso", "isosurfaces": [{"value": 1.5}])", 64, backend));
    FrameBuffers full;
    testing::render_settled(whole, full, {.depth = true, .normals = true});
    EXPECT_LT(compare_frames(fb, full, 1.0 / 6).coverage_mismatch_fraction, 0.25) << backend;
  }
}

}  // namespace
}  // namespace brickyard
