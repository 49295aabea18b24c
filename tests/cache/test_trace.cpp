#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "cache/policy.h"
#include "cache/trace.h"
#include "core/error.h"
#include "test_util.h"

namespace brickyard {
namespace {

Trace sample_trace() {
  Trace t;
  t.records = {{7, 0, 100, AccessKind::demand, 1, 0},  {9, 0, 200, AccessKind::prefetch_request, 0, 1},
               {7, 1, 100, AccessKind::blocking, 3, 0}, {9, 1, 200, AccessKind::prefetch_fill, 2, 1},
               {5, 2, 50, AccessKind::demand, 0, 2},    {7, 2, 100, AccessKind::demand, 1, 0}};
  return t;
}

TEST(Trace, BrickyardFormatRoundTripsEveryField) {
  testing::TempDir dir;
  const Trace t = sample_trace();
  write_trace(dir.file("t.bytrace"), t, TraceFormat::brickyard);
  EXPECT_EQ(std::filesystem::file_size(dir.file("t.bytrace")), 16u + 24u * t.records.size());
  const Trace back = read_trace(dir.file("t.bytrace"));
  ASSERT_EQ(back.records.size(), t.records.size());
  for (size_t i = 0; i < t.records.size(); ++i) {
    EXPECT_EQ(back.records[i].key, t.records[i].key);
    EXPECT_EQ(back.records[i].frame, t.records[i].frame);
    EXPECT_EQ(back.records[i].size, t.records[i].size);
    EXPECT_EQ(back.records[i].kind, t.records[i].kind);
    EXPECT_EQ(back.records[i].hit_level, t.records[i].hit_level);
    EXPECT_EQ(back.records[i].thread, t.records[i].thread);
  }
  EXPECT_EQ(back.unique_objects(), 3u);
  EXPECT_EQ(back.unique_bytes(), 350u);
  EXPECT_EQ(back.frames(), 3u);
}

TEST(Trace, OracleGeneralCarriesNextAccessTimes) {
  testing::TempDir dir;
  const Trace t = sample_trace();
  write_trace(dir.file("t.oracleGeneral"), t, TraceFormat::oracle_general);
  const std::string bytes = testing::read_file(dir.file("t.oracleGeneral"));
  ASSERT_EQ(bytes.size(), 24u * t.records.size());
  auto field = [&](size_t record, size_t offset, auto value) {
    std::memcpy(&value, bytes.data() + record * 24 + offset, sizeof value);
    return value;
  };
  EXPECT_EQ(field(0, 4, uint64_t{}), 7u);
  EXPECT_EQ(field(0, 12, uint32_t{}), 100u);
  EXPECT_EQ(field(0, 16, int64_t{}), 2);   // object 7 is next demanded at record 2
  EXPECT_EQ(field(2, 16, int64_t{}), 5);
  EXPECT_EQ(field(5, 16, int64_t{}), -1);  // never again
  EXPECT_EQ(field(1, 16, int64_t{}), -1);  // 9 is never demanded
  const Trace back = read_trace(dir.file("t.oracleGeneral"));
  ASSERT_EQ(back.records.size(), t.records.size());
  EXPECT_EQ(back.records[4].key, 5u);
  EXPECT_EQ(back.records[4].size, 50u);
  const auto next = next_demand_access(t);
  EXPECT_EQ(next[0], 2u);
  EXPECT_EQ(next[5], kNoNextAccess);
}

TEST(Trace, OptsFutureEndsWhereAnObjectChangesSize) {
  Trace t;
  t.records = {{1, 0, 4}, {1, 0, 4, AccessKind::prefetch_fill}, {1, 0, 4}, {1, 0, 6, AccessKind::prefetch_fill},
               {1, 0, 6}, {1, 0, 8}, {1, 0, 6}};
  const auto next = next_demand_access(t);
  // A fill of the copy's size leaves it to serve record 2; the fill at size 6 replaces it; the
  // request at size 8 (record 5) replaces record 4's copy, which record 6, at 6 again, cannot use.
  const std::vector<uint64_t> expected = {2, 2, kNoNextAccess, 4, kNoNextAccess, kNoNextAccess, kNoNextAccess};
  EXPECT_EQ(next, expected);
  EXPECT_EQ(t.unique_bytes(), 8u);  // the object at its largest size
  // oracleGeneral keeps libCacheSim's meaning: the next request, whatever its size.
  testing::TempDir dir;
  write_trace(dir.file("t.oracleGeneral"), t, TraceFormat::oracle_general);
  const std::string bytes = testing::read_file(dir.file("t.oracleGeneral"));
  ASSERT_EQ(bytes.size(), 24u * t.records.size());
  int64_t field = 0;
  std::memcpy(&field, bytes.data() + 2 * 24 + 16, sizeof field);
  EXPECT_EQ(field, 4);
  std::memcpy(&field, bytes.data() + 4 * 24 + 16, sizeof field);
  EXPECT_EQ(field, 5);
}

TEST(Trace, TextFormatReadsKeyAndOptionalSize) {
  testing::TempDir dir;
  std::ofstream(dir.file("t.txt")) << "# key size\n12 4096\n0x10 8\n\n12   # size defaults to 1\n";
  const Trace t = read_trace(dir.file("t.txt"));
  ASSERT_EQ(t.records.size(), 3u);
  EXPECT_EQ(t.records[0].key, 12u);
  EXPECT_EQ(t.records[0].size, 4096u);
  EXPECT_EQ(t.records[1].key, 16u);
  EXPECT_EQ(t.records[2].size, 1u);
  write_trace(dir.file("o.txt"), t, TraceFormat::text);
  EXPECT_EQ(testing::read_file(dir.file("o.txt")), "12 4096\n16 8\n12 1\n");
}

void expect_format_error(const std::string& path, const std::string& text) {
  try {
    read_trace(path);
    FAIL() << "accepted " << path;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format) << e.what();
    EXPECT_EQ(e.file(), path);
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

TEST(Trace, MalformedFilesAreFormatErrors) {
  testing::TempDir dir;
  write_trace(dir.file("t.bytrace"), sample_trace(), TraceFormat::brickyard);
  std::filesystem::resize_file(dir.file("t.bytrace"), 16 + 24 * 3 + 5);
  expect_format_error(dir.file("t.bytrace"), "header says 6 records");
  std::ofstream(dir.file("x.bytrace")) << "garbage";
  expect_format_error(dir.file("x.bytrace"), "no BYTRACE1 magic");
  std::ofstream(dir.file("y.oracleGeneral")) << std::string(30, 'x');
  expect_format_error(dir.file("y.oracleGeneral"), "not a whole number of 24-byte");
  std::ofstream(dir.file("z.txt")) << "1 2\nthree 4\n";
  expect_format_error(dir.file("z.txt"), "line 2");
  std::ofstream(dir.file("w.txt")) << "1 2 3\n";
  expect_format_error(dir.file("w.txt"), "line 1: unknown record kind '3'");
  std::ofstream(dir.file("v.txt")) << "1 2 tet_cluster 4\n";
  expect_format_error(dir.file("v.txt"), "unexpected '4'");
  EXPECT_THROW(read_trace(dir.file("absent.bytrace")), Error);
}

// Found by fuzzing (tests/fuzz/regressions/trace_bytrace/): a record count of 2^61 makes
// 16 + count * 24 wrap to 16, the size of a header alone, and reserve() threw a bare
// std::length_error.
TEST(Trace, ARecordCountThatOverflowsTheFileSizeIsAFormatError) {
  testing::TempDir dir;
  std::ofstream(dir.file("forged.bytrace"), std::ios::binary) << std::string("BYTRACE1\0\0\0\0\0\0\0\x20", 16);
  expect_format_error(dir.file("forged.bytrace"), "header says 2305843009213693952 records (more than 2^64 bytes)");
}

TEST(Trace, SyntheticGeneratorsHaveTheirShape) {
  const Trace z = zipf_trace(100, 50000, 1.0, 1);
  std::map<uint64_t, int> counts;
  for (const auto& r : z.records) counts[r.key]++;
  std::vector<int> sorted;
  for (const auto& [k, c] : counts) sorted.push_back(c);
  std::sort(sorted.rbegin(), sorted.rend());
  // Rank 1 is about twice as popular as rank 2 for alpha = 1 (H_100 normalisation).
  EXPECT_NEAR(double(sorted[0]) / double(sorted[1]), 2.0, 0.25);
  EXPECT_NEAR(double(sorted[0]) / 50000.0, 1.0 / 5.187, 0.02);
  const Trace s = scan_trace(10, 3);
  EXPECT_EQ(s.unique_objects(), 30u);
  const Trace l = loop_trace(10, 3);
  EXPECT_EQ(l.unique_objects(), 10u);
  EXPECT_EQ(l.records.size(), 30u);
}

}  // namespace
}  // namespace brickyard
