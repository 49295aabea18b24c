// Datasets of every kind through one path: a store's kind, its views, the page cache over it and
// the back end that accepts it, as `brickyard render` opens them.

#include <gtest/gtest.h>

#include <set>

#include "cache/trace.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "session/grid_cache.h"
#include "session/render_session.h"
#include "tet_fixture.h"
#include "test_util.h"

namespace brickyard {
namespace {

class Datasets : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    testing::write_tet_store(dir_->file("row.store"), 4);
    BuildOptions o;
    o.brick_size = 8;
    build_store(*make_field_source(make_field("sphere"), {24, 24, 24}, ValueType::u8), dir_->file("sphere.store"), o);
    build_store(*make_field_source(make_field("sphere"), {24, 24, 24}, ValueType::f32), dir_->file("sphere-f32.store"), o);
  }
  static void TearDownTestSuite() { delete dir_; }

  /// A 64x16 scene of `store` (MIP unless `mode` says otherwise), looking along +y at the middle
  /// of its box.
  static Scene scene(const std::string& store, const std::string& backend, const std::string& mode = R"("mode": "mip")") {
    const std::string text = R"({"dataset": ")" + store + R"(", "backend": ")" + backend + R"(",
        "image": {"width": 64, "height": 16}, )" + mode + R"(, "cache": {"l1": "1MiB", "l2": "1MiB"},
        "camera": {"eye": [0.5, -6, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30}})";
    return parse_scene(text, dir_->file("scene.json"));
  }
  static BackendRegistry registry() {
    BackendRegistry r = builtin_backends();
    r.add(testing::tet_probe_backend());
    return r;
  }
  static testing::TempDir* dir_;
};
testing::TempDir* Datasets::dir_ = nullptr;

TEST_F(Datasets, AStoreSaysItsKindAndHandsOutTheViewOfThatKindOnly) {
  const Store mesh(dir_->file("row.store"));
  EXPECT_EQ(mesh.dataset().kind(), DataKind::tetrahedral);
  EXPECT_TRUE(mesh.dataset().has_tets());
  EXPECT_EQ(mesh.dataset().tets().clusters().size(), 4u);
  EXPECT_EQ(mesh.dataset().tets().tet_count(), 24u);
  EXPECT_EQ(mesh.dataset().info().world.hi.x, 4.0);
  try {
    (void)mesh.dataset().grid();
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::unsupported);
    EXPECT_EQ(e.file(), dir_->file("row.store"));
    EXPECT_NE(e.message().find("tetrahedral and has no grid view"), std::string::npos) << e.what();
  }
  const std::vector<PageKindInfo> kinds = mesh.page_kinds();
  ASSERT_EQ(kinds.size(), 1u);
  EXPECT_EQ(kinds[0].kind, RecordKind::tet_cluster);
  EXPECT_EQ(kinds[0].records, 4u);

  const Store grid(dir_->file("sphere.store"));
  EXPECT_EQ(grid.dataset().kind(), DataKind::structured);
  EXPECT_TRUE(grid.dataset().has_grid());
  EXPECT_FALSE(grid.dataset().has_tets());
  EXPECT_EQ(grid.dataset().grid().dims(), Vec3s(24));
  EXPECT_THROW((void)grid.dataset().tets(), Error);
  ASSERT_EQ(grid.page_kinds().size(), 1u);
  EXPECT_EQ(grid.page_kinds()[0].kind, RecordKind::brick);
  EXPECT_EQ(grid.page_kinds()[0].page_bytes, grid.format().bytes());
}

TEST_F(Datasets, ATetrahedralDatasetReachesItsBackEndThroughThePageCache) {
  const BackendRegistry r = registry();
  RenderSession::Options o;
  o.registry = &r;
  RenderSession session(scene("row.store", "tet-probe"), o);
  EXPECT_EQ(session.context().kind(), DataKind::tetrahedral);
  FrameBuffers fb;
  session.render(0, fb, {.depth = true});
  // Grey is the largest scalar of the clusters a ray meets, over the range [0, 4]: cube i has
  // scalars up to i + 1, and x grows to the right, so a row reads 1/4, 2/4, 3/4, 1 in order.
  std::set<float> levels;
  for (int y = 0; y < fb.height(); ++y) {
    float last = 0;
    for (int x = 0; x < fb.width(); ++x) {
      const Rgbaf c = fb.color(x, y);
      if (c.a == 0) continue;
      EXPECT_TRUE(c.r == 0.25f || c.r == 0.5f || c.r == 0.75f || c.r == 1.0f) << x << "," << y << ": " << c.r;
      EXPECT_GE(c.r, last) << x << "," << y;
      last = c.r;
      levels.insert(c.r);
    }
  }
  EXPECT_EQ(levels.size(), 4u);
  // Every cluster came from the store once, through the cache, and is resident now.
  const CacheStats s = session.pages().stats(RecordKind::tet_cluster);
  EXPECT_EQ(s.l3.hits, 4u);
  EXPECT_EQ(s.l1.resident, 4u);
  EXPECT_EQ(s.l3_bytes_decoded, 4 * TetClusterPage::bytes(8, 6));
  EXPECT_EQ(session.pages().stats(RecordKind::brick).l3.hits, 0u);
  EXPECT_THROW((void)session.bricks(), Error);  // no grid, no bricks
}

TEST_F(Datasets, GridBackEndsAreRefusedOnAMeshByName) {
  for (const char* backend : {"raymarch", "gobbetti", "gigavoxels", "octree_cgt"}) {
    try {
      RenderSession session(scene("row.store", backend, R"("mode": "iso", "isosurfaces": [{"value": 2}])"));
      FAIL() << backend;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::unsupported) << e.what();
      EXPECT_EQ(e.file(), dir_->file("row.store"));
      EXPECT_NE(e.message().find(std::string("back end '") + backend + "' does not render tetrahedral datasets"),
                std::string::npos)
          << e.what();
    }
  }
  const BackendRegistry r = registry();
  RenderSession::Options o;
  o.registry = &r;
  EXPECT_THROW(RenderSession(scene("sphere.store", "tet-probe"), o), Error);  // and the other way round
}

TEST_F(Datasets, ABackEndAskingForAViewItsDatasetLacksIsRefusedBeforeTheFirstFrame) {
  BackendRegistry r;
  BackendEntry e;
  e.info.name = "wants-a-grid";
  e.info.kinds = {DataKind::tetrahedral};
  e.info.modes = {RenderMode::mip};
  int constructed = 0;
  e.create = [&](const RenderContext& ctx, const BackendParams&) -> std::unique_ptr<Renderer> {
    (void)ctx.grid().layout();  // a grid back end that claimed the wrong kind
    ++constructed;
    return nullptr;
  };
  r.add(e);
  RenderSession::Options o;
  o.registry = &r;
  try {
    RenderSession session(scene("row.store", "wants-a-grid"), o);
    FAIL();
  } catch (const Error& err) {
    EXPECT_EQ(err.code(), Errc::unsupported);
    EXPECT_EQ(err.file(), dir_->file("row.store"));
    EXPECT_NE(err.message().find("no grid view"), std::string::npos) << err.what();
  }
  EXPECT_EQ(constructed, 0);
}

TEST_F(Datasets, ACacheBudgetBelowOnePageNamesTheScenesKeyAndThePage) {
  // One byte short of a brick (8^3 f32 with its apron: 4000 bytes, "3.91 KiB" both) gives both
  // in bytes. An L2 of 0 does not turn the L2 off: it is refused alike, with one decoded page.
  const uint64_t brick = Store(dir_->file("sphere-f32.store")).format().bytes();
  ASSERT_EQ(brick, 4000u);
  struct Case {
    uint64_t l1, l2;
    std::string field, says;
  };
  for (const Case& c : {Case{brick - 1, 1 << 20, "cache.l1", "the L1 budget of 3999 bytes is smaller than one brick (4000 bytes)"},
                        Case{1 << 20, 0, "cache.l2", "the L2 budget of 0 B is smaller than one decoded page (3.91 KiB)"}}) {
    Scene s = scene("sphere-f32.store", "raymarch");
    s.cache.l1_bytes = c.l1;
    s.cache.l2_bytes = c.l2;
    try {
      RenderSession session(s);
      ADD_FAILURE() << c.field << ": no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument) << e.what();
      EXPECT_EQ(e.field(), c.field) << e.what();
      EXPECT_EQ(e.file(), dir_->file("scene.json")) << e.what();
      EXPECT_NE(e.message().find(c.says), std::string::npos) << e.what();
    }
  }
  // A configuration the caller gave is the caller's: the cache's own field, no scene file.
  RenderSession::Options o;
  o.cache = cache_config(scene("sphere-f32.store", "raymarch"));
  o.cache->l2_bytes = 0;
  try {
    RenderSession session(scene("sphere-f32.store", "raymarch"), o);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "l2_bytes") << e.what();
  }
}

TEST_F(Datasets, ResetCacheKeepsTheContextAndStartsFromAnEmptyCache) {
  const BackendRegistry r = registry();
  RenderSession::Options o;
  o.registry = &r;
  RenderSession session(scene("row.store", "tet-probe"), o);
  const RenderContext* context = &session.context();
  FrameBuffers first, second;
  session.render(0, first);
  EXPECT_EQ(session.pages().stats().l3.hits, 4u);
  session.reset_cache();
  EXPECT_EQ(&session.context(), context);
  EXPECT_EQ(&session.context().pages(), &session.pages());
  EXPECT_EQ(session.pages().stats().l3.hits, 0u);
  session.render(0, second);
  EXPECT_EQ(session.pages().stats().l3.hits, 4u);  // cold again
  for (int y = 0; y < first.height(); ++y)
    for (int x = 0; x < first.width(); ++x) ASSERT_EQ(first.color(x, y), second.color(x, y));
}

TEST_F(Datasets, ATraceRecordsTheKindOfEveryPageAndReplaysByKind) {
  const BackendRegistry r = registry();
  RenderSession::Options o;
  o.registry = &r;
  o.cache = cache_config(scene("row.store", "tet-probe"));
  o.cache->trace_path = dir_->file("mesh.bytrace");
  {
    RenderSession session(scene("row.store", "tet-probe"), o);
    FrameBuffers fb;
    session.render(0, fb);
    session.render(0, fb);
  }
  const Trace t = read_trace(dir_->file("mesh.bytrace"));
  ASSERT_FALSE(t.records.empty());
  for (const TraceRecord& rec : t.records) ASSERT_EQ(rec.record, RecordKind::tet_cluster);
  EXPECT_EQ(t.unique_objects(), 4u);
  EXPECT_EQ(t.record_kinds(), std::vector<RecordKind>{RecordKind::tet_cluster});
}

TEST_F(Datasets, AGridStoreOfTheFirstFormatIsStillAGrid) {
  // A manifest written before datasets had a kind: no `kind`, no `time_steps`.
  const Store grid(dir_->file("sphere.store"));
  std::string text = grid.manifest().to_json();
  for (const char* key : {"\"kind\"", "\"time_steps\""}) {
    const size_t at = text.find(key);
    ASSERT_NE(at, std::string::npos);
    text.erase(at, text.find('\n', at) - at + 1);
  }
  const Manifest m = Manifest::from_json(text, "old.store");
  EXPECT_EQ(m.kind, DataKind::structured);
  EXPECT_EQ(m.time_steps, 1);
  EXPECT_EQ(m.format_version, 1);
  EXPECT_EQ(m.dims, Vec3s(24));
}

TEST_F(Datasets, ManifestsOfUnknownKindsOrWithoutAMeshAreFormatErrors) {
  const Store mesh(dir_->file("row.store"));
  const std::string text = mesh.manifest().to_json();
  EXPECT_NE(text.find("\"format_version\": 2"), std::string::npos) << text;
  std::string odd = text;
  odd.replace(odd.find("\"tetrahedral\""), 13, "\"hexahedral\"");
  try {
    Manifest::from_json(odd, "odd.store");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.field(), "kind");
    EXPECT_NE(e.message().find("unknown dataset kind 'hexahedral'"), std::string::npos) << e.what();
  }
  std::string old_version = text;
  old_version.replace(old_version.find("\"format_version\": 2"), 19, "\"format_version\": 1");
  try {
    Manifest::from_json(old_version, "old.store");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.field(), "format_version");
  }
  std::string no_mesh = text;
  no_mesh.replace(no_mesh.find("\"mesh\""), 6, "\"mush\"");
  try {
    Manifest::from_json(no_mesh, "odd.store");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "mesh");
  }
}

TEST_F(Datasets, VerifyDecodesEveryClusterAndFindsACorruptOne) {
  const Store mesh(dir_->file("row.store"));
  auto txn = mesh.begin_read();
  std::vector<std::byte> page(mesh.manifest().mesh.page_bytes);
  for (uint64_t c = 0; c < 4; ++c) {
    const PageRead read = mesh.read_page(txn, {RecordKind::tet_cluster, c}, page);
    EXPECT_GT(read.stored_bytes, 0u);
    const TetClusterPage p = TetClusterPage::view(page);
    EXPECT_EQ(p.vertex_count, 8u);
    EXPECT_EQ(p.tet_count, 6u);
    EXPECT_EQ(p.values[7], float(c + 1));
  }
  try {
    mesh.read_page(txn, {RecordKind::tet_cluster, 4}, page);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::not_found);
    EXPECT_EQ(e.key(), "cluster 4");
  }
  EXPECT_THROW(mesh.read_page(txn, {RecordKind::brick, 0}, page), Error);
}

}  // namespace
}  // namespace brickyard
