// The octree volume beside a grid (dataset/octree.h): lossless round trips of every voxel of
// every level, conservative ranges at every depth, consolidation, the lossy and clamped
// variants, and what a rebuild or an interrupted one leaves.

#include <gtest/gtest.h>

#include <map>
#include <optional>

#include "dataset/octree_walk.h"
#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"
#include "test_util.h"
#include "preprocess/builder_test_util.h"

namespace brickyard {
namespace {

using testing::Grid;

/// Every decoded page of a store's octree, by id.
struct Pages {
  std::map<uint64_t, std::vector<std::byte>> pages;
  explicit Pages(const Store& store) {
    auto txn = store.begin_read();
    std::vector<PageKey> keys;
    store.for_each_page(txn, RecordKind::octree_page, [&](const PageKey& k, std::span<const std::byte>) {
      keys.push_back(k);
      return true;
    });
    for (const PageKey& k : keys) {
      auto& p = pages[k.id];
      p.resize(size_t(store.manifest().octree->page_bytes));
      store.read_page(txn, k, p);
    }
  }
  const std::byte* operator()(uint64_t id) const {
    auto it = pages.find(id);
    return it == pages.end() ? nullptr : it->second.data();
  }
};

std::string build(const testing::TempDir& dir, const std::string& field, const Vec3s& dims, ValueType type,
                  const OctreeBuildOptions& options = {}, int brick = 8) {
  BuildOptions b;
  b.brick_size = brick;
  build_store(*make_field_source(make_field(field), dims, type), dir.file("s"), b);
  build_octree(dir.file("s"), options);
  return dir.file("s");
}

/// The pyramid the octree must reproduce: the sampled grid and its 2x filter, to the octree's depth.
template <typename T>
std::vector<Grid<T>> pyramid(const std::string& field, const Vec3s& dims, int depth) {
  std::vector<Grid<T>> levels{testing::sample<T>(*make_field(field), dims)};
  while (int(levels.size()) < depth) levels.push_back(testing::halve(levels.back()));
  return levels;
}

template <typename T>
void expect_round_trip(const std::string& field, const Vec3s& dims, std::optional<bool> expect_consolidation) {
  SCOPED_TRACE(field);
  testing::TempDir dir;
  Store store(build(dir, field, dims, ValueTypeOf<T>::value));
  ASSERT_TRUE(store.has_octree());
  ASSERT_TRUE(store.dataset().has_octree());
  const OctreeLayout layout = store.dataset().octree().layout();
  const OctreeSummary& summary = *store.manifest().octree;
  EXPECT_EQ(summary.max_error, 0.0);
  if (expect_consolidation) {
    EXPECT_EQ(*expect_consolidation, summary.consolidated > 0) << summary.consolidated << " consolidated";
  }
  const Pages pages(store);
  EXPECT_EQ(pages.pages.size(), summary.pages);
  const auto levels = pyramid<T>(field, dims, layout.depth);
  for (int s = 0; s < layout.depth; ++s) {
    const Grid<T>& g = levels[size_t(s)];
    ASSERT_EQ(g.dims, layout.level_dims(s));
    int64_t wrong = 0;
    for (int64_t z = 0; z < g.dims.z; ++z)
      for (int64_t y = 0; y < g.dims.y; ++y)
        for (int64_t x = 0; x < g.dims.x; ++x) {
          const auto got = octree_voxel<T>(layout, pages, s, {x, y, z});
          if (!got.exact || got.value != g.at(x, y, z)) {
            if (wrong++ < 3)
              ADD_FAILURE() << "level " << s << " voxel (" << x << ", " << y << ", " << z << "): " << double(got.value)
                            << (got.exact ? "" : " (not exact)") << ", expected " << double(g.at(x, y, z));
          }
        }
    EXPECT_EQ(wrong, 0) << "level " << s;
  }
}

TEST(Octree, LosslessOctreeRoundTripsEveryVoxelOfEveryLevel) {
  expect_round_trip<uint8_t>("sparse-blobs", {40, 37, 29}, true);
  expect_round_trip<uint16_t>("fbm", {33, 17, 20}, false);
  expect_round_trip<float>("marschner-lobb", {24, 24, 24}, false);
  expect_round_trip<uint8_t>("menger", {27, 27, 27}, true);
  expect_round_trip<uint8_t>("sphere", {3, 2, 5}, std::nullopt);  // the least octree: depth 3, one page
}

/// Visits every stored node with its depth and coordinates.
template <typename T, typename F>
void for_each_node(const OctreeLayout& layout, const Pages& pages, F&& f) {
  struct Walk {
    const OctreeLayout& layout;
    const Pages& pages;
    F& f;
    void page(int root, const Vec3s& c) {
      const std::byte* bytes = pages(OctreeLayout::page_id(root, c));
      ASSERT_NE(bytes, nullptr) << describe_octree_page(OctreeLayout::page_id(root, c));
      const auto p = OctreePage<T>::view({bytes, layout.page_bytes()}, layout);
      node(p, root, 0, 0, c);
    }
    void node(const OctreePage<T>& p, int root, int level, uint32_t index, const Vec3s& c) {
      const OctreeNode& n = p.nodes[size_t(level)][index];
      f(root + level, c, n);
      for (int o = 0; o < 8; ++o) {
        if (!(n.child_mask & (1u << o))) continue;
        const Vec3s cc{2 * c.x + (o & 1), 2 * c.y + ((o >> 1) & 1), 2 * c.z + ((o >> 2) & 1)};
        const int d = root + level + 1;
        if (d == layout.cap_depth()) continue;
        if (level + 1 < p.header->levels) node(p, root, level + 1, n.child_index(o), cc);
        else page(d, cc);
      }
    }
  } walk{layout, pages, f};
  walk.page(0, Vec3s(0));
}

TEST(Octree, NodeRangesCoverEveryCellOfTheirRegionAtEveryFinerLevel) {
  testing::TempDir dir;
  const Vec3s dims{37, 30, 26};
  Store store(build(dir, "fbm", dims, ValueType::u16));
  const OctreeLayout layout = store.dataset().octree().layout();
  const Pages pages(store);
  const auto levels = pyramid<uint16_t>("fbm", dims, layout.depth);
  int64_t nodes = 0;
  for_each_node<uint16_t>(layout, pages, [&](int d, const Vec3s& c, const OctreeNode& n) {
    ++nodes;
    for (int s = 0; s <= layout.level_of_depth(d); ++s) {
      const Grid<uint16_t>& g = levels[size_t(s)];
      const int64_t span = int64_t(2) << (layout.level_of_depth(d) - s);  // level-s voxels per node edge
      for (int64_t z = c.z * span; z <= std::min((c.z + 1) * span, g.dims.z - 1); ++z)
        for (int64_t y = c.y * span; y <= std::min((c.y + 1) * span, g.dims.y - 1); ++y)
          for (int64_t x = c.x * span; x <= std::min((c.x + 1) * span, g.dims.x - 1); ++x) {
            const float v = float(g.at(x, y, z));
            ASSERT_TRUE(v >= n.min && v <= n.max)
                << "depth " << d << " node (" << c.x << ", " << c.y << ", " << c.z << ") range [" << n.min << ", "
                << n.max << "] misses level " << s << " voxel (" << x << ", " << y << ", " << z << ") = " << v;
          }
    }
  });
  EXPECT_GT(nodes, 100);
}

TEST(Octree, ConsolidationStoresLessAndTheLossyVariantStaysWithinItsTolerance) {
  testing::TempDir lossless_dir, lossy_dir;
  const Vec3s dims{48, 40, 36};
  Store lossless(build(lossless_dir, "fbm", dims, ValueType::u8));
  OctreeBuildOptions lossy_options;
  lossy_options.tolerance = 6;
  Store lossy(build(lossy_dir, "fbm", dims, ValueType::u8, lossy_options));
  const OctreeSummary &a = *lossless.manifest().octree, &b = *lossy.manifest().octree;
  EXPECT_LT(b.bytes, a.bytes);
  EXPECT_GT(b.consolidated, a.consolidated);
  EXPECT_GT(b.max_error, 0.0);
  EXPECT_LE(b.max_error, 6.0);
  EXPECT_EQ(b.tolerance, 6.0);
  const OctreeLayout layout = lossy.dataset().octree().layout();
  const Pages pages(lossy);
  const Grid<uint8_t> g = testing::sample<uint8_t>(*make_field("fbm"), dims);
  double worst = 0;
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) {
        const auto got = octree_voxel<uint8_t>(layout, pages, 0, {x, y, z});
        ASSERT_TRUE(got.exact);
        worst = std::max(worst, std::abs(double(got.value) - double(g.at(x, y, z))));
      }
  EXPECT_EQ(worst, b.max_error) << "the reported error is the largest one";
}

TEST(Octree, TheClampedVariantIsExactInsideItsRangeAndConsolidatesOutside) {
  testing::TempDir full_dir, clamped_dir;
  const Vec3s dims{40, 40, 40};
  Store full(build(full_dir, "marschner-lobb", dims, ValueType::f32));
  OctreeBuildOptions options;
  options.clamp = std::pair{0.4, 0.6};
  Store clamped(build(clamped_dir, "marschner-lobb", dims, ValueType::f32, options));
  const OctreeSummary& c = *clamped.manifest().octree;
  EXPECT_TRUE(c.clamped);
  EXPECT_EQ(c.clamp_lo, 0.4);
  EXPECT_LT(c.bytes, full.manifest().octree->bytes);
  const Pages pages(clamped);
  const OctreeLayout layout = clamped.dataset().octree().layout();
  const Grid<float> g = testing::sample<float>(*make_field("marschner-lobb"), dims);
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) {
        const float v = octree_voxel<float>(layout, pages, 0, {x, y, z}).value;
        ASSERT_EQ(v, std::clamp(g.at(x, y, z), 0.4f, 0.6f)) << x << ", " << y << ", " << z;
      }
}

TEST(Octree, ARebuildReplacesTheOctreeAndAnInterruptedOneLeavesTheGridWithout) {
  testing::TempDir dir;
  const std::string path = build(dir, "sparse-blobs", {32, 32, 32}, ValueType::u8);
  const uint64_t lossless_pages = Store(path).manifest().octree->pages;
  OctreeBuildOptions lossy;
  lossy.tolerance = 40;
  build_octree(path, lossy);
  {
    Store store(path);
    EXPECT_EQ(store.manifest().octree->tolerance, 40.0);
    EXPECT_EQ(Pages(store).pages.size(), store.manifest().octree->pages) << "no page of the old octree is left";
    EXPECT_LE(store.manifest().octree->pages, lossless_pages);
  }
  {
    Store store(path, {.writable = true});
    OctreeWriter writer(store);  // starts a build, then dies before finish()
    writer.put_page(OctreeLayout::page_id(0, Vec3s(0)), std::vector<std::byte>(64));
  }
  Store store(path);
  EXPECT_FALSE(store.has_octree());
  EXPECT_FALSE(store.dataset().has_octree());
  try {
    (void)store.dataset().octree();
    FAIL() << "a grid without an octree handed out an octree view";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("build-octree"), std::string::npos) << e.what();
  }
  EXPECT_EQ(store.page_kinds().size(), 1u) << "only bricks";
}

TEST(Octree, PagesAreReadThroughThePageSourceAndAMissingOneIsNamed) {
  testing::TempDir dir;
  Store store(build(dir, "sparse-blobs", {40, 40, 40}, ValueType::u8));
  const auto kinds = store.page_kinds();
  ASSERT_EQ(kinds.size(), 2u);
  EXPECT_EQ(kinds[1].kind, RecordKind::octree_page);
  EXPECT_EQ(kinds[1].page_bytes, store.manifest().octree->page_bytes);
  auto reader = store.open_reader();
  std::vector<std::byte> page(kinds[1].page_bytes);
  reader->read({RecordKind::octree_page, store.dataset().octree().root_page()}, page);
  try {
    reader->read({RecordKind::octree_page, OctreeLayout::page_id(3, {9, 9, 9})}, page);
    FAIL() << "read a page outside the octree";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::not_found);
    EXPECT_NE(std::string(e.what()).find("octree page depth 3 (9, 9, 9)"), std::string::npos) << e.what();
  }
}

TEST(Octree, BadOptionsAndStoresAreRefusedNamingWhatIsWrong) {
  testing::TempDir dir;
  OctreeBuildOptions negative;
  negative.tolerance = -1;
  EXPECT_THROW(build_octree(dir.file("nothing"), negative), Error);
  OctreeBuildOptions inverted;
  inverted.clamp = std::pair{2.0, 1.0};
  try {
    build_octree(dir.file("nothing"), inverted);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--range"), std::string::npos) << e.what();
  }
  try {
    build_octree(dir.file("nothing"), {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::not_found);
  }
}

}  // namespace
}  // namespace brickyard
