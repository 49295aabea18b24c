// Grids of several time steps: a store built from one source a step holds, at each step, exactly
// the store of that step's volume alone (records, node table, value range), under keys that
// carry the step; the steps must be one grid; an octree volume is refused.

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "builder_test_util.h"
#include "core/error.h"
#include "fields/grid.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "storage/lmdb_env.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

const char* const kStepFields[] = {"sphere", "torus", "gyroid"};

/// Every record of one time step, for comparing against a one-step store.
std::vector<std::pair<uint64_t, std::vector<std::byte>>> step_records(const Store& store, int step) {
  std::vector<std::pair<uint64_t, std::vector<std::byte>>> out;
  auto txn = store.begin_read();
  store.for_each_step_record(txn, [&](int s, const BrickKey& k, std::span<const std::byte> r) {
    if (s == step) out.emplace_back(k.code(), std::vector<std::byte>(r.begin(), r.end()));
    return true;
  });
  return out;
}

struct Series {
  std::vector<std::unique_ptr<VolumeSource>> owned;
  std::vector<VolumeSource*> steps;
};

Series field_series(const Vec3s& dims, ValueType type) {
  Series s;
  for (const char* f : kStepFields) s.owned.push_back(make_field_source(make_field(f), dims, type));
  for (const auto& o : s.owned) s.steps.push_back(o.get());
  return s;
}

TEST(TimeSeries, EachStepIsExactlyTheStoreOfItsVolumeAlone) {
  const Vec3s dims{37, 29, 45};
  for (ValueType type : {ValueType::u8, ValueType::i16, ValueType::f32}) {
    SCOPED_TRACE(to_string(type));
    testing::TempDir dir;
    BuildOptions o;
    o.brick_size = 8;
    Series series = field_series(dims, type);
    const BuildResult r = build_series(series.steps, dir.file("series"), o);
    EXPECT_EQ(r.manifest.time_steps, 3);
    const Store store(dir.file("series"));
    EXPECT_EQ(store.time_steps(), 3);
    EXPECT_EQ(store.manifest().format_version, kTimeSeriesGridFormatVersion);
    ASSERT_EQ(store.manifest().step_ranges.size(), 3u);
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    uint64_t voxels = 0;
    std::vector<LevelStats> sum(size_t(store.layout().levels));
    for (int k = 0; k < 3; ++k) {
      SCOPED_TRACE(kStepFields[k]);
      const std::string alone = dir.file(fmt::format("alone{}", k));
      build_store(*make_field_source(make_field(kStepFields[k]), dims, type), alone, o);
      const Store one(alone);
      EXPECT_TRUE(step_records(store, k) == testing::all_records(one)) << "records differ";
      for (int l = 0; l < one.layout().levels; ++l) EXPECT_TRUE(store.nodes(k).level(l) == one.nodes().level(l)) << l;
      EXPECT_EQ(store.manifest().step_ranges[size_t(k)], (StepValueRange{one.manifest().min_value, one.manifest().max_value}));
      EXPECT_EQ(&store.dataset(k).grid().nodes(), &store.nodes(k));
      // Read through the step's page source, as a cache over that step reads.
      const auto reader = store.step_pages(k).open_reader();
      std::vector<std::byte> a(store.format().bytes()), b(a.size());
      for (int64_t i = 0; i < store.layout().brick_count(store.layout().finest()); ++i) {
        const BrickKey key = store.layout().key_at(store.layout().finest(), i);
        reader->read({RecordKind::brick, key.code()}, a);
        one.read_brick(key, b);
        ASSERT_TRUE(a == b) << key.to_string();
      }
      lo = std::min(lo, one.manifest().min_value), hi = std::max(hi, one.manifest().max_value);
      voxels += one.manifest().histogram.total();
      for (size_t l = 0; l < sum.size(); ++l) {
        sum[l].bricks += one.manifest().stats[l].bricks, sum[l].constant += one.manifest().stats[l].constant;
        sum[l].stored_bytes += one.manifest().stats[l].stored_bytes;
      }
    }
    EXPECT_EQ(store.manifest().min_value, lo);
    EXPECT_EQ(store.manifest().max_value, hi);
    EXPECT_EQ(store.dataset(2).info().min_value, lo) << "every step's dataset has the whole series' range";
    EXPECT_EQ(store.manifest().histogram.total(), voxels);
    for (size_t l = 0; l < sum.size(); ++l) {
      EXPECT_EQ(store.manifest().stats[l].bricks, sum[l].bricks);
      EXPECT_EQ(store.manifest().stats[l].constant, sum[l].constant);
      EXPECT_EQ(store.manifest().stats[l].stored_bytes, sum[l].stored_bytes);
    }
    try {
      (void)store.dataset(3);
      ADD_FAILURE() << "time step 3 of 3";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument);
      EXPECT_EQ(e.field(), "time_step");
      EXPECT_NE(std::string(e.what()).find("time step 3 of a dataset with 3 (0 to 2)"), std::string::npos) << e.what();
    }
  }
}

TEST(TimeSeries, AStepsNodeTableIsReadWhenThatStepIsFirstAskedForAndADamagedOneIsNamed) {
  testing::TempDir dir;
  BuildOptions o;
  o.brick_size = 8;
  Series series = field_series({20, 20, 20}, ValueType::u8);
  build_series(series.steps, dir.file("s"), o);
  {
    // Step 2's first node-table chunk overwritten: [step 2][level 0][chunk 0], big-endian.
    lmdb::Env env(dir.file("s"), {});
    const auto db = env.open_database("nodes", false);
    lmdb::BatchWriter w(env);
    std::vector<std::byte> key(12, std::byte{0});
    key[3] = std::byte{2};
    w.put(db, key, std::vector<std::byte>(24, std::byte{0x5a}));
    w.commit();
  }
  const Store store(dir.file("s"));  // opens: only step 0's table is read at open
  EXPECT_NO_THROW((void)store.dataset(1));
  try {
    (void)store.dataset(2);
    ADD_FAILURE() << "a damaged node table of step 2 was read";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::corrupt);
    EXPECT_NE(std::string(e.what()).find("node table chunk 0 of level 0 of time step 2"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)store.nodes(2), Error) << "asked again, it fails again";
}

TEST(TimeSeries, AOneStepStoreIsWrittenAsBefore) {
  testing::TempDir dir;
  BuildOptions o;
  o.brick_size = 8;
  Series one;
  one.owned.push_back(make_field_source(make_field("torus"), {20, 20, 20}, ValueType::u8));
  one.steps.push_back(one.owned.front().get());
  build_series(one.steps, dir.file("s"), o);
  const Store store(dir.file("s"));
  EXPECT_EQ(store.manifest().format_version, kGridStoreFormatVersion) << "older builds keep reading one-step grids";
  EXPECT_TRUE(store.manifest().step_ranges.empty());
  EXPECT_EQ(store.manifest().to_json().find("step_value_ranges"), std::string::npos);
  EXPECT_EQ(&store.step_pages(0), static_cast<const PageSource*>(&store));
}

TEST(TimeSeries, StepsOfAnotherShapeOrTypeAreRefusedNamingTheStep) {
  testing::TempDir dir;
  for (const auto& [dims, type, what] :
       {std::tuple{Vec3s{20, 20, 21}, ValueType::u8, "time step 2 is 20x20x21 voxels"},
        std::tuple{Vec3s{20, 20, 20}, ValueType::u16, "time step 2 holds u16 values"}}) {
    Series s = field_series({20, 20, 20}, ValueType::u8);
    s.owned[2] = make_field_source(make_field("gyroid"), dims, type);
    s.steps[2] = s.owned[2].get();
    try {
      build_series(s.steps, dir.file("s"), BuildOptions{});
      ADD_FAILURE() << what;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::format);
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("every time step must be the same grid"), std::string::npos) << e.what();
    }
    EXPECT_EQ(probe_store(dir.file("s")), StoreState::absent) << "refused before anything is written";
  }
}

TEST(TimeSeries, AnOctreeVolumeIsRefusedForSeveralSteps) {
  testing::TempDir dir;
  Series s = field_series({16, 16, 16}, ValueType::u8);
  BuildOptions o;
  o.octree = OctreeBuildOptions{};
  try {
    build_series(s.steps, dir.file("s"), o);
    ADD_FAILURE() << "built an octree over several time steps";
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "--octree");
  }
  EXPECT_EQ(probe_store(dir.file("s")), StoreState::absent);
}

}  // namespace
}  // namespace brickyard
