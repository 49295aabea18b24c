// tet_bvh against closed forms and against the tet reference: a linear field's isosurface on
// its plane; packets of every size and single rays alike; SAH and BIH alike; clusters alike;
// no pinholes; the reference's image; independent of the thread count; converging under an L1
// of a tenth of the mesh; degenerate tets kept out of the BVH; depth peeling's composite.

#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <map>
#include <optional>
#include <string>

#include "renderers/common/metrics.h"
#include "dataset/tet_bvh.h"
#include "renderers/tet_test_util.h"
#include "session/render_session.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

using testing::build;
using testing::lattice_mesh;
using testing::pinholes;
using testing::tet_scene;

/// The settled frame of a scene through tet_bvh with these parameters.
FrameBuffers bvh_frame(const Scene& scene, std::map<std::string, double> params = {}, FrameStats* stats = nullptr) {
  RenderSession::Options o;
  o.backend = "tet_bvh";
  o.params = std::move(params);
  RenderSession session(scene, o);
  const FrameOutputs outputs{.depth = true, .normals = true};
  session.settle(0, outputs);
  FrameBuffers fb;
  const FrameStats s = session.render(0, fb, outputs);
  if (stats) *stats = s;
  return fb;
}

int differing_pixels(const FrameBuffers& a, const FrameBuffers& b, float tolerance = 0) {
  int n = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x) {
      const Rgbaf p = a.color(x, y), q = b.color(x, y);
      const float da = a.depth(x, y), db = b.depth(x, y);
      const bool depth_differs = std::isfinite(da) != std::isfinite(db) || (std::isfinite(da) && std::abs(da - db) > tolerance);
      n += depth_differs || std::abs(p.r - q.r) > tolerance || std::abs(p.g - q.g) > tolerance || std::abs(p.b - q.b) > tolerance;
    }
  return n;
}

const char* kSphereIso = R"("mode": "iso", "isosurfaces": [{"value": 0.2, "color": [0.9, 0.6, 0.3]}, {"value": 0.35}],
    "clip": {"lo": [0, 0, 0], "hi": [1, 0.55, 1]},
    "shading": {"light": "point", "light_position": [1.6, -0.8, 2.2], "shadows": true})";

class TetBvh : public ::testing::Test {
 protected:
  void SetUp() override {
    build(lattice_mesh(10, 0.15, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }), dir_.file("sphere.store"), 256);
  }
  Scene sphere(const std::string& body = kSphereIso, int size = 64) {
    return tet_scene(dir_.file("sphere.store"), body, size, "tet_bvh");
  }
  testing::TempDir dir_;
};

TEST_F(TetBvh, ALinearFieldsIsosurfaceLiesOnItsPlane) {
  const Vec3d a(1, 0.5, 0.25);
  build(lattice_mesh(6, 0.2, [&](const Vec3d& p) { return dot(a, p); }), dir_.file("linear.store"), 64);
  const Scene scene = tet_scene(dir_.file("linear.store"), R"("mode": "iso", "isosurfaces": [{"value": 0.9}])", 64, "tet_bvh");
  RenderSession::Options o;
  RenderSession session(scene, o);
  session.settle(0, {.depth = true});
  FrameBuffers fb;
  session.render(0, fb, {.depth = true, .normals = true});
  const ImageRays rays(session.camera(0), fb.width(), fb.height());
  int hits = 0;
  double worst = 0, worst_normal = 0;
  for (int y = 0; y < fb.height(); ++y)
    for (int x = 0; x < fb.width(); ++x) {
      if (!std::isfinite(fb.depth(x, y))) continue;
      ++hits;
      const Rayd r = rays.ray(x + 0.5, y + 0.5);
      const double t_exact = (0.9 - dot(a, r.org)) / dot(a, r.dir);
      worst = std::max(worst, std::abs(double(fb.depth(x, y)) - t_exact));
      worst_normal = std::max(worst_normal, 1 - std::abs(dot(Vec3d(fb.normal(x, y)), normalize(a))));
    }
  EXPECT_GT(hits, 600);
  EXPECT_LT(worst, 1e-5 / 6);  // 1e-5 of the cell size (1/6)
  EXPECT_LT(worst_normal, 1e-6);
}

TEST_F(TetBvh, PacketsOfEverySizeAndSingleRaysGiveIdenticalHits) {
  const FrameBuffers single = bvh_frame(sphere(), {{"packet", 1}});
  for (int packet : {2, 4, 8, 16}) {
    EXPECT_EQ(differing_pixels(single, bvh_frame(sphere(), {{"packet", double(packet)}})), 0) << packet;
  }
  EXPECT_EQ(differing_pixels(single, bvh_frame(sphere(), {{"corner_culling", 0}})), 0);
  // An eye inside the mesh: polygons and boxes beside and behind it project nowhere, and the
  // packets fall back to testing their rays.
  const std::string inside = std::string(R"("mode": "iso", "isosurfaces": [{"value": 0.2}, {"value": 0.35}],
      "camera": {"eye": [0.45, 0.5, 0.55], "target": [0.9, 0.6, 0.4], "up": [0, 0, 1], "fov_degrees": 100})");
  const FrameBuffers near_single = bvh_frame(sphere(inside), {{"packet", 1}});
  const FrameBuffers near_packets = bvh_frame(sphere(inside));
  EXPECT_EQ(differing_pixels(near_single, near_packets), 0);
  int hits = 0;
  for (int y = 0; y < near_packets.height(); ++y)
    for (int x = 0; x < near_packets.width(); ++x) hits += std::isfinite(near_packets.depth(x, y));
  EXPECT_EQ(hits, near_packets.width() * near_packets.height()) << "an eye inside the 0.35 shell sees it everywhere";
}

TEST_F(TetBvh, SahAndSpatialMedianBuildsGiveIdenticalImages) {
  EXPECT_EQ(differing_pixels(bvh_frame(sphere()), bvh_frame(sphere(), {{"sah", 1}})), 0);
  EXPECT_EQ(differing_pixels(bvh_frame(sphere()), bvh_frame(sphere(), {{"leaf_size", 1}})), 0);
}

TEST_F(TetBvh, AMeshSplitIntoClustersRendersAsOneCluster) {
  build(lattice_mesh(10, 0.15, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }), dir_.file("one.store"), 6000);
  ASSERT_EQ(Store(dir_.file("one.store")).clusters().size(), 1u);
  ASSERT_GT(Store(dir_.file("sphere.store")).clusters().size(), 20u);
  const Scene one = tet_scene(dir_.file("one.store"), kSphereIso, 64, "tet_bvh");
  EXPECT_EQ(differing_pixels(bvh_frame(one), bvh_frame(sphere())), 0);
}

TEST_F(TetBvh, MatchesTheTetReference) {
  // The same crossings by other arithmetic (the isopolygon's plane against the tet's linear
  // field along the ray): depths within 1e-6, colours within float rounding of the shading.
  for (const char* body : {kSphereIso, R"("mode": "iso", "isosurfaces": [{"value": 0.3}], "shading": {"light": "headlight"})",
                           R"("mode": "iso", "isosurfaces": [{"value": 0.3}], "shading": {"light": "directional",
                              "light_direction": [0.3, 1, -0.6], "shadows": true}, "clip": {"lo": [0.1, 0, 0], "hi": [1, 0.6, 1]})"}) {
    Scene s = sphere(body, 96);
    const FrameBuffers bvh = bvh_frame(s);
    s.backend = "reference";
    RenderSession ref(s);
    FrameBuffers truth;
    ref.render(0, truth, {.depth = true, .normals = true});
    EXPECT_LE(differing_pixels(bvh, truth, 1e-5f), 2) << body;  // a ray grazing a silhouette may go either way
    const ImageError e = compare_frames(bvh, truth, 0.1);
    EXPECT_LT(e.rmse, 1e-3) << body;
  }
}

TEST_F(TetBvh, RaysThroughSharedVerticesEdgesAndFacesLeaveNoPinholes) {
  build(lattice_mesh(8, 0.0, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }), dir_.file("grid.store"), 96);
  for (const char* camera : {R"({"eye": [0.5, 0.5, -2], "target": [0.5, 0.5, 0.5], "up": [0, 1, 0], "fov_degrees": 30})",
                             R"({"eye": [-2, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30})",
                             R"({"eye": [2.5, 2.5, 2.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 25})"}) {
    for (double packet : {1.0, 16.0}) {
      const FrameBuffers fb = bvh_frame(tet_scene(dir_.file("grid.store"),
                                                  std::string(R"("mode": "iso", "isosurfaces": [{"value": 0.3}], "camera": )") + camera,
                                                  129, "tet_bvh"),
                                        {{"packet", packet}});
      EXPECT_EQ(pinholes(fb), 0) << camera << " packet " << packet;
      for (int i = 40; i <= 88; ++i) {
        EXPECT_TRUE(std::isfinite(fb.depth(i, 64))) << camera << " row pixel " << i;
        EXPECT_TRUE(std::isfinite(fb.depth(64, i))) << camera << " column pixel " << i;
      }
    }
  }
}

TEST_F(TetBvh, TheImageDoesNotDependOnTheThreadCount) {
  FrameBuffers one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = bvh_frame(sphere());
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = bvh_frame(sphere());
  }
  EXPECT_EQ(differing_pixels(one, two), 0);
}

TEST_F(TetBvh, AnL1OfATenthOfTheMeshConvergesToTheFullImage) {
  // Exact frames (exact = 1, or the frames a still image settles through) wait in passes for
  // the clusters they miss, as many as L1 keeps, and resume each ray where it met one; a pass
  // without progress has one tile wait for each cluster where it needs it.
  build(lattice_mesh(10, 0.15, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }), dir_.file("small.store"), 64);
  const Store store(dir_.file("small.store"));
  const uint64_t page = store.manifest().mesh.page_bytes, clusters = store.clusters().size();
  const FrameBuffers full = bvh_frame(sphere());
  {
    Scene s = tet_scene(dir_.file("small.store"), kSphereIso, 64, "tet_bvh");
    s.cache.l1_bytes = page * std::max<uint64_t>(2, clusters / 10);
    s.cache.l2_bytes = page * std::max<uint64_t>(2, clusters / 10);
    RenderSession::Options o;
    o.backend = "tet_bvh";
    o.params = {{"exact", 1}};
    RenderSession session(s, o);
    FrameBuffers fb;
    const FrameStats st = session.render(0, fb, {.depth = true, .normals = true});
    EXPECT_TRUE(session.converged()) << "passes " << st.backend_value("passes") << ", unfinished "
                                     << st.backend_value("unfinished_rays");
    EXPECT_EQ(differing_pixels(fb, full), 0);
    EXPECT_GT(st.backend_value("passes"), 1) << "a cold exact frame waits for its clusters in passes";
    EXPECT_LE(session.pages().stats(RecordKind::tet_cluster).l1.resident, s.cache.l1_bytes / page);
  }
}

TEST_F(TetBvh, OnlyClustersInViewHoldingAnIsovalueAreRead) {
  build(lattice_mesh(8, 0.0, [](const Vec3d& p) { return p.x; }), dir_.file("ramp.store"), 64);
  const Store store(dir_.file("ramp.store"));
  uint64_t holding = 0;
  for (const TetCluster& c : store.clusters()) holding += c.min <= 0.05f && c.max >= 0.05f;
  FrameStats st;
  const Scene s = tet_scene(dir_.file("ramp.store"), R"("mode": "iso", "isosurfaces": [{"value": 0.05}])", 64, "tet_bvh");
  RenderSession::Options o;
  o.backend = "tet_bvh";
  RenderSession session(s, o);
  session.settle(0, {.depth = true});
  EXPECT_GT(session.pages().stats(RecordKind::tet_cluster).l3.hits, 0u);
  EXPECT_LE(session.pages().stats(RecordKind::tet_cluster).l3.hits, holding);
}

TEST_F(TetBvh, DepthPeelingCompositesTheLayersFrontToBack) {
  // f = x, isosurfaces at 0.3 (white) and 0.7 (red), unlit, seen head on: two layers of
  // opacity 0.5 give 0.5 white + 0.25 red over a quarter of the background (black).
  build(lattice_mesh(4, 0.1, [](const Vec3d& p) { return p.x; }), dir_.file("planes.store"), 64);
  const Scene s = tet_scene(dir_.file("planes.store"),
                            R"("mode": "iso", "isosurfaces": [{"value": 0.3, "color": [1, 1, 1]}, {"value": 0.7, "color": [1, 0, 0]}],
                               "shading": {"light": "none"},
                               "camera": {"eye": [-1, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 10})",
                            17, "tet_bvh");
  const Rgbaf c = bvh_frame(s, {{"layers", 2}, {"layer_opacity", 0.5}}).color(8, 8);
  EXPECT_NEAR(c.r, 0.75f, 1e-6f);
  EXPECT_NEAR(c.g, 0.5f, 1e-6f);
  EXPECT_NEAR(c.a, 0.75f, 1e-6f);
  const Rgbaf opaque = bvh_frame(s).color(8, 8);
  EXPECT_NEAR(opaque.g, 1.0f, 1e-6f);
}

TEST(TetBvhBuild, DegenerateTetsNeverReachTheBvh) {
  // A page with a valid tet, a flat one, an inverted one and one with a NaN coordinate.
  const std::vector<float> positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 2, 0, 0, 0, 0, std::nanf("")};
  const std::vector<float> values = {0, 1, 2, 3, 4, 5};
  const std::vector<uint32_t> corners = {0, 1, 2, 3, 0, 1, 4, 3, 0, 2, 1, 3, 0, 1, 2, 5};
  // The page layout itself refuses nothing: what reaches the back end from a store is valid,
  // and the BVH keeps out whatever is not.
  std::vector<std::byte> page = TetClusterPage::encode(positions, values, corners);
  const TetClusterPage view = TetClusterPage::view(page);
  for (auto method : {tet_bvh::BuildMethod::bih, tet_bvh::BuildMethod::sah}) {
    const tet_bvh::ClusterBvh bvh = tet_bvh::ClusterBvh::build(view, 0, method, 12);
    EXPECT_EQ(bvh.skipped, 3u);
    ASSERT_EQ(bvh.bvh.order.size(), 1u);
    EXPECT_EQ(bvh.bvh.order[0], 0u);
  }
}

TEST(TetBvhBuild, LeavesHoldAtMostTheirSizeAndNodesBoundTheirTets) {
  testing::TempDir dir;
  build(lattice_mesh(6, 0.2, [](const Vec3d& p) { return p.x * p.y + p.z; }), dir.file("m.store"), 2000);
  const Store store(dir.file("m.store"));
  std::vector<std::byte> page(store.manifest().mesh.page_bytes);
  auto txn = store.begin_read();
  store.read_page(txn, {RecordKind::tet_cluster, 0}, page);
  const TetClusterPage view = TetClusterPage::view(page);
  for (auto method : {tet_bvh::BuildMethod::bih, tet_bvh::BuildMethod::sah}) {
    const tet_bvh::ClusterBvh bvh = tet_bvh::ClusterBvh::build(view, 0, method, 12);
    EXPECT_EQ(bvh.bvh.order.size(), view.tet_count);
    std::vector<int> seen(view.tet_count, 0);
    for (size_t n = 0; n < bvh.bvh.nodes.size(); ++n) {
      const tet_bvh::BvhNode& node = bvh.bvh.nodes[n];
      if (!node.leaf()) continue;
      EXPECT_LE(node.count, 12);
      for (uint32_t s = node.index; s < node.index + node.count; ++s) {
        const uint32_t t = bvh.bvh.order[s];
        ++seen[t];
        for (int k = 0; k < 4; ++k) {
          const uint32_t v = view.corners[4 * t + uint32_t(k)];
          for (int a = 0; a < 3; ++a) {
            EXPECT_GE(view.positions[3 * v + uint32_t(a)], node.lo[a]);
            EXPECT_LE(view.positions[3 * v + uint32_t(a)], node.hi[a]);
          }
          EXPECT_GE(view.values[v], node.lo[3]);
          EXPECT_LE(view.values[v], node.hi[3]);
        }
      }
    }
    for (int s : seen) EXPECT_EQ(s, 1);
  }
}

}  // namespace
}  // namespace brickyard

namespace brickyard {
namespace {

/// A sphere's distance on a lattice whose vertices move (a shear growing with the step, so
/// every tet keeps its orientation) while the field moves along x.
TetMesh moving_sphere(int steps) {
  TetMesh m = lattice_mesh(10, 0.15, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }, steps);
  const double two_pi = 2 * 3.14159265358979323846;
  for (int s = 1; s < steps; ++s) {
    std::vector<float> moved = m.positions;
    for (size_t v = 0; v < m.vertex_count(); ++v) {
      const double y = m.positions[3 * v + 1], z = m.positions[3 * v + 2];
      moved[3 * v] = float(m.positions[3 * v] + 0.04 * s * std::sin(two_pi * y));
      moved[3 * v + 1] = float(y + 0.03 * s * std::sin(two_pi * z));
    }
    m.step_positions.push_back(std::move(moved));
  }
  return m;
}

/// Frames 0 .. count-1 of a time series, each one exact frame (no settling: the frame's own
/// statistics show what it built and refitted).
std::vector<FrameBuffers> series_frames(const Scene& scene, std::map<std::string, double> params,
                                        std::vector<FrameStats>* stats = nullptr) {
  RenderSession::Options o;
  o.backend = "tet_bvh";
  o.params = std::move(params);
  o.params["exact"] = 1;
  RenderSession session(scene, o);
  std::vector<FrameBuffers> out(size_t(scene.frames()));
  for (int f = 0; f < scene.frames(); ++f) {
    const FrameStats s = session.render(f, out[size_t(f)], {.depth = true, .normals = true});
    if (stats) stats->push_back(s);
  }
  return out;
}

}  // namespace

TEST_F(TetBvh, RefitEqualsRebuildForMovingVertices) {
  build(moving_sphere(3), dir_.file("moving.store"), 256);
  ASSERT_TRUE(Store(dir_.file("moving.store")).manifest().mesh.moving);
  const std::string body = std::string(kSphereIso) + R"(, "time_series": {"first": 0, "count": 3})";
  const Scene series = tet_scene(dir_.file("moving.store"), body, 64, "tet_bvh");
  ASSERT_EQ(series.frames(), 3);
  std::vector<FrameStats> refit_stats, per_step_stats;
  const std::vector<FrameBuffers> refitted = series_frames(series, {}, &refit_stats);
  const std::vector<FrameBuffers> per_step = series_frames(series, {{"bvh_per_step", 1}}, &per_step_stats);
  for (int f = 1; f < 3; ++f) {
    EXPECT_GT(refit_stats[size_t(f)].backend_value("bvh_refits"), 0) << f;
    EXPECT_EQ(per_step_stats[size_t(f)].backend_value("bvh_refits"), 0) << f;
    EXPECT_GT(per_step_stats[size_t(f)].backend_value("bvh_builds"), 0) << f;
    EXPECT_EQ(refit_stats[size_t(f)].backend_value("time_step"), f);
  }
  for (int f = 0; f < 3; ++f) {
    // The same step drawn by a fresh renderer (BVHs built for that step alone), and by the
    // reference.
    Scene still = tet_scene(dir_.file("moving.store"), std::string(kSphereIso) + R"(, "time_step": )" + std::to_string(f),
                            64, "tet_bvh");
    const FrameBuffers fresh = bvh_frame(still);
    EXPECT_EQ(differing_pixels(refitted[size_t(f)], fresh), 0) << "step " << f;
    EXPECT_EQ(differing_pixels(per_step[size_t(f)], fresh), 0) << "step " << f;
    still.backend = "reference";
    RenderSession ref(still);
    FrameBuffers truth;
    ref.render(0, truth, {.depth = true, .normals = true});
    EXPECT_LE(differing_pixels(fresh, truth, 1e-5f), 2) << "step " << f;
  }
  // The steps differ: the test would catch a refit that left step 0's bounds.
  EXPECT_GT(differing_pixels(refitted[0], refitted[2]), 200);
}

TEST_F(TetBvh, TheBvhCacheKeepsTheBvhsOfWhatL1Holds) {
  // 162k tets: some 3 MiB of BVHs. Under a 1 MiB BVH cache every frame rebuilds what it
  // dropped; by default (1.5 x L1) a warm frame builds nothing.
  build(lattice_mesh(30, 0.1, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }), dir_.file("big.store"), 4096);
  const Scene s = tet_scene(dir_.file("big.store"), R"("mode": "iso", "isosurfaces": [{"value": 0.3}])", 64, "tet_bvh");
  auto warm_builds = [&](std::map<std::string, double> params) {
    RenderSession::Options o;
    o.backend = "tet_bvh";
    o.params = std::move(params);
    o.params["exact"] = 1;
    RenderSession session(s, o);
    FrameBuffers fb;
    session.render(0, fb);
    const FrameStats warm = session.render(0, fb);
    return std::pair{warm.backend_value("bvh_builds"), warm.backend_value("bvh_bytes")};
  };
  const auto [default_builds, default_bytes] = warm_builds({});
  EXPECT_EQ(default_builds, 0);
  EXPECT_GT(default_bytes, double(1 << 20));
  const auto [small_builds, small_bytes] = warm_builds({{"bvh_cache", 1}});
  EXPECT_GT(small_builds, 0);
  EXPECT_LE(small_bytes, double(1 << 20) + 200e3);  // the budget, and at most the one BVH just built
}

TEST_F(TetBvh, AStoredBvhIsReadInsteadOfBuiltAndRendersTheSame) {
  build(lattice_mesh(10, 0.15, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }), dir_.file("stored.store"), 256, true);
  const Scene stored = tet_scene(dir_.file("stored.store"), kSphereIso, 64, "tet_bvh");
  const FrameBuffers built = bvh_frame(sphere());
  FrameStats st;
  EXPECT_EQ(differing_pixels(bvh_frame(stored, {{"exact", 1}}, &st), built), 0);
  // bvh_frame settles first: the frame it returns found every BVH cached; a cold one loads.
  RenderSession::Options o;
  o.backend = "tet_bvh";
  o.params = {{"exact", 1}};
  RenderSession cold(stored, o);
  FrameBuffers fb;
  st = cold.render(0, fb, {.depth = true, .normals = true});
  EXPECT_GT(st.backend_value("bvh_loads"), 0);
  EXPECT_EQ(st.backend_value("bvh_builds"), 0);
  EXPECT_EQ(differing_pixels(fb, built), 0);
  // Built otherwise than stored (SAH, other leaves), or not wanted: built, the same image.
  for (const std::map<std::string, double>& params :
       {std::map<std::string, double>{{"sah", 1}}, {{"leaf_size", 4}}, {{"stored_bvh", 0}}}) {
    o.params = params;
    o.params["exact"] = 1;
    RenderSession session(stored, o);
    st = session.render(0, fb, {.depth = true, .normals = true});
    EXPECT_EQ(st.backend_value("bvh_loads"), 0);
    EXPECT_GT(st.backend_value("bvh_builds"), 0);
    EXPECT_EQ(differing_pixels(fb, built), 0);
  }
}

TEST_F(TetBvh, AStoredBvhRefittedToOtherStepsEqualsARebuild) {
  build(moving_sphere(3), dir_.file("moving.store"), 256, true);
  const std::string body = std::string(kSphereIso) + R"(, "time_series": {"first": 0, "count": 3})";
  std::vector<FrameStats> stats;
  const std::vector<FrameBuffers> frames = series_frames(tet_scene(dir_.file("moving.store"), body, 64, "tet_bvh"), {}, &stats);
  EXPECT_GT(stats[0].backend_value("bvh_loads"), 0);
  for (int f = 0; f < 3; ++f) {
    const Scene still = tet_scene(dir_.file("moving.store"), std::string(kSphereIso) + R"(, "time_step": )" + std::to_string(f),
                                  64, "tet_bvh");
    EXPECT_EQ(differing_pixels(frames[size_t(f)], bvh_frame(still, {{"stored_bvh", 0}})), 0) << "step " << f;
  }
}

TEST(TetBvhTree, AStoredBvhThatDoesNotFitItsPageIsCorrupt) {
  TetMesh m = lattice_mesh(4, 0.1, [](const Vec3d& p) { return p.x; });
  std::vector<std::byte> page = TetClusterPage::encode(m.positions, m.scalars[0], m.tets);
  const size_t plain = page.size();
  using tet_bvh::BuildMethod;
  using tet_bvh::ClusterBvh;
  const ClusterBvh bvh = ClusterBvh::build(TetClusterPage::view(page), 0, BuildMethod::bih, 12);
  const std::vector<std::byte> tail = bvh.encode(plain, BuildMethod::bih, 12);
  page.insert(page.end(), tail.begin(), tail.end());
  const std::optional<ClusterBvh> read = ClusterBvh::stored(TetClusterPage::view(page), BuildMethod::bih, 12);
  ASSERT_TRUE(read);
  EXPECT_EQ(read->bvh.order, bvh.bvh.order);
  EXPECT_EQ(read->tet_range, bvh.tet_range);
  EXPECT_FALSE(ClusterBvh::stored(TetClusterPage::view(page), BuildMethod::sah, 12));  // built otherwise
  EXPECT_FALSE(ClusterBvh::stored(TetClusterPage::view(std::span(page).first(plain)), BuildMethod::bih, 12));  // none
  const size_t header = plain + (8 - plain % 8) % 8;
  auto corrupt = [&](size_t offset, uint32_t value) {
    std::vector<std::byte> bad = page;
    std::memcpy(bad.data() + offset, &value, sizeof value);
    try {
      ClusterBvh::stored(TetClusterPage::view(bad), BuildMethod::bih, 12);
      ADD_FAILURE() << "accepted a stored BVH with " << value << " at " << offset;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::corrupt) << e.what();
    }
  };
  corrupt(header + 12, 1u << 30);                                       // more nodes than the page holds
  corrupt(header + 16, uint32_t(m.tets.size() / 4) + 5);                // more tets than the cluster has
  corrupt(header + 24 + offsetof(tet_bvh::BvhNode, index), 1u << 20);  // the root's right child outside the tree
  const size_t order = header + 24 + bvh.bvh.nodes.size() * sizeof(tet_bvh::BvhNode);
  corrupt(order, 1u << 20);  // a slot naming a tet the cluster does not have
  ASSERT_FALSE(bvh.bvh.nodes[1].leaf());
  corrupt(header + 24 + offsetof(tet_bvh::BvhNode, index), 3);  // the root's right child shared with node 1's subtree
  float shrunk = bvh.bvh.nodes[0].lo[0] + 0.25f;
  uint32_t bits;
  std::memcpy(&bits, &shrunk, sizeof bits);
  corrupt(header + 24, bits);  // the root's box no longer holds its tets
  corrupt(order + sizeof(uint32_t), bvh.bvh.order[0]);  // one tet in two slots
}

TEST(TetBvhTree, ARefitKeepsTheTopologyAndBoundsEveryNodesItems) {
  testing::TempDir dir;
  build(moving_sphere(3), dir.file("moving.store"), 6000);
  const Store store(dir.file("moving.store"));
  ASSERT_EQ(store.clusters().size(), 1u);
  std::vector<std::byte> bytes(store.manifest().mesh.page_bytes);
  auto txn = store.begin_read();
  store.read_page(txn, {RecordKind::tet_cluster, 0}, bytes);
  const TetClusterPage page = TetClusterPage::view(bytes);
  using tet_bvh::BuildMethod;
  using tet_bvh::ClusterBvh;
  const ClusterBvh at0 = ClusterBvh::build(page, 0, BuildMethod::bih, 12);
  // Refitted to its own step, a BVH is unchanged to the bit.
  const std::optional<ClusterBvh> same = at0.refit(page, 0);
  ASSERT_TRUE(same);
  ASSERT_EQ(same->bvh.nodes.size(), at0.bvh.nodes.size());
  EXPECT_EQ(std::memcmp(same->bvh.nodes.data(), at0.bvh.nodes.data(), at0.bvh.nodes.size() * sizeof(tet_bvh::BvhNode)), 0);
  EXPECT_EQ(same->tet_range, at0.tet_range);
  // Refitted to step 2: the same order, and every node the exact union of its items at step 2.
  const std::optional<ClusterBvh> at2 = at0.refit(page, 2);
  ASSERT_TRUE(at2);
  EXPECT_EQ(at2->bvh.order, at0.bvh.order);
  EXPECT_EQ(at2->step, 2u);
  const ClusterBvh rebuilt = ClusterBvh::build(page, 2, BuildMethod::bih, 12);
  for (int a = 0; a < 4; ++a) {  // the roots bound the same tets
    EXPECT_EQ(at2->bvh.nodes[0].lo[a], rebuilt.bvh.nodes[0].lo[a]) << a;
    EXPECT_EQ(at2->bvh.nodes[0].hi[a], rebuilt.bvh.nodes[0].hi[a]) << a;
  }
  const float* pos = page.positions_at(2);
  const float* val = page.values_at(2);
  int moved = 0;
  for (size_t i = 0; i < at2->bvh.nodes.size(); ++i) {
    const tet_bvh::BvhNode& n = at2->bvh.nodes[i];
    const tet_bvh::BvhNode& old = at0.bvh.nodes[i];
    moved += std::memcmp(n.lo, old.lo, sizeof n.lo) != 0;
    if (!n.leaf()) continue;
    float lo[4] = {INFINITY, INFINITY, INFINITY, INFINITY}, hi[4] = {-INFINITY, -INFINITY, -INFINITY, -INFINITY};
    for (uint32_t s = n.index; s < n.index + n.count; ++s)
      for (int k = 0; k < 4; ++k) {
        const uint32_t v = page.corners[4 * size_t(at2->bvh.order[s]) + size_t(k)];
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], pos[3 * v + a]), hi[a] = std::max(hi[a], pos[3 * v + a]);
        lo[3] = std::min(lo[3], val[v]), hi[3] = std::max(hi[3], val[v]);
      }
    for (int a = 0; a < 4; ++a) {
      ASSERT_EQ(n.lo[a], lo[a]) << "leaf " << i;
      ASSERT_EQ(n.hi[a], hi[a]) << "leaf " << i;
    }
  }
  EXPECT_GT(moved, int(at2->bvh.nodes.size()) / 2);
}

}  // namespace brickyard
