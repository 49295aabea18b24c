// "What a scene does not ask for costs nothing": no gradients without shading or normals, no
// shadow rays without a light, no back end built that the scene does not name, and no brick
// fetched whose value range cannot contribute to the image (isovalue outside it, or zero
// opacity over it by the transfer function's summed-area table), for every back end.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "cache/trace.h"
#include "session/grid_cache.h"
#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/volume_source.h"
#include "session/render_session.h"
#include "render_test_util.h"
#include "shared_suite.h"
#include "renderers/common/renderer.h"
#include "renderers/common/scene.h"
#include "test_util.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

/// A sphere's signed distance, 48^3 f32 in 8^3 bricks (6^3 finest bricks): every brick has its
/// own value range, none is constant, and those wholly inside or outside the surface have
/// ranges that exclude 0. Values run from about -0.35 (centre) to 0.52 (corners).
class CostsNothing : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    BuildOptions o;
    o.brick_size = 8;
    auto sphere = make_field_source(make_field("sphere"), {48, 48, 48}, ValueType::f32);
    build_store(*sphere, dir_->file("sphere.store"), o);
    build_octree(dir_->file("sphere.store"), {});  // for the back ends that read an octree volume
  }
  static void TearDownTestSuite() { delete dir_; }

  static std::string store() { return dir_->file("sphere.store"); }

  /// A size x size scene of the sphere store: `mode_and_more` holds the mode's members and any others.
  static Scene scene(const std::string& mode_and_more, int size = 40) {
    const std::string text = R"({"dataset": "sphere.store", "image": {"width": )" + std::to_string(size) + R"(, "height": )" +
                             std::to_string(size) + R"(}, "cache": {"l1": "4MiB", "l2": "4MiB"},
        "camera": {"eye": [1.9, -1.3, 1.5], "target": [0.5, 0.5, 0.5], "fov_degrees": 40}, )" +
                             mode_and_more + "}";
    return parse_scene(text, dir_->file("scene.json"));
  }

  /// The back end's converged frame (shared_suite.h): what `brickyard render` shows.
  static FrameStats render(const Scene& s, const std::string& backend, const FrameOutputs& outputs, FrameBuffers& out) {
    RenderSession::Options o;
    o.backend = backend;
    RenderSession session(s, o);
    return testing::render_settled(session, out, outputs);
  }

  static int covered_pixels(const FrameBuffers& fb) {
    int n = 0;
    for (int y = 0; y < fb.height(); ++y)
      for (int x = 0; x < fb.width(); ++x) n += fb.color(x, y).a > 0;
    return n;
  }

  /// Renders frame 0, settled, with a cache that records its trace; returns the brick keys
  /// (codes) fetched at any level.
 public:
  /// The records of one kind the back end's frame read (bricks unless said otherwise).
  static std::set<uint64_t> fetched(const Scene& s, const std::string& backend, const FrameOutputs& outputs, int* covered = nullptr,
                                    RecordKind kind = RecordKind::brick) {
    const std::string trace = dir_->file(backend + ".bytrace");
    {
      RenderSession::Options o;
      o.backend = backend;
      CacheConfig c = cache_config(s);
      c.trace_path = trace;
      o.cache = c;
      RenderSession session(s, o);
      FrameBuffers fb;
      testing::render_settled(session, fb, outputs);
      if (covered) *covered = covered_pixels(fb);
    }  // the cache writes its trace when destroyed
    std::set<uint64_t> keys;
    for (const TraceRecord& r : read_trace(trace).records)
      if (r.record == kind) keys.insert(r.key);
    std::filesystem::remove(trace);
    return keys;
  }

  static testing::TempDir* dir_;
};
testing::TempDir* CostsNothing::dir_ = nullptr;

using testing::backends_for;

/// Whether a fetched brick can contribute to `scene`: at the finest level by its own range; at
/// a coarser one by the range of everything below it, which is what level-of-detail back ends
/// decide by (a coarse level's own range is narrowed by averaging).
bool may_contribute(const Store& store, const Scene& scene, const BrickKey& k, double tolerance = 0) {
  const NodeRecord& n = store.nodes().at(k);
  float lo = n.min, hi = n.max;
  const GridLayout& l = store.layout();
  std::vector<BrickKey> below{k};
  while (!below.empty()) {
    const BrickKey b = below.back();
    below.pop_back();
    lo = std::min(lo, store.nodes().at(b).min), hi = std::max(hi, store.nodes().at(b).max);
    if (int(b.level) < l.finest())
      for (int c = 0; c < 8; ++c)
        if (l.contains(b.child(c))) below.push_back(b.child(c));
  }
  return scene.value_range_visible(lo - tolerance, hi + tolerance);
}
const std::string kIso = R"("mode": "iso", "isosurfaces": [{"value": 0.0}])";

bool reads_octree(const std::string& backend) {
  const auto& r = backends().find(backend).info.records;
  return std::find(r.begin(), r.end(), RecordKind::octree_page) != r.end();
}

/// For back ends that read the octree volume: every page it fetched has a range holding an
/// isovalue, some are cap pages (full resolution), and no brick is read.
/// `check` is `sc` with its values in the store's units, when they are not.
void expect_octree_pages_hold_the_isovalue(const Store& s, const Scene& sc, const std::string& backend,
                                           const Scene* check = nullptr, double tolerance = 0) {
  if (!check) check = &sc;
  int covered = 0;
  const std::set<uint64_t> pages = CostsNothing::fetched(sc, backend, FrameOutputs{.depth = true, .normals = true}, &covered, RecordKind::octree_page);
  EXPECT_GT(covered, 100);
  ASSERT_FALSE(pages.empty());
  EXPECT_TRUE(CostsNothing::fetched(sc, backend, {}).empty()) << "no bricks";
  const OctreeView& view = s.dataset().octree();
  bool any_cap_page = false;
  for (uint64_t id : pages) {
    const OctreePageRange* p = view.page(id);
    ASSERT_NE(p, nullptr) << describe_octree_page(id);
    any_cap_page |= int(BrickKey::from_code(id).level) == view.layout().cap_page_root();
    EXPECT_TRUE(check->value_range_visible(p->min - tolerance, p->max + tolerance))
        << describe_octree_page(id) << " [" << p->min << ", " << p->max << "]";
  }
  EXPECT_TRUE(any_cap_page);
  // That pages the rays cross are skipped is octree_cgt's own test: on this sphere every page
  // holds the isovalue.
}

// --- (a) gradients ---------------------------------------------------------------------------

TEST_F(CostsNothing, NoGradientWhenNothingIsShadedAndNoNormalsAreAsked) {
  const FrameOutputs colour_only{.depth = true, .normals = false};
  const std::vector<std::string> modes = {R"("mode": "iso", "isosurfaces": [{"value": 0.0}])",
                                          R"("mode": "dvr", "transfer_function": {"points": [{"value": -0.1, "opacity": 0.2}, {"value": 0.1, "opacity": 0}]})"};
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr})
    for (const std::string& backend : backends_for(mode)) {
      SCOPED_TRACE(backend + " " + std::string(to_string(mode)));
      const std::string& text = modes[mode == RenderMode::iso ? 0 : 1];
      FrameBuffers fb;
      const FrameStats unlit = render(scene(text + R"(, "shading": {"light": "none"})"), backend, colour_only, fb);
      EXPECT_GT(covered_pixels(fb), 100);
      EXPECT_GT(unlit.counters.samples, 0u);
      EXPECT_EQ(unlit.counters.gradients, 0u);
      const FrameStats lit = render(scene(text + R"(, "shading": {"light": "headlight"})"), backend, colour_only, fb);
      EXPECT_GT(lit.counters.gradients, 0u);
      const FrameStats normals =
          render(scene(text + R"(, "shading": {"light": "none"})"), backend, FrameOutputs{.depth = true, .normals = true}, fb);
      EXPECT_GT(normals.counters.gradients, 0u);
    }
  // MIP is never shaded, whatever the light.
  for (const std::string& backend : backends_for(RenderMode::mip)) {
    SCOPED_TRACE(backend + " mip");
    FrameBuffers fb;
    const FrameStats mip = render(scene(R"("mode": "mip", "shading": {"light": "headlight"})"), backend, colour_only, fb);
    EXPECT_GT(covered_pixels(fb), 100);
    EXPECT_EQ(mip.counters.gradients, 0u);
  }
}

// --- (b) shadow rays -------------------------------------------------------------------------

TEST_F(CostsNothing, NoShadowRayWithoutALightEvenWhenShadowsAreAsked) {
  const FrameOutputs outputs{.depth = true, .normals = false};
  for (const std::string& backend : backends_for(RenderMode::iso)) {
    SCOPED_TRACE(backend);
    FrameBuffers fb;
    const FrameStats dark = render(scene(kIso + R"(, "shading": {"light": "none", "shadows": true})"), backend, outputs, fb);
    EXPECT_GT(covered_pixels(fb), 100);
    EXPECT_EQ(dark.counters.shadow_rays, 0u);
    const Scene lit_scene = scene(kIso + R"(, "shading": {"light": "point", "light_position": [1.5, -1, 2], "shadows": true})");
    // A back end that casts no shadow rays is refused a scene that asks for them (the rest
    // applies to it: no light, or no shadows asked, costs none).
    if (!testing::shades_as_asked(backend, lit_scene.shading)) {
      EXPECT_THROW(RenderSession(lit_scene, testing::backend_options(backend)), Error);
    } else {
      const FrameStats lit = render(lit_scene, backend, outputs, fb);
      EXPECT_GT(lit.counters.shadow_rays, 0u);
      EXPECT_EQ(lit.counters.shadow_rays, uint64_t(covered_pixels(fb)));  // one per surface hit
    }
    const FrameStats unshadowed = render(scene(kIso + R"(, "shading": {"light": "point", "light_position": [1.5, -1, 2]})"), backend,
                                         outputs, fb);
    EXPECT_EQ(unshadowed.counters.shadow_rays, 0u);
  }
}

// --- (c) back ends -----------------------------------------------------------------------------

/// A back end that counts its constructions and paints every pixel it is given.
struct FakeCounts {
  std::atomic<int> constructed{0}, begun{0}, ended{0}, tiles{0};
};

class FakeRenderer final : public Renderer {
 public:
  FakeRenderer(FakeCounts& counts, float shade) : counts_(counts), shade_(shade) { ++counts_.constructed; }
  void begin_frame(const FrameSetup&) override { ++counts_.begun; }
  void render_tile(const FrameSetup&, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    ++counts_.tiles;
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) {
        Rgbaf& c = out.color(x, y);
        c.r += shade_;  // accumulate: a pixel painted twice shows
        c.a += 1;
        ++counters.rays;
      }
  }
  void end_frame(const FrameSetup&, const FrameBuffers&) override { ++counts_.ended; }

 private:
  FakeCounts& counts_;
  float shade_;
};

BackendEntry fake_backend(const std::string& name, FakeCounts& counts, float shade) {
  BackendEntry e;
  e.info.name = name;
  e.info.description = "test double";
  e.info.kinds = {DataKind::structured};
  e.info.modes = {RenderMode::iso, RenderMode::dvr, RenderMode::mip};
  e.info.params = {{"knob", 1, 0, 2, "does nothing"}};
  e.create = [&counts, shade](const RenderContext&, const BackendParams& p) -> std::unique_ptr<Renderer> {
    EXPECT_GE(p["knob"], 0);
    return std::make_unique<FakeRenderer>(counts, shade);
  };
  return e;
}

TEST_F(CostsNothing, RegisteringAndFindingBackEndsConstructsNothing) {
  FakeCounts a, b;
  BackendRegistry registry;
  registry.add(fake_backend("fake-a", a, 0.25f));
  registry.add(fake_backend("fake-b", b, 0.5f));
  EXPECT_EQ(registry.names(), (std::vector<std::string>{"fake-a", "fake-b"}));
  EXPECT_TRUE(registry.contains("fake-b"));
  EXPECT_FALSE(registry.contains("fake-c"));
  EXPECT_EQ(registry.find("fake-b").info.name, "fake-b");
  try {
    registry.find("fake-c");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    EXPECT_THAT(e.what(), ::testing::HasSubstr("unknown back end 'fake-c' (known: 'fake-a', 'fake-b')"));
  }
  EXPECT_EQ(a.constructed, 0);
  EXPECT_EQ(b.constructed, 0);

  // What RenderSession does with the scene's back end, with the fakes: only the named one is
  // built, and render_frame calls begin/end once and covers every pixel exactly once.
  const Scene s = scene(kIso + R"(, "backend": {"name": "fake-b", "params": {"knob": 2}})");
  Store store_(store());
  GridCache cache(store_, cache_config(s));
  RenderContext context(s, store_.dataset(), cache.pages(), &cache.bricks());
  const BackendEntry& entry = registry.find(s.backend);
  std::unique_ptr<Renderer> renderer = entry.create(context, BackendParams(entry.info, s.backend_params, s.file));
  EXPECT_EQ(a.constructed, 0);
  EXPECT_EQ(b.constructed, 1);
  FrameSetup setup;
  setup.camera = s.camera.at(0).in_box(context.geometry().world);
  setup.width = 37;  // not a multiple of the tile size
  setup.height = 21;
  FrameBuffers fb;
  const FrameStats stats = render_frame(*renderer, context, setup, fb);
  EXPECT_EQ(b.begun, 1);
  EXPECT_EQ(b.ended, 1);
  EXPECT_EQ(b.tiles, ((37 + kTileSize - 1) / kTileSize) * ((21 + kTileSize - 1) / kTileSize));
  EXPECT_EQ(stats.counters.rays, uint64_t(37 * 21));
  for (int y = 0; y < 21; ++y)
    for (int x = 0; x < 37; ++x) ASSERT_EQ(fb.color(x, y), (Rgbaf{0.5f, 0, 0, 1})) << x << "," << y;
  EXPECT_EQ(a.constructed + a.begun + a.tiles, 0);
}

TEST_F(CostsNothing, RenderSessionBuildsTheBackEndTheSceneOrTheOptionsName) {
  // RenderSession takes its back ends from backends() and cannot be handed a registry,
  // so construction counts cannot be observed here; what can be: the one it holds.
  const Scene s = scene(kIso + R"(, "backend": {"name": "reference", "params": {"step": 0.25}})");
  RenderSession session(s);
  EXPECT_EQ(session.backend().name, "reference");
  EXPECT_DOUBLE_EQ(session.params()["step"], 0.25);
  RenderSession::Options o;
  o.backend = "raymarch";
  RenderSession other(s, o);
  EXPECT_EQ(other.backend().name, "raymarch");
  EXPECT_DOUBLE_EQ(other.params()["step"], 0.5);  // the scene's step was the reference's
}

// --- (d) nothing fetched outside the value range that can contribute ---------------------------

TEST_F(CostsNothing, IsoFetchesOnlyBricksWhoseRangeHoldsTheIsovalue) {
  Store s(store());
  const int finest = s.layout().finest();
  const double iso = 0.05;
  // Some bricks hold the isovalue, some do not (inside and outside the surface).
  int holding = 0, not_holding = 0;
  for (int64_t i = 0; i < s.layout().brick_count(finest); ++i) {
    const NodeRecord& n = s.nodes().at(s.layout().key_at(finest, i));
    (n.min <= iso && iso <= n.max ? holding : not_holding)++;
  }
  ASSERT_GT(holding, 10);
  ASSERT_GT(not_holding, 10);

  // The rays do cross bricks without the isovalue: a transfer function that shows every value
  // (MIP where the back end has it) fetches them.
  const Scene everything = scene(R"("mode": "dvr", "transfer_function": {"points": [{"value": -1, "opacity": 0.01}, {"value": 1, "opacity": 0.01}]})");
  for (const std::string& backend : backends_for(RenderMode::iso)) {
    for (const char* shading : {R"("light": "none")", R"("light": "point", "light_position": [1.5, -1, 2], "shadows": true)"}) {
      SCOPED_TRACE(backend + " " + shading);
      const Scene sc = scene(R"("mode": "iso", "isosurfaces": [{"value": 0.05}], "shading": {)" + std::string(shading) + "}", 64);
      if (!testing::shades_as_asked(backend, sc.shading)) continue;  // no shadow rays: refused (above)
      if (reads_octree(backend)) {
        expect_octree_pages_hold_the_isovalue(s, sc, backend);
        continue;
      }
      int covered = 0;
      const std::set<uint64_t> keys = fetched(sc, backend, FrameOutputs{.depth = true, .normals = true}, &covered);
      EXPECT_GT(covered, 100);
      ASSERT_FALSE(keys.empty());
      bool any_finest = false;
      for (uint64_t code : keys) {
        const BrickKey k = BrickKey::from_code(code);
        any_finest |= int(k.level) == finest;
        EXPECT_TRUE(may_contribute(s, sc, k)) << k.to_string();
      }
      EXPECT_TRUE(any_finest);  // the scenes ask for full resolution
      int skipped = 0;
      for (uint64_t code : fetched(everything, backend, {}))
        skipped += !keys.count(code);
      EXPECT_GT(skipped, 5);
    }
  }
}

TEST_F(CostsNothing, NormalizedIsovaluesAreMappedBeforeBricksAreChosen) {
  // "values": "normalized": the filter uses the isovalue in the store's units.
  Store s(store());
  const double lo = s.manifest().min_value, hi = s.manifest().max_value;
  const double iso = 0.05, fraction = (iso - lo) / (hi - lo);
  const Scene sc = scene(R"("values": "normalized", "mode": "iso", "isosurfaces": [{"value": )" + std::to_string(fraction) + "}]", 64);
  for (const std::string& backend : backends_for(RenderMode::iso)) {
    SCOPED_TRACE(backend);
    if (reads_octree(backend)) {
      Scene in_store_units = sc;
      normalize_values(in_store_units, lo, hi);
      expect_octree_pages_hold_the_isovalue(s, sc, backend, &in_store_units, 1e-6);
      continue;
    }
    int covered = 0;
    const std::set<uint64_t> keys = fetched(sc, backend, {}, &covered);
    EXPECT_GT(covered, 100);
    ASSERT_FALSE(keys.empty());
    Scene in_store_units = sc;  // what the session filters by
    normalize_values(in_store_units, lo, hi);
    ASSERT_NEAR(in_store_units.isosurfaces[0].value, iso, 1e-6);  // to_string kept 6 digits of the fraction
    for (uint64_t code : keys)
      EXPECT_TRUE(may_contribute(s, in_store_units, BrickKey::from_code(code), 1e-6)) << BrickKey::from_code(code).to_string();
  }
}

TEST_F(CostsNothing, DvrFetchesOnlyBricksTheTransferFunctionMakesVisible) {
  Store s(store());
  const int finest = s.layout().finest();
  // Opacity only in a band around the surface: the inside and the outside are invisible.
  const std::string tf = R"("mode": "dvr", "transfer_function": {"points": [
      {"value": -1, "opacity": 0}, {"value": -0.04, "opacity": 0}, {"value": 0.0, "opacity": 0.3},
      {"value": 0.04, "opacity": 0}, {"value": 1, "opacity": 0}]})";
  const Scene probe = scene(tf);
  int visible = 0, invisible = 0;
  for (int64_t i = 0; i < s.layout().brick_count(finest); ++i) {
    const NodeRecord& n = s.nodes().at(s.layout().key_at(finest, i));
    (probe.transfer_function.visible(n.min, n.max) ? visible : invisible)++;
  }
  ASSERT_GT(visible, 10);
  ASSERT_GT(invisible, 10);

  const Scene everything = scene(R"("mode": "dvr", "transfer_function": {"points": [{"value": -1, "opacity": 0.01}, {"value": 1, "opacity": 0.01}]})");
  for (const std::string& backend : backends_for(RenderMode::dvr))
    for (const char* shading : {R"("light": "none")", R"("light": "headlight")"}) {
      SCOPED_TRACE(backend + " " + shading);
      const Scene sc = scene(tf + R"(, "shading": {)" + shading + "}", 64);
      int covered = 0;
      const std::set<uint64_t> keys = fetched(sc, backend, FrameOutputs{.depth = true, .normals = true}, &covered);
      EXPECT_GT(covered, 100);
      ASSERT_FALSE(keys.empty());
      for (uint64_t code : keys) EXPECT_TRUE(may_contribute(s, sc, BrickKey::from_code(code))) << BrickKey::from_code(code).to_string();
      int skipped = 0;
      for (uint64_t code : fetched(everything, backend, {}))
        skipped += !keys.count(code);
      EXPECT_GT(skipped, 5);
    }
}

// Difference normals (central, forward) sample one voxel either side of the hit or sample; the
// stencil stays inside the brick that holds the sample's cell (one-sided at its faces), so no
// neighbour whose values cannot contribute is fetched for it. Back ends that compute only the
// analytic gradient (BackendInfo::normals) are refused such scenes and are not asked.
TEST_F(CostsNothing, DifferenceNormalsFetchOnlyBricksThatCanContribute) {
  Store s(store());
  const std::string band = R"("mode": "dvr", "transfer_function": {"points": [
      {"value": -1, "opacity": 0}, {"value": -0.04, "opacity": 0}, {"value": 0.0, "opacity": 0.3},
      {"value": 0.04, "opacity": 0}, {"value": 1, "opacity": 0}]})";
  for (RenderMode m : {RenderMode::iso, RenderMode::dvr})
    for (const std::string& backend : backends_for(m))
      for (const char* normals : {"central", "forward"}) {
        const std::string& mode = m == RenderMode::iso ? kIso : band;
        SCOPED_TRACE(backend + " " + normals + " " + mode);
        const Scene sc = scene(mode + R"(, "shading": {"normals": ")" + normals + "\"}", 96);
        if (!testing::shades_as_asked(backend, sc.shading)) {
          EXPECT_THROW(RenderSession(sc, testing::backend_options(backend)), Error);
          continue;
        }
        if (reads_octree(backend)) {
          // Octree pages only, no brick; on this sphere every page holds the isovalue, and the
          // voxels a difference reads beyond a cell's corners lie in the cell's page or the next.
          expect_octree_pages_hold_the_isovalue(s, sc, backend);
          continue;
        }
        const std::set<uint64_t> keys = fetched(sc, backend, FrameOutputs{.depth = true, .normals = true});
        ASSERT_FALSE(keys.empty());
        for (uint64_t code : keys) EXPECT_TRUE(may_contribute(s, sc, BrickKey::from_code(code))) << BrickKey::from_code(code).to_string();
      }
}

}  // namespace
}  // namespace brickyard
