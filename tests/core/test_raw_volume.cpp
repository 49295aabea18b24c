#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/raw_volume.h"
#include "test_util.h"

namespace brickyard {
namespace {

RawVolumeInfo sample_info() {
  RawVolumeInfo info;
  info.dims = {4, 5, 6};
  info.type = ValueType::u16;
  info.spacing = {0.5, 0.25, 2.0};
  info.origin = {-1, 0, 1};
  info.min_value = 3;
  info.max_value = 65000;
  info.quantization = {{-1.0, 2.0}};
  info.source = "field test";
  info.source_params = {{"seed", 7.0}};
  info.bytes = 4 * 5 * 6 * 2;
  info.xxh3_64 = 0x0123456789abcdefull;
  return info;
}

TEST(RawSidecar, RoundTripsEveryField) {
  testing::TempDir dir;
  const std::string path = dir.file("v.raw.json");
  const RawVolumeInfo info = sample_info();
  write_raw_sidecar(path, info);
  const RawVolumeInfo back = read_raw_sidecar(path);
  EXPECT_EQ(back.dims, info.dims);
  EXPECT_EQ(back.type, info.type);
  EXPECT_TRUE(back.little_endian);
  EXPECT_EQ(back.spacing, info.spacing);
  EXPECT_EQ(back.origin, info.origin);
  EXPECT_EQ(back.min_value, 3);
  EXPECT_EQ(back.max_value, 65000);
  EXPECT_EQ(back.quantization, info.quantization);
  EXPECT_EQ(back.source, "field test");
  EXPECT_EQ(back.source_params, info.source_params);
  EXPECT_EQ(back.bytes, info.bytes);
  EXPECT_EQ(back.xxh3_64, info.xxh3_64);
  EXPECT_EQ(raw_sidecar_path("a/b.raw"), "a/b.raw.json");
}

// Writes the sample sidecar with one key replaced (or removed, when value is empty).
std::string sidecar_with(const testing::TempDir& dir, const std::string& key, const std::string& value) {
  const std::string path = dir.file("edit.json");
  write_raw_sidecar(path, sample_info());
  nlohmann::json j = nlohmann::json::parse(testing::read_file(path));
  if (value.empty()) j.erase(key);
  else j[key] = nlohmann::json::parse(value);
  std::ofstream(path) << j.dump(2);
  return path;
}

void expect_error_names(const std::string& path, const std::string& field, Errc code) {
  try {
    read_raw_sidecar(path);
    FAIL() << "no error for field " << field;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_EQ(e.file(), path);
    EXPECT_EQ(e.field(), field) << e.what();
  }
}

TEST(RawSidecar, BadContentNamesTheKey) {
  testing::TempDir dir;
  expect_error_names(sidecar_with(dir, "dims", ""), "dims", Errc::format);
  expect_error_names(sidecar_with(dir, "dims", "[4, 5]"), "dims", Errc::format);
  expect_error_names(sidecar_with(dir, "dims", "[4, 0, 6]"), "dims", Errc::format);
  expect_error_names(sidecar_with(dir, "dims", "\"big\""), "dims", Errc::format);
  expect_error_names(sidecar_with(dir, "type", "\"f64\""), "type", Errc::format);
  expect_error_names(sidecar_with(dir, "endianness", "\"middle\""), "endianness", Errc::format);
  expect_error_names(sidecar_with(dir, "bytes", "239"), "bytes", Errc::format);
  expect_error_names(sidecar_with(dir, "brickyard_raw", "99"), "brickyard_raw", Errc::unsupported);
  expect_error_names(sidecar_with(dir, "dims", "[4000000000, 4000000000, 4000000000]"), "dims", Errc::format);
  expect_error_names(sidecar_with(dir, "xxh3_64", "\"xyz\""), "xxh3_64", Errc::format);
  expect_error_names(sidecar_with(dir, "spacing", "[1, 0, 1]"), "spacing", Errc::format);
  expect_error_names(sidecar_with(dir, "spacing", "[1, -2, 1]"), "spacing", Errc::format);
  expect_error_names(sidecar_with(dir, "source_params", "{\"seed\": \"five\"}"), "source_params.seed", Errc::format);
  // A key this build does not know (a typo, or a newer writer's) is named, not ignored.
  expect_error_names(sidecar_with(dir, "spacings", "[1, 1, 1]"), "spacings", Errc::format);
}

TEST(RawSidecar, LargeExponentsAreFormatErrors) {
  testing::TempDir dir;
  const std::string path = dir.file("huge.json");
  std::ofstream(path) << "{\"brickyard_raw\": 1, \"dims\": [1e999, 1, 1]}";
  try {
    read_raw_sidecar(path);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.file(), path);
  }
}

TEST(Spacing, OnlyPositiveFiniteDistancesPlaceAGrid) {
  EXPECT_EQ(spacing_problem({1, 0.5, 2e-9}), "");
  for (const Vec3d s : {Vec3d(0, 1, 1), Vec3d(1, -1, 1), Vec3d(1, 1, std::nan("")), Vec3d(1, INFINITY, 1)})
    EXPECT_NE(spacing_problem(s).find("positive, finite"), std::string::npos) << s.x << " " << s.y << " " << s.z;
}

// Found by fuzzing (tests/fuzz/regressions/raw_sidecar/): numbers that do not fit their key's
// type were converted with undefined behaviour, and a source parameter that is not a number
// escaped as nlohmann's type_error.
TEST(RawSidecar, NumbersThatDoNotFitAndWrongTypesNameTheKey) {
  testing::TempDir dir;
  expect_error_names(sidecar_with(dir, "dims", "[2e30, 5, 6]"), "dims", Errc::format);
  expect_error_names(sidecar_with(dir, "dims", "[4.5, 5, 6]"), "dims", Errc::format);
  expect_error_names(sidecar_with(dir, "brickyard_raw", "1e10"), "brickyard_raw", Errc::format);
  expect_error_names(sidecar_with(dir, "bytes", "-3.5e30"), "bytes", Errc::format);
  expect_error_names(sidecar_with(dir, "bytes", "-240"), "bytes", Errc::format);
  expect_error_names(sidecar_with(dir, "source_params", "{\"seed\": \"seven\"}"), "source_params.seed", Errc::format);
  expect_error_names(sidecar_with(dir, "quantization", "[0, 1]"), "quantization", Errc::format);
  for (const char* hex : {"\"-1\"", "\" ff\"", "\"0x1f\"", "\"12\\u00003\"", "\"00000000000000001\""})
    expect_error_names(sidecar_with(dir, "xxh3_64", hex), "xxh3_64", Errc::format);
  try {
    read_raw_sidecar(sidecar_with(dir, "dims", "[2e30, 5, 6]"));
  } catch (const Error& e) {
    EXPECT_NE(e.message().find("expected an array, each element an integer,"), std::string::npos) << e.what();
  }
  // Integral numbers written as floats still read.
  const RawVolumeInfo info = read_raw_sidecar(sidecar_with(dir, "dims", "[4.0, 5, 6e0]"));
  EXPECT_EQ(info.dims, Vec3s(4, 5, 6));
}

TEST(RawSidecar, MalformedJsonIsAFormatError) {
  testing::TempDir dir;
  const std::string path = dir.file("bad.json");
  std::ofstream(path) << "{ \"dims\": [1, 2, ";
  try {
    read_raw_sidecar(path);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.file(), path);
  }
  EXPECT_THROW(read_raw_sidecar(dir.file("absent.json")), Error);
  // Found by fuzzing: nlohmann's out_of_range for a number beyond the double range escaped.
  const std::string big = dir.file("big.json");
  write_raw_sidecar(big, sample_info());
  std::string text = testing::read_file(big);
  text.insert(text.find('{') + 1, "\"spacing\": [1e400, 1, 1], ");
  std::ofstream(big) << text;
  try {
    read_raw_sidecar(big);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.file(), big);
    EXPECT_NE(e.message().find("number overflow"), std::string::npos) << e.what();
  }
}

TEST(GridBytes, RejectsEmptyAndOverflowingGrids) {
  EXPECT_EQ(checked_grid_bytes({256, 256, 256}, ValueType::f32), uint64_t(256) * 256 * 256 * 4);
  EXPECT_FALSE(checked_grid_bytes({0, 256, 256}, ValueType::u8));
  EXPECT_FALSE(checked_grid_bytes({1 << 22, 1 << 22, 1 << 22}, ValueType::f32));
  EXPECT_FALSE(checked_grid_bytes({int64_t(1) << 40, int64_t(1) << 40, 1}, ValueType::u8));
}

}  // namespace
}  // namespace brickyard
