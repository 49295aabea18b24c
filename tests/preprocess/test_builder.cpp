#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>

#include <tbb/task_arena.h>

#include "builder_test_util.h"
#include "core/error.h"
#include "core/raw_volume.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "storage/lmdb_env.h"
#include "storage/store.h"
#include "storage/store_lock.h"
#include "test_util.h"

namespace brickyard {
namespace {

using testing::Grid;

BuildOptions small_bricks(int m = 8, int apron = 1) {
  BuildOptions o;
  o.brick_size = m;
  o.apron = apron;
  return o;
}

template <typename T>
void expect_pyramid_matches(const std::string& field_name, const Vec3s& dims, const BuildOptions& options) {
  testing::TempDir dir;
  auto field = make_field(field_name);
  auto source = make_field_source(make_field(field_name), dims, ValueTypeOf<T>::value);
  build_store(*source, dir.file("s"), options);
  Store store(dir.file("s"));
  Grid<T> expected = testing::sample<T>(*field, dims);
  for (int level = store.layout().finest(); level >= 0; --level) {
    const Grid<T> got = testing::read_level<T>(store, level);
    ASSERT_EQ(got.dims, expected.dims) << "level " << level;
    ASSERT_TRUE(got.v == expected.v) << field_name << " level " << level << " differs from the reference pyramid";
    if (level > 0) expected = testing::halve(expected);
  }
}

TEST(Builder, EveryLevelEqualsTheReferencePyramid) {
  expect_pyramid_matches<uint8_t>("sphere", {40, 37, 29}, small_bricks());
  expect_pyramid_matches<uint16_t>("gyroid", {33, 16, 17}, small_bricks(16, 2));
  expect_pyramid_matches<int8_t>("fbm", {27, 19, 21}, small_bricks());
  expect_pyramid_matches<int16_t>("marschner-lobb", {33, 16, 17}, small_bricks(16, 2));
  expect_pyramid_matches<float>("marschner-lobb", {24, 24, 24}, small_bricks(8, 0));
}

TEST(Builder, ApronsReplicateNeighboursAndNodeRangesCoverTrilinearCells) {
  testing::TempDir dir;
  const Vec3s dims{30, 21, 19};
  auto source = make_field_source(make_field("fbm"), dims, ValueType::u16);
  build_store(*source, dir.file("s"), small_bricks(8, 2));
  Store store(dir.file("s"));
  const GridLayout& l = store.layout();
  const BrickFormat& f = store.format();
  std::vector<std::byte> buffer(f.bytes());
  for (int level = 0; level < l.levels; ++level) {
    const Grid<uint16_t> g = testing::read_level<uint16_t>(store, level);
    for (int64_t i = 0; i < l.brick_count(level); ++i) {
      const BrickKey k = l.key_at(level, i);
      store.read_brick(k, buffer);
      const auto* v = reinterpret_cast<const uint16_t*>(buffer.data());
      const int e = f.edge(), m = f.brick_size, a = f.apron;
      for (int z = 0; z < e; ++z)
        for (int y = 0; y < e; ++y)
          for (int x = 0; x < e; ++x)
            ASSERT_EQ(v[(z * e + y) * e + x],
                      g.at(int64_t(k.x) * m - a + x, int64_t(k.y) * m - a + y, int64_t(k.z) * m - a + z))
                << k << " at " << x << "," << y << "," << z;
      // Node range: over voxels [b*M, (b+1)*M] clamped to the level, forward neighbours included.
      uint16_t lo = 65535, hi = 0;
      const int64_t bx = k.x, by = k.y, bz = k.z;
      for (int64_t z = bz * m; z <= std::min<int64_t>((bz + 1) * m, g.dims.z - 1); ++z)
        for (int64_t y = by * m; y <= std::min<int64_t>((by + 1) * m, g.dims.y - 1); ++y)
          for (int64_t x = bx * m; x <= std::min<int64_t>((bx + 1) * m, g.dims.x - 1); ++x) {
            lo = std::min(lo, g.at(x, y, z));
            hi = std::max(hi, g.at(x, y, z));
          }
      EXPECT_EQ(store.nodes().at(k).min, lo) << k;
      EXPECT_EQ(store.nodes().at(k).max, hi) << k;
    }
  }
}

TEST(Builder, ConstantBricksHaveNoPayloadAndBackgroundOnesAreEmpty) {
  testing::TempDir dir;
  auto source = make_field_source(make_field("sparse-blobs"), {64, 64, 64}, ValueType::u8);
  const BuildResult r = build_store(*source, dir.file("s"), small_bricks());
  Store store(dir.file("s"));
  const GridLayout& l = store.layout();
  auto txn = store.begin_read();
  int64_t constant = 0, empty = 0, stored = 0;
  for (int64_t i = 0; i < l.brick_count(l.finest()); ++i) {
    const BrickKey k = l.key_at(l.finest(), i);
    const NodeRecord& n = store.nodes().at(k);
    EXPECT_TRUE(n.flags & kNodeFinest);
    EXPECT_FALSE(n.flags & kNodeHasChildren);
    if (n.is_constant()) {
      ++constant;
      EXPECT_FALSE(store.record(txn, k).has_value()) << k;
      EXPECT_EQ(n.min, n.constant);
      EXPECT_EQ(n.max, n.constant);
      if (n.is_empty()) {
        ++empty;
        EXPECT_EQ(n.constant, 0.0f);
      }
    } else {
      ++stored;
      EXPECT_TRUE(store.record(txn, k).has_value()) << k;
    }
  }
  EXPECT_GT(empty, l.brick_count(l.finest()) / 2);  // mostly empty space
  EXPECT_GT(stored, 0);
  EXPECT_EQ(r.manifest.stats[size_t(l.finest())].constant, constant);
  EXPECT_EQ(r.manifest.stats[size_t(l.finest())].empty, empty);
  EXPECT_EQ(store.record_count(), uint64_t(l.total_bricks() - [&] {
              int64_t c = 0;
              for (const auto& s : r.manifest.stats) c += s.constant;
              return c;
            }()));
}

// Found by fuzzing (tests/fuzz/regressions/node_table/): a node table chunk without its
// checksum (as stores written before checksums have) was trusted whole, and read_brick converted
// a constant of -1.7e38 to u16 with undefined behaviour. The store now refuses such a table at
// open, naming the brick.
TEST(Builder, AStoreWhoseNodeTableHoldsWhatNoBuildWritesIsCorrupt) {
  testing::TempDir dir;
  auto source = make_field_source(make_field("sphere"), {20, 20, 20}, ValueType::u16);
  build_store(*source, dir.file("s"), small_bricks());
  std::vector<NodeRecord> level0;
  {
    const Store store(dir.file("s"));
    level0 = store.nodes().level(0);
  }
  auto open_with = [&](NodeRecord node) -> std::string {
    std::vector<NodeRecord> records = level0;
    records[0] = node;
    {
      lmdb::Env env(dir.file("s"), {});
      const lmdb::Database nodes = env.open_database(kNodesDb, false);
      lmdb::BatchWriter writer(env);
      const std::vector<std::byte> key(8, std::byte{0});  // level 0, chunk 0, without a checksum
      writer.put(nodes, key, lmdb::Bytes(reinterpret_cast<const std::byte*>(records.data()), records.size() * sizeof(NodeRecord)));
      writer.commit();
    }
    try {
      const Store store(dir.file("s"));
      return "";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::corrupt) << e.what();
      EXPECT_EQ(e.file(), dir.file("s"));
      EXPECT_EQ(e.key(), "L0 (0, 0, 0)");
      return e.message();
    }
  };
  EXPECT_EQ(open_with(level0[0]), "");  // unchecked but sound: read as before
  EXPECT_EQ(open_with({0, 1, -1.7e38f, kNodeConstant | kNodeHasChildren}),
            "the node table gives the brick the constant value -1.7e+38, which is not a u16 value (a whole number in [0, 65535])");
  EXPECT_NE(open_with({0, 1, 2.5f, kNodeConstant | kNodeHasChildren}).find("constant value 2.5"), std::string::npos);
  EXPECT_EQ(open_with({NAN, 1, 0, kNodeHasChildren}), "the node table gives the brick the value range [nan, 1]");
  EXPECT_EQ(open_with({2, 1, 0, kNodeHasChildren}), "the node table gives the brick the value range [2, 1]");
}

TEST(Builder, ManifestDescribesTheVolume) {
  testing::TempDir dir;
  auto field = make_field("sphere");
  auto source = make_field_source(make_field("sphere"), {50, 40, 30}, ValueType::u8);
  const BuildResult r = build_store(*source, dir.file("s"), small_bricks(16));
  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_TRUE(m.complete);
  EXPECT_EQ(m.dims, Vec3s(50, 40, 30));
  EXPECT_EQ(m.levels, 3);
  EXPECT_EQ(m.format.brick_size, 16);
  const Grid<uint8_t> g = testing::sample<uint8_t>(*field, {50, 40, 30});
  EXPECT_EQ(m.min_value, *std::min_element(g.v.begin(), g.v.end()));
  EXPECT_EQ(m.max_value, *std::max_element(g.v.begin(), g.v.end()));
  EXPECT_EQ(m.histogram.total(), uint64_t(50 * 40 * 30));
  EXPECT_EQ(m.histogram.counts.size(), 256u);
  EXPECT_EQ(m.spacing, GridSampler(*field, {50, 40, 30}, ValueType::u8).spacing());
  EXPECT_NE(m.source.find("\"field\":\"sphere\""), std::string::npos) << m.source;
  EXPECT_NE(m.build.find("\"brick_size\":16"), std::string::npos) << m.build;
  EXPECT_EQ(r.manifest.to_json(), m.to_json());
}

TEST(Builder, RawFileRoundTripsBitExactlyThroughTheStore) {
  testing::TempDir dir;
  auto field = make_field("torus");
  GridSampler sampler(*field, {45, 23, 31}, ValueType::u16);
  const RawVolumeInfo info = write_raw_grid(sampler, dir.file("t.raw"));
  RawFileSpec spec;
  spec.dims = info.dims;
  spec.type = element_type(info.type);
  auto source = open_raw_source(dir.file("t.raw"), spec);
  build_store(*source, dir.file("s"), small_bricks(16));
  Store store(dir.file("s"));
  const RawVolumeInfo out = export_raw(store, store.layout().finest(), export_region(store, store.layout().finest(), {}),
                                       dir.file("back.raw"));
  EXPECT_EQ(testing::read_file(dir.file("back.raw")), testing::read_file(dir.file("t.raw")));
  EXPECT_EQ(out.xxh3_64, info.xxh3_64);
  // A box of the finest level equals the same box cut from the source.
  const VoxelBox box{{3, 4, 5}, {40, 9, 30}};
  export_raw(store, store.layout().finest(), export_region(store, store.layout().finest(), box), dir.file("box.raw"));
  const std::string all = testing::read_file(dir.file("t.raw")), part = testing::read_file(dir.file("box.raw"));
  ASSERT_EQ(part.size(), size_t(37 * 5 * 25 * 2));
  size_t at = 0;
  for (int64_t z = 5; z < 30; ++z)
    for (int64_t y = 4; y < 9; ++y, at += 37 * 2) EXPECT_EQ(part.substr(at, 74), all.substr(size_t(((z * 23 + y) * 45 + 3) * 2), 74));
  EXPECT_THROW(export_region(store, 0, VoxelBox{{0, 0, 0}, {100, 1, 1}}), Error);
  EXPECT_THROW(export_region(store, 9, std::nullopt), Error);
}

TEST(Builder, BigEndianRawAndHeaderBytesAreHonoured) {
  testing::TempDir dir;
  const Vec3s dims{9, 8, 7};
  std::string bytes = "HEADER--";
  std::vector<uint16_t> values;
  for (int i = 0; i < 9 * 8 * 7; ++i) {
    values.push_back(uint16_t(i * 97));
    bytes += char(values.back() >> 8);
    bytes += char(values.back() & 0xff);
  }
  std::ofstream(dir.file("be.raw"), std::ios::binary) << bytes;
  RawFileSpec spec;
  spec.dims = dims;
  spec.type = ElementType::u16;
  spec.little_endian = false;
  spec.header_bytes = 8;
  auto source = open_raw_source(dir.file("be.raw"), spec);
  build_store(*source, dir.file("s"), small_bricks());
  const Grid<uint16_t> g = testing::read_level<uint16_t>(Store(dir.file("s")), 1);
  EXPECT_EQ(g.v, values);
}

TEST(Builder, OptionsChangeEncodingButNotDecodedData) {
  auto build = [](const BuildOptions& o, testing::TempDir& dir) {
    auto source = make_field_source(make_field("marschner-lobb"), {33, 33, 33}, ValueType::f32);
    build_store(*source, dir.file("s"), o);
    return testing::read_level<float>(Store(dir.file("s")), 2).v;
  };
  testing::TempDir a, b, c;
  BuildOptions hc = small_bricks(16);
  hc.codec = Codec::lz4hc;
  BuildOptions plain = small_bricks(16);
  plain.shuffle = false;
  const auto reference = build(small_bricks(16), a);
  EXPECT_EQ(build(hc, b), reference);
  EXPECT_EQ(build(plain, c), reference);
}

TEST(Builder, MinAndMaxFiltersPreserveExtremes) {
  testing::TempDir dir;
  BuildOptions o = small_bricks();
  o.downsample = Downsample::max;
  auto field = make_field("menger", {{"levels", 3}});
  auto source = make_field_source(make_field("menger", {{"levels", 3}}), {27, 27, 27}, ValueType::u8);
  build_store(*source, dir.file("s"), o);
  Store store(dir.file("s"));
  const Grid<uint8_t> fine = testing::read_level<uint8_t>(store, store.layout().finest());
  const Grid<uint8_t> coarse = testing::read_level<uint8_t>(store, store.layout().finest() - 1);
  for (int64_t z = 0; z < coarse.dims.z; ++z)
    for (int64_t y = 0; y < coarse.dims.y; ++y)
      for (int64_t x = 0; x < coarse.dims.x; ++x) {
        uint8_t m = 0;
        for (int d = 0; d < 8; ++d)
          m = std::max(m, fine.at(std::min(2 * x + (d & 1), fine.dims.x - 1), std::min(2 * y + ((d >> 1) & 1), fine.dims.y - 1),
                                  std::min(2 * z + (d >> 2), fine.dims.z - 1)));
        ASSERT_EQ(coarse.at(x, y, z), m);
      }
}

TEST(Builder, ClampRangeAndConstantTolerance) {
  testing::TempDir dir;
  BuildOptions o = small_bricks();
  o.clamp = {{100.0, 150.0}};
  auto source = make_field_source(make_field("sphere"), {32, 32, 32}, ValueType::u8);
  const BuildResult r = build_store(*source, dir.file("s"), o);
  EXPECT_GE(r.manifest.min_value, 100);
  EXPECT_LE(r.manifest.max_value, 150);

  BuildOptions loose = small_bricks();
  loose.constant_tolerance = 255;
  auto source2 = make_field_source(make_field("sphere"), {32, 32, 32}, ValueType::u8);
  build_store(*source2, dir.file("t"), loose);
  EXPECT_EQ(Store(dir.file("t")).record_count(), 0u);  // everything within tolerance
}

TEST(Builder, WarnsOfValueRangesSinglePrecisionHandlesBadly) {
  // The build succeeds, and says what the renderers will make of such values.
  EXPECT_TRUE(value_range_warnings(-1e30, 1e30).empty());
  EXPECT_TRUE(value_range_warnings(0, 0).empty());
  EXPECT_TRUE(value_range_warnings(-1e-30, 1e-30).empty());
  const std::vector<std::string> huge = value_range_warnings(-0.6 * double(FLT_MAX), 0.1);
  ASSERT_EQ(huge.size(), 1u);
  EXPECT_NE(huge[0].find("within a factor of 2 of the largest float"), std::string::npos) << huge[0];
  EXPECT_EQ(value_range_warnings(0, 0.5 * double(FLT_MAX)).size(), 1u);
  const std::vector<std::string> tiny = value_range_warnings(-1e-40, 2e-40);
  ASSERT_EQ(tiny.size(), 1u);
  EXPECT_NE(tiny[0].find("denormal"), std::string::npos) << tiny[0];
  // Through a build: the values of a store reach them.
  testing::TempDir dir;
  auto source = make_field_source(make_field("sphere"), {9, 9, 9}, ValueType::f32);
  EXPECT_TRUE(build_store(*source, dir.file("plain.store"), {}).warnings.empty());
}

TEST(Builder, ResultDoesNotDependOnThreadCount) {
  testing::TempDir dir;
  auto build = [&](int threads, const std::string& name) {
    tbb::task_arena(threads).execute([&] {
      auto source = make_field_source(make_field("fbm"), {48, 40, 36}, ValueType::u16);
      build_store(*source, dir.file(name), small_bricks());
    });
    return testing::all_records(Store(dir.file(name)));
  };
  EXPECT_TRUE(build(1, "one") == build(2, "two"));
}

class FailingSource final : public VolumeSource {
 public:
  explicit FailingSource(int64_t fail_at) : inner_(make_field_source(make_field("fbm"), {40, 40, 40}, ValueType::u8)), fail_at_(fail_at) {}
  std::string name() const override { return "failing"; }
  Vec3s dims() const override { return inner_->dims(); }
  Vec3d spacing() const override { return inner_->spacing(); }
  Vec3d origin() const override { return inner_->origin(); }
  ValueType type() const override { return inner_->type(); }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    if (z0 >= fail_at_) throw Error(Errc::io, "simulated read failure").with_file("failing");
    inner_->read_slab(z0, z1, out);
  }
  std::string describe_json() const override { return inner_->describe_json(); }

 private:
  std::unique_ptr<VolumeSource> inner_;
  int64_t fail_at_;
};

TEST(Builder, AnInterruptedBuildIsIncompleteAndTheNextRunRebuildsIdentically) {
  testing::TempDir dir;
  const std::string s = dir.file("s");
  FailingSource failing(25);
  EXPECT_THROW(build_store(failing, s, small_bricks()), Error);
  EXPECT_EQ(probe_store(s), StoreState::incomplete);
  try {
    Store store(s);
    FAIL() << "opened an incomplete store";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("incomplete"), std::string::npos) << e.what();
  }
  FailingSource healthy(1 << 30);
  const BuildResult r = build_store(healthy, s, small_bricks());
  EXPECT_TRUE(r.rebuilt_incomplete);
  auto source = make_field_source(make_field("fbm"), {40, 40, 40}, ValueType::u8);
  build_store(*source, dir.file("clean"), small_bricks());
  EXPECT_TRUE(testing::all_records(Store(s)) == testing::all_records(Store(dir.file("clean"))));
  EXPECT_EQ(Store(s).manifest().to_json(), Store(dir.file("clean")).manifest().to_json());
}

TEST(Builder, RerunsAreIdempotentAndDifferentParametersNeedForce) {
  testing::TempDir dir;
  const std::string s = dir.file("s");
  auto run = [&](BuildOptions o) {
    auto source = make_field_source(make_field("sphere"), {20, 20, 20}, ValueType::u8);
    return build_store(*source, s, o);
  };
  EXPECT_FALSE(run(small_bricks()).up_to_date);
  EXPECT_TRUE(run(small_bricks()).up_to_date);
  BuildOptions other = small_bricks(16);
  EXPECT_THROW(run(other), Error);
  other.force = true;
  const BuildResult r = run(other);
  EXPECT_FALSE(r.up_to_date);
  EXPECT_EQ(Store(s).format().brick_size, 16);
}

/// What a rebuild may leave beside the store `s` in `dir`: nothing, once it has finished.
void expect_nothing_beside(const testing::TempDir& dir) {
  for (const char* sibling : {".s.lock", ".s.rebuilding", ".s.replaced"})
    EXPECT_FALSE(std::filesystem::exists(dir.file(sibling))) << sibling << " left behind";
}

TEST(Builder, AForcedRebuildThatFailsLeavesTheOldStoreAsItWas) {
  testing::TempDir dir;
  const std::string s = dir.file("s");
  auto sphere = make_field_source(make_field("sphere"), {20, 20, 20}, ValueType::u8);
  build_store(*sphere, s, small_bricks());
  const auto records = testing::all_records(Store(s));
  const std::string manifest = Store(s).manifest().to_json();

  BuildOptions force = small_bricks();
  force.force = true;
  FailingSource failing(25);  // another source: only --force rebuilds over the sphere
  EXPECT_THROW(build_store(failing, s, force), Error);
  EXPECT_EQ(probe_store(s), StoreState::complete);
  EXPECT_TRUE(testing::all_records(Store(s)) == records);
  EXPECT_EQ(Store(s).manifest().to_json(), manifest);
  expect_nothing_beside(dir);
}

TEST(Builder, AForcedRebuildReplacesTheStore) {
  testing::TempDir dir;
  const std::string s = dir.file("s");
  auto sphere = make_field_source(make_field("sphere"), {20, 20, 20}, ValueType::u8);
  build_store(*sphere, s, small_bricks());

  BuildOptions other = small_bricks(16);
  other.force = true;
  auto again = make_field_source(make_field("sphere"), {20, 20, 20}, ValueType::u8);
  const BuildResult r = build_store(*again, s, other);
  EXPECT_FALSE(r.up_to_date);
  EXPECT_FALSE(r.rebuilt_incomplete);
  EXPECT_EQ(Store(s).format().brick_size, 16);
  auto clean = make_field_source(make_field("sphere"), {20, 20, 20}, ValueType::u8);
  build_store(*clean, dir.file("clean"), small_bricks(16));
  EXPECT_TRUE(testing::all_records(Store(s)) == testing::all_records(Store(dir.file("clean"))));
  expect_nothing_beside(dir);
}

TEST(Builder, ASecondWriterIsRefusedAndDoesNotDiscardTheLiveBuild) {
  testing::TempDir dir;
  const std::string s = dir.file("s");
  FailingSource failing(25);
  EXPECT_THROW(build_store(failing, s, small_bricks()), Error);
  ASSERT_EQ(probe_store(s), StoreState::incomplete);
  {
    // Another process's build in progress, as this store's writer sees it: locked and incomplete.
    const StoreWriteLock live(s);
    FailingSource healthy(1 << 30);
    try {
      build_store(healthy, s, small_bricks());
      FAIL() << "a second writer built over a live build";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("another writer"), std::string::npos) << e.what();
    }
    EXPECT_EQ(probe_store(s), StoreState::incomplete);
  }
  FailingSource healthy(1 << 30);
  EXPECT_TRUE(build_store(healthy, s, small_bricks()).rebuilt_incomplete);  // no writer: it was interrupted
  EXPECT_EQ(probe_store(s), StoreState::complete);
}

TEST(Builder, TheNextWriterReclaimsWhatAKilledRebuildLeftBeside) {
  testing::TempDir dir;
  const std::string s = dir.file("s");
  auto build = [&](const std::string& where, int brick_size) {
    auto source = make_field_source(make_field("sphere"), {20, 20, 20}, ValueType::u8);
    return build_store(*source, where, small_bricks(brick_size));
  };
  // Killed while rebuilding: the old store in place, half a rebuild beside it.
  build(s, 8);
  FailingSource failing(25);
  EXPECT_THROW(build_store(failing, store_sibling(s, "rebuilding"), small_bricks()), Error);
  EXPECT_TRUE(build(s, 8).up_to_date);
  expect_nothing_beside(dir);

  // Killed between the two renames of a swap without an atomic exchange, before the second:
  // the old store aside, a complete rebuild beside, nothing in place. The rebuild goes in.
  std::filesystem::rename(s, store_sibling(s, "replaced"));
  build(store_sibling(s, "rebuilding"), 16);
  EXPECT_TRUE(build(s, 16).up_to_date);
  EXPECT_EQ(Store(s).format().brick_size, 16);
  expect_nothing_beside(dir);

  // The same kill with the rebuild unfinished: the old store goes back.
  std::filesystem::rename(s, store_sibling(s, "replaced"));
  EXPECT_THROW(build_store(failing, store_sibling(s, "rebuilding"), small_bricks()), Error);
  EXPECT_TRUE(build(s, 16).up_to_date);
  expect_nothing_beside(dir);
}

TEST(Builder, RefusesToDeleteADirectoryBesideTheStoreThatIsNotOne) {
  testing::TempDir dir;
  const std::string s = dir.file("s");
  std::filesystem::create_directories(store_sibling(s, "rebuilding"));
  std::ofstream(store_sibling(s, "rebuilding") + "/thesis.tex") << "do not delete";
  auto source = make_field_source(make_field("sphere"), {8, 8, 8}, ValueType::u8);
  EXPECT_THROW(build_store(*source, s, small_bricks()), Error);
  EXPECT_TRUE(std::filesystem::exists(store_sibling(s, "rebuilding") + "/thesis.tex"));
}

TEST(Builder, EstimatesItsMemoryAndAnUpperBoundOfItsDiskFromTheLayout) {
  // 64^3 u8 in 32^3 bricks with a 1-voxel apron: levels of 32^3 (1 brick) and 64^3 (8 bricks).
  // A brick record at LZ4's bound: 64 + 34^3 + 34^3/255 + 16 = 39538 bytes, on 10 pages of 4 KiB.
  const ResourceNeeds small = estimate_build_needs({64, 64, 64}, ValueType::u8, BuildOptions{}, 1);
  EXPECT_EQ(small.disk.bytes, uint64_t((9 * 40960 + 9 * 16) * 9 / 8));
  const uint64_t rings = 34 * (32 * 32 + 64 * 64), row = 4 * 39538;
  EXPECT_GE(small.memory.bytes, rings + row);
  EXPECT_LT(small.memory.bytes, 2 * (rings + row) + 9 * 40960);  // no fixed 96 MiB for 9 bricks' worth of data

  // The cases: far beyond any disk, or any memory, and each said so.
  const ResourceNeeds u8 = estimate_build_needs({8192, 8192, 8192}, ValueType::u8, BuildOptions{}, 16);
  EXPECT_GT(u8.disk.bytes, uint64_t(512) << 30);  // at least the raw grid
  EXPECT_LT(u8.memory.bytes, uint64_t(16) << 30);
  const ResourceNeeds f32 = estimate_build_needs({100000, 100000, 100000}, ValueType::f32, BuildOptions{}, 16);
  EXPECT_GT(f32.memory.bytes, uint64_t(1) << 40);  // 34 slices of 40 GB
  EXPECT_EQ(f32.task, "import of 100000x100000x100000 f32");
  // Smaller bricks hold fewer slices and a thinner row of bricks, and more nodes: here the
  // slices weigh more, and the message says which way to go.
  BuildOptions small_bricks16;
  small_bricks16.brick_size = 16;
  EXPECT_LT(estimate_build_needs({8192, 8192, 8192}, ValueType::u8, small_bricks16, 16).memory.bytes, u8.memory.bytes);
  EXPECT_NE(u8.memory.lower.find("a smaller --brick-size"), std::string::npos) << u8.memory.lower;
}

/// Sets an environment variable for the scope of a test.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) { ::setenv(name, value, 1); }
  ~ScopedEnv() { ::unsetenv(name_); }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  const char* name_;
};

TEST(Builder, RefusesABuildThatCannotFitBeforeItReadsTheSource) {
  testing::TempDir dir;
  const ScopedEnv small_disk("BRICKYARD_AVAILABLE_DISK", "64KiB");
  FailingSource never_read(0);  // any read fails: the refusal must come first
  try {
    build_store(never_read, dir.file("s"), small_bricks());
    FAIL() << "a 40^3 store fitted in 64 KiB of disk";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::resource) << e.what();
    EXPECT_NE(std::string(e.what()).find("of disk"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir.file("s")));
  BuildOptions unchecked = small_bricks();
  unchecked.check_disk = false;
  FailingSource healthy(1 << 30);
  EXPECT_NO_THROW(build_store(healthy, dir.file("s"), unchecked));
}

TEST(Builder, RefusesToOverwriteSomethingThatIsNotAStore) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir.file("precious"));
  std::ofstream(dir.file("precious/thesis.tex")) << "do not delete";
  auto source = make_field_source(make_field("sphere"), {8, 8, 8}, ValueType::u8);
  EXPECT_THROW(build_store(*source, dir.file("precious"), small_bricks()), Error);
  EXPECT_TRUE(std::filesystem::exists(dir.file("precious/thesis.tex")));
}

TEST(Builder, AFullMapWithoutGrowthFailsAndLeavesAnIncompleteStore) {
  testing::TempDir dir;
  BuildOptions o = small_bricks();
  o.map_size = 512 << 10;
  o.map_growth = false;
  o.batch_bytes = 64 << 10;
  auto source = make_field_source(make_field("fbm"), {96, 96, 96}, ValueType::f32);
  try {
    build_store(*source, dir.file("s"), o);
    FAIL() << "a 3.4 MB volume fitted in 512 KiB";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::resource);
    EXPECT_NE(std::string(e.what()).find("store is full"), std::string::npos) << e.what();
  }
  EXPECT_EQ(probe_store(dir.file("s")), StoreState::incomplete);
}

}  // namespace
}  // namespace brickyard
