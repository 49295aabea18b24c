// Resumable imports: a build killed after a checkpoint resumes from it when run again, and ends
// identical, record for record and in its manifest, to a build that was never interrupted.

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <fcntl.h>
#include <sys/stat.h>
#include <limits>
#include <memory>
#include <string>

#include "builder_test_util.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "core/raw_volume.h"
#include "fields/grid.h"
#include "storage/lmdb_env.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

/// A field's grid whose reads fail from slice `stop_at` on (as a kill would stop the build),
/// once it has been rewound `passes` times (the pre-passes before the build's), optionally as a
/// stream that cannot skip (as a gzip file). Its provenance is the field's, so the healthy
/// source of the same field resumes its build.
class Interrupted final : public VolumeSource {
 public:
  Interrupted(const std::string& field, const Vec3s& dims, ValueType type, int64_t stop_at, bool stream = false,
              int passes = 0)
      : inner_(make_field_source(make_field(field), dims, type)), stop_at_(stop_at), passes_(passes), stream_(stream) {}
  std::string name() const override { return "interrupted"; }
  Vec3s dims() const override { return inner_->dims(); }
  ValueType type() const override { return inner_->type(); }
  Vec3d spacing() const override { return inner_->spacing(); }
  Vec3d origin() const override { return inner_->origin(); }
  std::optional<ValueRange> value_range_hint() const override { return inner_->value_range_hint(); }
  bool may_contain_nonfinite() const override { return inner_->may_contain_nonfinite(); }
  bool can_skip() const override { return !stream_; }
  void rewind() override { next_ = 0, ++rewinds_; }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    if (z0 >= stop_at_ && rewinds_ >= passes_) throw Error(Errc::io, "killed");
    if (stream_ && z0 != next_) throw Error(Errc::internal, "a stream read out of order");
    next_ = z1;
    ++reads_;
    inner_->read_slab(z0, z1, out);
  }
  std::string describe_json() const override { return inner_->describe_json(); }
  int64_t reads() const { return reads_; }

 private:
  std::unique_ptr<VolumeSource> inner_;
  int64_t stop_at_, next_ = 0, reads_ = 0;
  int passes_, rewinds_ = 0;
  bool stream_;
};

BuildOptions every_row(int m = 8, int apron = 1) {
  BuildOptions o;
  o.brick_size = m;
  o.apron = apron;
  o.checkpoint_seconds = 0;  // a checkpoint after every finest row of bricks
  return o;
}

struct Case {
  const char* field;
  ValueType type;
  int brick, apron;
};

void expect_same_store(const std::string& a, const std::string& b) {
  EXPECT_TRUE(testing::all_records(Store(a)) == testing::all_records(Store(b)));
  EXPECT_EQ(Store(a).manifest().to_json(), Store(b).manifest().to_json());
  EXPECT_TRUE(Store(a).nodes().level(0) == Store(b).nodes().level(0));
}

/// A raw file's source, counting its content checks, that fails reading from slice `stop_at`.
class CountingRaw final : public VolumeSource {
 public:
  CountingRaw(const std::string& path, int64_t stop_at, int& checks) : stop_at_(stop_at), checks_(checks) {
    const RawVolumeInfo info = read_raw_sidecar(path + ".json");
    RawFileSpec spec;
    spec.dims = info.dims;
    spec.type = element_type(info.type);
    spec.xxh3_64 = info.xxh3_64;
    inner_ = open_raw_source(path, spec);
  }
  std::string name() const override { return inner_->name(); }
  Vec3s dims() const override { return inner_->dims(); }
  ValueType type() const override { return inner_->type(); }
  void verify_content() override { ++checks_, inner_->verify_content(); }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    if (z0 >= stop_at_) throw Error(Errc::io, "killed");
    inner_->read_slab(z0, z1, out);
  }
  std::string describe_json() const override { return inner_->describe_json(); }

 private:
  std::unique_ptr<VolumeSource> inner_;
  int64_t stop_at_;
  int& checks_;
};

TEST(Resume, ARerunOfAnUnchangedCheckedFileDoesNotHashItAgain) {
  testing::TempDir dir;
  const std::string raw = dir.file("g.raw"), store = dir.file("s");
  write_raw_grid(GridSampler(*make_field("gyroid"), {24, 20, 40}, ValueType::u8), raw);
  const int64_t never = std::numeric_limits<int64_t>::max();
  int checks = 0;
  const BuildOptions o = every_row();
  // Killed, then resumed: the file was checked before the kill and has not changed.
  CountingRaw killed(raw, 21, checks);
  EXPECT_THROW(build_store(killed, store, o), Error);
  EXPECT_EQ(checks, 1);
  CountingRaw rest(raw, never, checks);
  EXPECT_GT(build_store(rest, store, o).resumed_at_slice, 0);
  EXPECT_EQ(checks, 1) << "the resumed build hashed the file again";
  // Up to date: not hashed either.
  EXPECT_TRUE(build_store(*std::make_unique<CountingRaw>(raw, never, checks), store, o).up_to_date);
  EXPECT_EQ(checks, 1);
  // Touched (a new modification time, the same bytes): hashed, and still up to date.
  struct stat st {};
  ASSERT_EQ(::stat(raw.c_str(), &st), 0);
  const timespec later[2] = {st.st_atim, {st.st_mtim.tv_sec + 10, st.st_mtim.tv_nsec}};
  ASSERT_EQ(::utimensat(AT_FDCWD, raw.c_str(), later, 0), 0);
  EXPECT_TRUE(build_store(*std::make_unique<CountingRaw>(raw, never, checks), store, o).up_to_date);
  EXPECT_EQ(checks, 2);
  // Rewritten (new bytes, a new time): the check names the checksum, and the store stays.
  {
    std::fstream f(raw, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(100);
    f.put(char(7));
  }
  const timespec latest[2] = {st.st_atim, {st.st_mtim.tv_sec + 20, st.st_mtim.tv_nsec}};
  ASSERT_EQ(::utimensat(AT_FDCWD, raw.c_str(), latest, 0), 0);
  try {
    build_store(*std::make_unique<CountingRaw>(raw, never, checks), store, o);
    ADD_FAILURE() << "a rewritten file was taken for its sidecar's";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("xxh3_64"), std::string::npos) << e.what();
  }
  EXPECT_EQ(probe_store(store), StoreState::complete);
}

TEST(Resume, AKilledBuildResumesFromItsLastCheckpointAndEqualsAnUninterruptedOne) {
  const Vec3s dims{37, 29, 45};
  for (const Case& c : {Case{"fbm", ValueType::u8, 8, 1}, Case{"gyroid", ValueType::i16, 8, 2},
                        Case{"marschner-lobb", ValueType::f32, 16, 1}, Case{"sphere", ValueType::u16, 8, 0}}) {
    testing::TempDir dir;
    BuildOptions o = every_row(c.brick, c.apron);
    build_store(*make_field_source(make_field(c.field), dims, c.type), dir.file("clean"), o);
    for (int64_t stop : {int64_t(c.brick + 3), int64_t(2 * c.brick + 5), dims.z - 2}) {
      SCOPED_TRACE(fmt::format("{} {} killed at slice {}", c.field, to_string(c.type), stop));
      const std::string s = dir.file(fmt::format("s{}", stop));
      Interrupted killed(c.field, dims, c.type, stop);
      EXPECT_THROW(build_store(killed, s, o), Error);
      EXPECT_EQ(probe_store(s), StoreState::incomplete);
      ASSERT_TRUE(read_build_checkpoint(s).has_value());
      Interrupted rest(c.field, dims, c.type, std::numeric_limits<int64_t>::max());
      const BuildResult r = build_store(rest, s, o);
      EXPECT_FALSE(r.rebuilt_incomplete);
      // Resumed after the last finest row written before the kill: (rows) * M + max(A, 1).
      const int64_t forward = std::max(c.apron, 1);
      const int64_t rows_before = (stop - forward) / c.brick;
      EXPECT_EQ(r.resumed_at_slice, rows_before * c.brick + forward);
      EXPECT_EQ(rest.reads(), dims.z - r.resumed_at_slice) << "slices read again";
      expect_same_store(s, dir.file("clean"));
      EXPECT_FALSE(read_build_checkpoint(s).has_value()) << "a complete store keeps no checkpoint";
    }
  }
}

TEST(Resume, AStreamThatCannotSkipIsReadUpToWhereTheBuildStopped) {
  testing::TempDir dir;
  const Vec3s dims{20, 18, 40};
  build_store(*make_field_source(make_field("torus"), dims, ValueType::u8), dir.file("clean"), every_row());
  Interrupted killed("torus", dims, ValueType::u8, 30, /*stream=*/true);
  EXPECT_THROW(build_store(killed, dir.file("s"), every_row()), Error);
  Interrupted rest("torus", dims, ValueType::u8, 1000, /*stream=*/true);
  EXPECT_GT(build_store(rest, dir.file("s"), every_row()).resumed_at_slice, 0);
  EXPECT_EQ(rest.reads(), dims.z);
  expect_same_store(dir.file("s"), dir.file("clean"));
}

TEST(Resume, PrePassesAndAnAutomaticBackgroundComeFromTheCheckpoint) {
  testing::TempDir dir;
  const Vec3s dims{24, 24, 40};
  BuildOptions o = every_row();
  o.background_auto = true;
  o.constant_tolerance = 0.05;
  build_store(*make_field_source(make_field("sparse-blobs"), dims, ValueType::f32), dir.file("clean"), o);
  Interrupted killed("sparse-blobs", dims, ValueType::f32, 27, false, /*passes=*/1);  // after the border scan
  EXPECT_THROW(build_store(killed, dir.file("s"), o), Error);
  Interrupted rest("sparse-blobs", dims, ValueType::f32, 1000);
  const BuildResult r = build_store(rest, dir.file("s"), o);
  EXPECT_EQ(r.resumed_at_slice, 25);
  EXPECT_EQ(rest.reads(), dims.z - 25) << "no pre-pass and no border scan again";
  expect_same_store(dir.file("s"), dir.file("clean"));
}

TEST(Resume, AnotherImportOrAnUnreadableCheckpointStartsOver) {
  testing::TempDir dir;
  const Vec3s dims{20, 20, 40};
  BuildOptions o = every_row();
  Interrupted killed("fbm", dims, ValueType::u8, 30);
  EXPECT_THROW(build_store(killed, dir.file("s"), o), Error);
  // Other parameters: the checkpoint is not of this import.
  BuildOptions other = o;
  other.downsample = Downsample::max;
  Interrupted rest("fbm", dims, ValueType::u8, 1000);
  BuildResult r = build_store(rest, dir.file("s"), other);
  EXPECT_TRUE(r.rebuilt_incomplete);
  EXPECT_EQ(r.resumed_at_slice, 0);
  build_store(*make_field_source(make_field("fbm"), dims, ValueType::u8), dir.file("clean"), other);
  expect_same_store(dir.file("s"), dir.file("clean"));

  // A checkpoint that fails its checksum.
  Interrupted again("fbm", dims, ValueType::u8, 30);
  EXPECT_THROW(build_store(again, dir.file("t"), o), Error);
  {
    lmdb::Env env(dir.file("t"), {});
    const auto db = env.open_database("manifest", false);
    lmdb::BatchWriter w(env);
    std::vector<std::byte> garbage(64, std::byte{0x5a});
    w.put(db, lmdb::as_bytes(std::string("build.checkpoint")), std::move(garbage));
    w.commit();
  }
  EXPECT_FALSE(read_build_checkpoint(dir.file("t")).has_value());
  r = build_store(rest, dir.file("t"), o);
  EXPECT_TRUE(r.rebuilt_incomplete);
  build_store(*make_field_source(make_field("fbm"), dims, ValueType::u8), dir.file("clean-o"), o);
  expect_same_store(dir.file("t"), dir.file("clean-o"));
}

TEST(Resume, ASeriesKilledInALaterStepResumesThereWithoutReadingTheStepsBefore) {
  const Vec3s dims{24, 20, 40};
  const char* const fields[] = {"sphere", "torus", "gyroid"};
  const int64_t never = std::numeric_limits<int64_t>::max();
  testing::TempDir dir;
  const BuildOptions o = every_row();
  {
    std::vector<std::unique_ptr<VolumeSource>> owned;
    std::vector<VolumeSource*> steps;
    for (const char* f : fields) owned.push_back(make_field_source(make_field(f), dims, ValueType::u16)), steps.push_back(owned.back().get());
    build_series(steps, dir.file("clean"), o);
  }
  // Killed inside step 1 (after some of its rows), then inside step 2 at its first slice (the
  // checkpoint between steps 1 and 2 is the last), each time resumed where it stopped.
  for (const auto& [killed_step, stop, resumed_step, resumed_slice] :
       {std::tuple{1, int64_t(21), 1, int64_t(17)}, std::tuple{2, int64_t(0), 2, int64_t(0)}}) {
    SCOPED_TRACE(fmt::format("killed in step {} at slice {}", killed_step, stop));
    const std::string s = dir.file(fmt::format("s{}", killed_step));
    std::vector<std::unique_ptr<Interrupted>> first, second;
    for (int k = 0; k < 3; ++k) first.push_back(std::make_unique<Interrupted>(fields[k], dims, ValueType::u16, k == killed_step ? stop : never));
    std::vector<VolumeSource*> steps;
    for (auto& p : first) steps.push_back(p.get());
    EXPECT_THROW(build_series(steps, s, o), Error);
    EXPECT_EQ(probe_store(s), StoreState::incomplete);
    EXPECT_TRUE(read_manifest(s).step_ranges.empty()) << "an interrupted series has no ranges yet; none are invented";
    EXPECT_EQ(read_manifest(s).to_json().find("step_value_ranges"), std::string::npos);
    steps.clear();
    for (int k = 0; k < 3; ++k) second.push_back(std::make_unique<Interrupted>(fields[k], dims, ValueType::u16, never)), steps.push_back(second.back().get());
    const BuildResult r = build_series(steps, s, o);
    EXPECT_FALSE(r.rebuilt_incomplete);
    EXPECT_EQ(r.resumed_at_step, resumed_step);
    EXPECT_EQ(r.resumed_at_slice, resumed_slice);
    for (int k = 0; k < resumed_step; ++k) EXPECT_EQ(second[size_t(k)]->reads(), 0) << "step " << k << " read again";
    EXPECT_EQ(second[size_t(resumed_step)]->reads(), dims.z - resumed_slice);
    const Store a(s), b(dir.file("clean"));
    EXPECT_TRUE(testing::all_records(a) == testing::all_records(b));
    EXPECT_EQ(a.manifest().to_json(), b.manifest().to_json());
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < a.layout().levels; ++l) EXPECT_TRUE(a.nodes(k).level(l) == b.nodes(k).level(l)) << k << " " << l;
    EXPECT_FALSE(read_build_checkpoint(s).has_value());
  }
}

}  // namespace
}  // namespace brickyard
