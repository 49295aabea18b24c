// octree_cgt: the octree volume's isosurfaces against the reference (both solve each cell's
// trilinear cubic), the pages it reads (only those whose range holds an isovalue), a cache far
// smaller than the octree, and the refusal of a grid without an octree.

#include <gtest/gtest.h>

#include <cmath>
#include <array>
#include <cstring>
#include <map>
#include <set>

#include "cache/trace.h"
#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/volume_source.h"
#include "render_test_util.h"
#include "shared_suite.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

class OctreeCgt : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    BuildOptions o;
    o.brick_size = 8;
    auto make = [&](const char* name, const char* field, const Vec3s& dims, ValueType t, bool octree = true) {
      build_store(*make_field_source(make_field(field), dims, t), dir_->file(name), o);
      if (octree) build_octree(dir_->file(name), {});
    };
    make("ml.store", "marschner-lobb", {41, 38, 35}, ValueType::f32);
    make("fbm.store", "fbm", {34, 30, 37}, ValueType::u16);
    make("sphere.store", "sphere", {96, 96, 96}, ValueType::f32);
    make("gyroid.store", "gyroid", {64, 64, 64}, ValueType::f32);
    // One brick: the reference's difference normals are confined to a brick, octree_cgt's to
    // the volume.
    o.brick_size = 64;
    make("ml-one-brick.store", "marschner-lobb", {41, 38, 35}, ValueType::f32);
    make("grid-only.store", "sphere", {20, 20, 20}, ValueType::f32, false);
  }
  static void TearDownTestSuite() { delete dir_; }

  static Scene scene(const std::string& store, const std::string& what, int size = 64, const std::string& cache = "",
                     int height = -1) {
    const std::string text = R"({"dataset": ")" + dir_->file(store) + R"(", "backend": "octree_cgt", "image": {"width": )" +
                             std::to_string(size) + R"(, "height": )" + std::to_string(height < 0 ? size : height) + R"(},)" + cache + R"(
        "camera": {"eye": [1.7, -1.0, 1.4], "target": [0.5, 0.5, 0.45], "fov_degrees": 40}, )" + what + "}";
    return parse_scene(text, dir_->file("scene.json"));
  }
  static testing::TempDir* dir_;
};
testing::TempDir* OctreeCgt::dir_ = nullptr;

/// A frame of octree_cgt with these parameters (the defaults otherwise), depth and normals too.
FrameBuffers render(const Scene& s, std::map<std::string, double> params = {}, FrameStats* stats = nullptr) {
  RenderSession session(s, testing::backend_options("octree_cgt", std::move(params)));
  FrameBuffers fb;
  const FrameStats st = session.render(0, fb, {.depth = true, .normals = true});
  if (stats) *stats = st;
  return fb;
}

TEST_F(OctreeCgt, HitsWhereTheReferenceDoesToATenThousandthOfAVoxel) {
  struct Case {
    const char* store;
    std::string what;
  };
  for (const Case& c : {Case{"ml.store", R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "shading": {"light": "headlight"})"},
                        Case{"fbm.store", R"("mode": "iso", "values": "normalized", "isosurfaces": [{"value": 0.45, "color": [1, 0, 0]},
                             {"value": 0.6, "color": [0, 1, 0]}], "shading": {"light": "headlight"})"},
                        Case{"sphere.store", R"("mode": "iso", "isosurfaces": [{"value": 0.0}], "shading": {"light": "none"})"}}) {
    SCOPED_TRACE(c.store);
    const Scene s = scene(c.store, c.what);
    const FrameBuffers fb = render(s);
    const FrameBuffers truth = testing::reference_frame(s);
    int hits = 0, mismatched = 0;
    double worst = 0, worst_normal = 0;
    for (int y = 0; y < fb.height(); ++y)
      for (int x = 0; x < fb.width(); ++x) {
        const bool a = std::isfinite(fb.depth(x, y)), b = std::isfinite(truth.depth(x, y));
        if (a != b) {
          ++mismatched;
          continue;
        }
        if (!a) continue;
        ++hits;
        worst = std::max(worst, std::abs(double(fb.depth(x, y)) - double(truth.depth(x, y))));
        worst_normal = std::max(worst_normal, double(length(fb.normal(x, y) - truth.normal(x, y))));
      }
    EXPECT_GT(hits, 300);
    EXPECT_EQ(mismatched, 0);
    const double voxel = RenderSession(s).context().geometry().voxel_size;
    EXPECT_LT(worst / voxel, 1e-4) << "voxels";
    EXPECT_LT(worst_normal, 1e-3);
  }
}

TEST_F(OctreeCgt, DifferenceNormalsAreTheReferencesAndCostOnlyWhenAsked) {
  const std::string iso = R"("mode": "iso", "isosurfaces": [{"value": 0.5}], )";
  FrameStats analytic_stats;
  const FrameBuffers analytic = render(scene("ml-one-brick.store", iso + R"("shading": {"light": "headlight"})"), {}, &analytic_stats);
  for (const char* method : {"central", "forward"}) {
    SCOPED_TRACE(method);
    const Scene s = scene("ml-one-brick.store", iso + R"("shading": {"light": "headlight", "normals": ")" + method + R"("})");
    FrameStats stats;
    const FrameBuffers fb = render(s, {}, &stats);
    const FrameBuffers truth = testing::reference_frame(s);
    double worst = 0, from_analytic = 0;
    int hits = 0;
    for (int y = 0; y < fb.height(); ++y)
      for (int x = 0; x < fb.width(); ++x) {
        if (!std::isfinite(fb.depth(x, y)) || !std::isfinite(truth.depth(x, y))) continue;
        ++hits;
        worst = std::max(worst, double(length(fb.normal(x, y) - truth.normal(x, y))));
        from_analytic = std::max(from_analytic, double(length(fb.normal(x, y) - analytic.normal(x, y))));
      }
    EXPECT_GT(hits, 300);
    EXPECT_LT(worst, 1e-3) << "the reference's differences of the same interpolant";
    EXPECT_GT(from_analytic, 1e-2) << "and not the analytic gradient";
    // The voxels beyond a cell's corners are looked up only for these normals.
    EXPECT_GT(stats.counters.samples, analytic_stats.counters.samples);
  }
}

TEST_F(OctreeCgt, PacketsOfEverySizeAndPackletWidthHitWhereSingleRaysDoPartialPacketsIncluded) {
  // 50x37: the image's last packets in x and y are partial at every packet size; packlets of
  // 4 and 16 lanes and the build's width (0) split them differently and must not matter.
  const std::string what = R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "shading": {"light": "headlight"})";
  struct Case {
    const char* store;
    std::string what;
  };
  for (const Case& c : {Case{"ml.store", what}, Case{"fbm.store", R"("mode": "iso", "values": "normalized",
                          "isosurfaces": [{"value": 0.45}, {"value": 0.6}])"}}) {
    SCOPED_TRACE(c.store);
    const auto frame = [&](int packet, int packlet = 0) {
      return render(scene(c.store, c.what, 50, "", 37), {{"packet", double(packet)}, {"packlet", double(packlet)}});
    };
    const FrameBuffers single = frame(1);
    int hits = 0;
    for (int y = 0; y < single.height(); ++y)
      for (int x = 0; x < single.width(); ++x) hits += std::isfinite(single.depth(x, y));
    EXPECT_GT(hits, 300);
    for (int packet : {2, 4, 8, 16})
      for (int packlet : {0, 4, 16}) {
        SCOPED_TRACE(::testing::Message() << packet << "x" << packet << " in packlets of " << packlet);
        const FrameBuffers fb = frame(packet, packlet);
        double worst = 0;
        int mismatched = 0;
        for (int y = 0; y < fb.height(); ++y)
          for (int x = 0; x < fb.width(); ++x) {
            const float a = single.depth(x, y), b = fb.depth(x, y);
            if (std::isfinite(a) != std::isfinite(b)) ++mismatched;
            else if (std::isfinite(a)) worst = std::max(worst, std::abs(double(a) - double(b)));
          }
        EXPECT_EQ(mismatched, 0);
        EXPECT_LT(worst, 1e-4) << "world units; voxels are larger";
        EXPECT_EQ(std::memcmp(single.color.data(), fb.color.data(), fb.color.size() * sizeof(Rgbaf)), 0)
            << "the same cells, the same roots: the same colours";
      }
  }
  // Anything but a power of two is refused, naming the parameter.
  for (const char* param : {"packet", "packlet"})
    try {
      RenderSession session(scene("ml.store", what), testing::backend_options("octree_cgt", {{param, 3.0}}));
      FAIL() << param << " 3 accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(param), std::string::npos) << e.what();
    }
}

TEST_F(OctreeCgt, EveryOptimisationOnOrOffGivesTheSameImage) {
  const Scene s = scene("fbm.store", R"("mode": "iso", "values": "normalized", "isosurfaces": [{"value": 0.45}, {"value": 0.6}],
      "shading": {"light": "headlight"})", 40);
  const auto frame = [&](std::map<std::string, double> params, FrameStats* stats = nullptr) {
    return render(s, std::move(params), stats);
  };
  FrameStats all_on, all_off;
  const FrameBuffers expected = frame({}, &all_on);
  for (double packet : {1.0, 8.0})
    for (int off = 0; off < 8; ++off) {
      std::map<std::string, double> p{{"packet", packet}, {"mcell", double(!(off & 1))}, {"cell", double(!(off & 2))},
                                      {"slice", double(!(off & 4))}};
      SCOPED_TRACE(::testing::Message() << "packet " << packet << " mcell " << p["mcell"] << " cell " << p["cell"] << " slice " << p["slice"]);
      FrameStats stats;
      const FrameBuffers fb = frame(p, &stats);
      EXPECT_EQ(std::memcmp(expected.color.data(), fb.color.data(), fb.color.size() * sizeof(Rgbaf)), 0);
      EXPECT_EQ(std::memcmp(expected.depth.data(), fb.depth.data(), fb.depth.size() * sizeof(float)), 0);
      if (packet == 8 && off == 7) all_off = stats;
    }
  // What the switches save is real: culling leaves fewer cells and nodes to visit.
  EXPECT_LT(all_on.counters.cells, all_off.counters.cells);
  EXPECT_LT(all_on.counters.nodes, all_off.counters.nodes);
}

TEST_F(OctreeCgt, LevelOfDetailTradesErrorForCellsAndBothModesAgree) {
  const Scene s = scene("ml.store", R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "shading": {"light": "headlight"})", 64);
  const FrameBuffers truth = testing::reference_frame(s);
  const auto frame = [&](std::map<std::string, double> params, FrameStats* stats = nullptr) {
    return render(s, std::move(params), stats);
  };
  double last_rmse = -1;
  uint64_t last_cells = 0;
  for (double dpdv : {0.0, 2.0, 8.0}) {
    SCOPED_TRACE(dpdv);
    FrameStats stats;
    const FrameBuffers fb = frame({{"dpdv", dpdv}}, &stats);
    ASSERT_TRUE(testing::all_finite(fb));
    const double rmse = compare_frames(fb, truth, 1.0).rmse;
    if (dpdv == 0) {
      EXPECT_EQ(rmse, 0.0);
    } else {
      EXPECT_GT(rmse, last_rmse) << "coarser voxels, more error";
      EXPECT_LT(rmse, dpdv <= 2 ? 0.12 : 0.3) << "Marschner-Lobb's ripples are a voxel or two wide: coarse levels lose them";
      EXPECT_LT(stats.counters.cells, last_cells) << "and fewer cells";
    }
    last_rmse = rmse, last_cells = stats.counters.cells;
    // The same levels, cells and roots in both modes.
    const FrameBuffers single = frame({{"dpdv", dpdv}, {"packet", 1}});
    EXPECT_EQ(std::memcmp(single.color.data(), fb.color.data(), fb.color.size() * sizeof(Rgbaf)), 0);
  }
  // show_levels colours hits by level: at dP/dV 8 more than one level is drawn.
  const FrameBuffers levels = frame({{"dpdv", 8.0}, {"show_levels", 1}});
  std::set<std::array<float, 3>> colours;
  for (int y = 0; y < levels.height(); ++y)
    for (int x = 0; x < levels.width(); ++x)
      if (levels.color(x, y).a > 0) colours.insert({levels.color(x, y).r, levels.color(x, y).g, levels.color(x, y).b});
  EXPECT_GE(colours.size(), 2u);
}

/// Pixels that see through a surface seen from outside (a closed, convex one): all 8
/// neighbours hit it, and the pixel itself sees nothing or something `gap` farther than each.
int holes(const FrameBuffers& fb, double gap) {
  int n = 0;
  for (int y = 1; y + 1 < fb.height(); ++y)
    for (int x = 1; x + 1 < fb.width(); ++x) {
      bool through = true;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (dx || dy) {
            const float nb = fb.depth(x + dx, y + dy);
            through &= std::isfinite(nb) && !(double(fb.depth(x, y)) <= double(nb) + gap);
          }
      n += through;
    }
  return n;
}

TEST_F(OctreeCgt, SmoothTransitionsLeaveNoCrackBetweenLevelsOfDetail) {
  // A closed sphere seen from outside, at dP/dV where the finest level and the next meet across
  // its visible half. Without smooth transitions a ray can pass between a level's last cells
  // and the coarser level's first beyond them, and see the sphere's far side; with them, none
  // does, in either mode. Eyes on the -K and the +K side of the three axes (on the +K side a
  // coarser level's cells overlap the finer one's instead).
  const double gap = 0.01;  // world units: a voxel of the 96^3 sphere
  int cracked = 0;
  for (const char* camera : {R"("eye": [0.5, -0.35, 0.5])", R"("eye": [1.35, 0.5, 0.5])", R"("eye": [0.5, 0.5, -0.4], "up": [0, 1, 0])",
                             R"("eye": [-0.3, 0.45, 0.55])"}) {
    SCOPED_TRACE(camera);
    const std::string text = R"({"dataset": ")" + dir_->file("sphere.store") + R"(", "backend": "octree_cgt",
        "image": {"width": 160, "height": 160}, "camera": {)" + std::string(camera) + R"(, "target": [0.5, 0.5, 0.5],
        "fov_degrees": 50}, "mode": "iso", "isosurfaces": [{"value": 0.0}], "shading": {"light": "headlight"}})";
    const Scene s = parse_scene(text, dir_->file("scene.json"));
    const FrameBuffers finest = render(s);
    ASSERT_EQ(holes(finest, gap), 0) << "the finest level is closed";
    int coarser = 0;  // pixels drawn from coarser cells
    for (double dpdv : {5.5, 6.0, 6.5, 7.0}) {
      SCOPED_TRACE(dpdv);
      const FrameBuffers lod = render(s, {{"dpdv", dpdv}});
      EXPECT_EQ(holes(lod, gap), 0);
      for (int y = 0; y < lod.height(); ++y)
        for (int x = 0; x < lod.width(); ++x) coarser += std::abs(lod.depth(x, y) - finest.depth(x, y)) > 1e-6f;
      if (dpdv == 6.0) {
        EXPECT_EQ(holes(render(s, {{"dpdv", dpdv}, {"packet", 1}}), gap), 0) << "single rays";
      }
      cracked += holes(render(s, {{"dpdv", dpdv}, {"smooth", 0}}), gap);
    }
    EXPECT_GT(coarser, 100) << "levels of detail change across the sphere";
  }
  EXPECT_GT(cracked, 30) << "without smooth transitions the levels leave cracks (else this test shows nothing)";
}

TEST_F(OctreeCgt, ShadowsFallWhereTheReferencesDoAndThroughACoarserLevelOfDetail) {
  const std::string iso = R"("mode": "iso", "values": "normalized", "isosurfaces": [{"value": 0.45}, {"value": 0.6}], )";
  const std::string light = R"("light": "point", "light_position": [1.2, -0.4, 1.9])";
  const Scene s = scene("gyroid.store", iso + R"("shading": {)" + light + R"(, "shadows": true})", 64);
  const Scene unshadowed = scene("gyroid.store", iso + R"("shading": {)" + light + "}", 64);
  const FrameBuffers truth = testing::reference_frame(s);
  const FrameBuffers lit = render(unshadowed);
  const auto differ = [](const Rgbaf& a, const Rgbaf& b, float by) {
    return std::abs(a.r - b.r) > by || std::abs(a.g - b.g) > by || std::abs(a.b - b.b) > by;
  };
  /// Pixels whose shadowing (fb against its unshadowed frame) differs from the reference's
  /// (against `lit`), and pixels in shadow.
  const auto shadow_mismatch = [&](const FrameBuffers& fb, const FrameBuffers& fb_lit, int& shadowed) {
    int mismatched = 0;
    shadowed = 0;
    for (int y = 0; y < fb.height(); ++y)
      for (int x = 0; x < fb.width(); ++x) {
        if (!std::isfinite(fb.depth(x, y))) continue;
        const bool dark = differ(fb.color(x, y), fb_lit.color(x, y), 1e-3f);
        const bool truth_dark = differ(truth.color(x, y), lit.color(x, y), 1e-3f);
        shadowed += dark;
        mismatched += dark != truth_dark;
      }
    return mismatched;
  };
  FrameStats full_stats;
  const FrameBuffers full = render(s, {}, &full_stats);
  int shadowed = 0;
  EXPECT_LE(shadow_mismatch(full, lit, shadowed), 3) << "at the finest level, the reference's shadows (grazing rays aside)";
  EXPECT_GT(shadowed, 100) << "the light is placed so that the surfaces shadow each other";
  EXPECT_EQ(full_stats.counters.shadow_rays, uint64_t(testing::hit_pixels(full)));
  // With levels of detail, shadow rays see coarser cells than primary rays (by default at
  // twice their dP/dV): fewer cells, the coarser the fewer, and shadows mostly where the
  // reference has them (thin occluders thin out at a coarse level, and a shadow ray leaves its
  // surface by half a coarse voxel).
  FrameStats same_stats, coarser_stats, coarsest_stats;
  render(s, {{"dpdv", 1.0}, {"shadow_dpdv", 1.0}}, &same_stats);
  const FrameBuffers coarser = render(s, {{"dpdv", 1.0}}, &coarser_stats);
  render(s, {{"dpdv", 1.0}, {"shadow_dpdv", 4.0}}, &coarsest_stats);
  EXPECT_LT(coarser_stats.counters.cells, same_stats.counters.cells);
  EXPECT_LT(coarsest_stats.counters.cells, coarser_stats.counters.cells);
  int coarse_shadowed = 0;
  const FrameBuffers coarser_lit = render(unshadowed, {{"dpdv", 1.0}});
  EXPECT_LT(shadow_mismatch(coarser, coarser_lit, coarse_shadowed), shadowed / 4);
  EXPECT_GT(coarse_shadowed, shadowed / 2);
  // Off without the scene asking: no shadow ray, and multires=0 draws the finest level.
  FrameStats none;
  render(unshadowed, {}, &none);
  EXPECT_EQ(none.counters.shadow_rays, 0u);
  const FrameBuffers flat = render(s, {{"dpdv", 4.0}, {"multires", 0.0}});
  EXPECT_EQ(std::memcmp(flat.color.data(), full.color.data(), full.color.size() * sizeof(Rgbaf)), 0);
}

TEST_F(OctreeCgt, ReadsOnlyPagesWhoseRangeHoldsTheIsovalueAndSkipsTheOthersItsRaysCross) {
  // The sphere's surface: pages well inside it and near the volume's corners miss it.
  Scene s = scene("sphere.store", R"("mode": "iso", "isosurfaces": [{"value": 0.0}])");
  const std::string trace = dir_->file("sphere.bytrace");
  {
    RenderSession::Options o;
    CacheConfig c = cache_config(s);
    c.trace_path = trace;
    o.cache = c;
    RenderSession session(s, o);
    FrameBuffers fb;
    session.render(0, fb, {});
  }
  std::set<uint64_t> fetched;
  for (const TraceRecord& r : read_trace(trace).records) {
    EXPECT_EQ(r.record, RecordKind::octree_page);
    fetched.insert(r.key);
  }
  Store store(dir_->file("sphere.store"));
  const OctreeView& view = store.dataset().octree();
  Scene in_store_units = s;
  normalize_values(in_store_units, store.manifest().min_value, store.manifest().max_value);
  // A page is read when its range holds the isovalue, or when it is a forward neighbour of
  // one that does: its first voxels close that page's last cells (pages carry no apron).
  auto holds = [&](const OctreePageRange* p) { return p && in_store_units.value_range_visible(p->min, p->max); };
  int holding = 0, not_holding = 0, skipped = 0;
  for (const OctreePageRange& p : view.pages()) {
    const BrickKey k = BrickKey::from_code(p.id);
    bool behind = false;
    for (int o = 1; o < 8; ++o)
      if ((!(o & 1) || k.x > 0) && (!(o & 2) || k.y > 0) && (!(o & 4) || k.z > 0))
        behind |= holds(view.page(OctreeLayout::page_id(int(k.level), {int64_t(k.x) - (o & 1), int64_t(k.y) - ((o >> 1) & 1),
                                                                       int64_t(k.z) - ((o >> 2) & 1)})));
    (holds(&p) ? holding : not_holding)++;
    if (!holds(&p) && !behind) {
      EXPECT_FALSE(fetched.count(p.id)) << describe_octree_page(p.id);
      ++skipped;
    }
  }
  EXPECT_GT(skipped, 0);
  EXPECT_GT(holding, 5);
  EXPECT_GT(not_holding, 5) << "pages without the surface, which rays through the volume cross";
  EXPECT_GT(fetched.size(), 5u);
}

TEST_F(OctreeCgt, AnL1FarBelowTheOctreeGivesTheSameImage) {
  const std::string what = R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "shading": {"light": "headlight"})";
  Store store(dir_->file("ml.store"));
  const uint64_t page = store.manifest().octree->page_bytes;
  ASSERT_GT(store.manifest().octree->pages, 20u);
  const FrameBuffers roomy = render(scene("ml.store", what, 64, R"("cache": {"l1": "64MiB", "l2": "64MiB"},)"));
  // Four pages of L1 and of L2 for an octree of dozens: tiles re-read what they need.
  const std::string tight = R"("cache": {"l1": ")" + std::to_string(4 * page) + R"(", "l2": ")" + std::to_string(4 * page) + R"("},)";
  FrameStats stats;
  const FrameBuffers small = render(scene("ml.store", what, 64, tight), {}, &stats);
  EXPECT_EQ(std::memcmp(roomy.color.data(), small.color.data(), roomy.color.size() * sizeof(Rgbaf)), 0);
  EXPECT_EQ(std::memcmp(roomy.depth.data(), small.depth.data(), roomy.depth.size() * sizeof(float)), 0);
}

TEST(OctreeCgtLarge, A1024CubedOctreeRendersWithAnL1FarBelowItsSize) {
  // 2^30 voxels (1 GiB of u8), streamed into a store and its octree; mostly empty space, so
  // both stay small on disk, but the octree is deep (10 levels) and wide (thousands of pages).
  testing::TempDir dir;
  const std::string store_dir = dir.file("blobs1024.store");
  build_store(*make_field_source(make_field("sparse-blobs"), {1024, 1024, 1024}, ValueType::u8), store_dir, {});
  build_octree(store_dir, {});
  Store store(store_dir);
  const OctreeSummary& octree = *store.manifest().octree;
  ASSERT_EQ(octree.depth, 10);
  ASSERT_GT(octree.pages, 2000u);
  const auto frame = [&](const std::string& l1, FrameStats* stats = nullptr) {
    const std::string text = R"({"dataset": ")" + store_dir + R"(", "backend": "octree_cgt", "image": {"width": 128, "height": 128},
        "cache": {"l1": ")" + l1 + R"(", "l2": ")" + l1 + R"("}, "camera": {"eye": [1.6, -1.1, 1.4], "target": [0.5, 0.5, 0.45],
        "fov_degrees": 35}, "mode": "iso", "values": "normalized", "isosurfaces": [{"value": 0.3}], "shading": {"light": "headlight"}})";
    return render(parse_scene(text, dir.file("scene.json")), {{"pinned_pages", 8}}, stats);
  };
  const FrameBuffers roomy = frame("256MiB");
  EXPECT_GT(testing::hit_pixels(roomy), 500);
  // An L1 and an L2 of 1/32 of the octree each (the tiles' 8 pinned pages fit in them): the
  // same image, its pages fetched again and again.
  const uint64_t budget = octree.bytes / 32;
  ASSERT_GE(budget, 2 * 8 * octree.page_bytes) << "room for two tiles' pinned pages";
  FrameStats stats;
  const FrameBuffers tight = frame(std::to_string(budget), &stats);
  EXPECT_EQ(std::memcmp(roomy.color.data(), tight.color.data(), roomy.color.size() * sizeof(Rgbaf)), 0);
  EXPECT_EQ(std::memcmp(roomy.depth.data(), tight.depth.data(), roomy.depth.size() * sizeof(float)), 0);
  EXPECT_GT(stats.counters.bricks, budget / octree.page_bytes) << "more page visits than the L1 holds";
}

TEST_F(OctreeCgt, AGridWithoutAnOctreeIsRefusedBeforeTheFirstFrameNamingTheCommand) {
  const Scene s = scene("grid-only.store", R"("mode": "iso", "isosurfaces": [{"value": 0.0}])");
  try {
    RenderSession session(s);
    FAIL() << "a grid without an octree was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::unsupported);
    EXPECT_NE(std::string(e.what()).find("brickyard build-octree"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("grid-only.store"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace brickyard
