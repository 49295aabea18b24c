#include <gtest/gtest.h>

#include <xxhash.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <set>
#include <vector>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include "core/error.h"
#include "core/raw_volume.h"
#include "fields/field.h"
#include "fields/grid.h"
#include "test_util.h"

namespace brickyard {
namespace {

std::vector<std::byte> whole_grid(const GridSampler& s) {
  std::vector<std::byte> out(size_t(s.dims().z) * s.slice_bytes());
  s.sample_slab(0, s.dims().z, out);
  return out;
}

TEST(GridSampler, VertexCentredOnTheDomain) {
  auto f = make_field("marschner-lobb");
  GridSampler s(*f, {41, 41, 1}, ValueType::f32);
  EXPECT_EQ(s.position(0, 0, 0), Vec3d(-1, -1, 0));  // 1-sample axis: the domain centre
  EXPECT_EQ(s.position(40, 40, 0), Vec3d(1, 1, 0));
  EXPECT_DOUBLE_EQ(s.spacing().x, 0.05);
  EXPECT_DOUBLE_EQ(s.position(20, 0, 0).x, 0.0);
  EXPECT_THROW(GridSampler(*f, {0, 4, 4}, ValueType::u8), Error);
}

TEST(GridSampler, FloatGridHoldsTheAnalyticValues) {
  auto f = make_field("marschner-lobb");
  GridSampler s(*f, {24, 17, 9}, ValueType::f32);
  const auto bytes = whole_grid(s);
  const float* v = reinterpret_cast<const float*>(bytes.data());
  for (int64_t k = 0; k < 9; ++k)
    for (int64_t j = 0; j < 17; ++j)
      for (int64_t i = 0; i < 24; ++i) {
        const Vec3d p = s.position(i, j, k);
        ASSERT_EQ(v[(k * 17 + j) * 24 + i], static_cast<float>(f->value(p))) << i << "," << j << "," << k;
      }
}

TEST(GridSampler, IntegerGridsQuantiseWithinHalfAStep) {
  auto f = make_field("gyroid");
  for (ValueType t : {ValueType::u8, ValueType::u16}) {
    GridSampler s(*f, {16, 16, 16}, t);
    const auto bytes = whole_grid(s);
    const double step = (f->range().hi - f->range().lo) / integer_max(t);
    for (int64_t n = 0; n < 16 * 16 * 16; ++n) {
      const int64_t i = n % 16, j = (n / 16) % 16, k = n / 256;
      const double stored = t == ValueType::u8 ? double(reinterpret_cast<const uint8_t*>(bytes.data())[n])
                                               : double(reinterpret_cast<const uint16_t*>(bytes.data())[n]);
      EXPECT_LE(std::abs(dequantize(stored, t, f->range()) - f->value(s.position(i, j, k))), step / 2 + 1e-12);
    }
  }
}

TEST(GridSampler, IntegerValuedFieldsAreStoredAsTheyAreWhereTheTypeHoldsThem) {
  auto f = make_field("shepp-logan");  // integers in [-1000, 1000]
  GridSampler s(*f, {20, 20, 20}, ValueType::i16);
  EXPECT_TRUE(s.stores_values_as_is());
  EXPECT_EQ(s.quantization().lo, -32768.0);
  EXPECT_EQ(s.quantization().hi, 32767.0);
  const auto bytes = whole_grid(s);
  const int16_t* v = reinterpret_cast<const int16_t*>(bytes.data());
  std::set<int> seen;
  for (int64_t n = 0; n < 20 * 20 * 20; ++n) {
    const Vec3d p = s.position(n % 20, (n / 20) % 20, n / 400);
    ASSERT_EQ(double(v[n]), f->value(p)) << n;
    seen.insert(v[n]);
  }
  EXPECT_TRUE(seen.count(-1000) && seen.count(20) && seen.count(1000));
  // Types that cannot hold [-1000, 1000] quantise the range as for any field.
  for (ValueType t : {ValueType::u8, ValueType::i8, ValueType::u16, ValueType::f32}) {
    GridSampler q(*f, {4, 4, 4}, t);
    EXPECT_FALSE(q.stores_values_as_is()) << to_string(t);
    EXPECT_EQ(q.quantization().lo, -1000.0);
  }
  // A field that is not integer-valued is quantised even where its range would fit.
  EXPECT_FALSE(GridSampler(*make_field("gyroid"), {4, 4, 4}, ValueType::i16).stores_values_as_is());
}

TEST(Quantize, ClampsOutOfRangeAndNaN) {
  const ValueRange r{-1, 1};
  EXPECT_EQ(quantize<uint8_t>(-1, r), 0);
  EXPECT_EQ(quantize<uint8_t>(1, r), 255);
  EXPECT_EQ(quantize<uint8_t>(7, r), 255);
  EXPECT_EQ(quantize<uint8_t>(-7, r), 0);
  EXPECT_EQ(quantize<uint8_t>(NAN, r), 0);
  EXPECT_EQ(quantize<uint16_t>(0, r), 32768);  // 32767.5 rounds up
  EXPECT_EQ(quantize<float>(0.25, r), 0.25f);
}

TEST(GridSampler, SlabStreamingEqualsWholeGridGeneration) {
  for (const char* name : {"fbm", "sparse-blobs", "torus"})
    for (ValueType t : {ValueType::u8, ValueType::u16, ValueType::f32}) {
      auto f = make_field(name);
      GridSampler s(*f, {19, 23, 29}, t);
      const auto whole = whole_grid(s);
      for (int64_t slab : {1, 3, 7, 29, 100}) {
        std::vector<std::byte> streamed;
        int64_t expect_z = 0;
        stream_grid(s, slab, [&](int64_t z0, int64_t z1, std::span<const std::byte> bytes) {
          EXPECT_EQ(z0, expect_z);
          EXPECT_EQ(bytes.size(), size_t(z1 - z0) * s.slice_bytes());
          expect_z = z1;
          streamed.insert(streamed.end(), bytes.begin(), bytes.end());
        });
        EXPECT_EQ(expect_z, 29);
        EXPECT_TRUE(streamed == whole) << name << " " << to_string(t) << " slab " << slab;
      }
    }
}

TEST(GridSampler, ResultDoesNotDependOnThreadCount) {
  auto f = make_field("fbm");
  GridSampler s(*f, {64, 32, 16}, ValueType::f32);
  std::vector<std::byte> one, many;
  tbb::task_arena(1).execute([&] { one = whole_grid(s); });
  tbb::task_arena(4).execute([&] { many = whole_grid(s); });
  EXPECT_TRUE(one == many);
}

TEST(RawGrid, WritesFileAndSidecarWithChecksumAndRange) {
  testing::TempDir dir;
  auto f = make_field("sphere");
  GridSampler s(*f, {20, 21, 22}, ValueType::u16);
  const std::string path = dir.file("sphere.raw");
  const RawVolumeInfo info = write_raw_grid(s, path);
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
  const std::string data = testing::read_file(path);
  ASSERT_EQ(data.size(), size_t(20 * 21 * 22 * 2));
  EXPECT_EQ(data, std::string(reinterpret_cast<const char*>(whole_grid(s).data()), data.size()));

  const RawVolumeInfo back = read_raw_sidecar(raw_sidecar_path(path));
  EXPECT_EQ(back.dims, Vec3s(20, 21, 22));
  EXPECT_EQ(back.type, ValueType::u16);
  EXPECT_EQ(back.bytes, data.size());
  EXPECT_EQ(back.xxh3_64, XXH3_64bits(data.data(), data.size()));
  EXPECT_EQ(back.spacing, s.spacing());
  EXPECT_EQ(back.source, "field sphere");
  ASSERT_TRUE(back.quantization.has_value());
  EXPECT_EQ(back.quantization->first, f->range().lo);
  uint16_t lo = 65535, hi = 0;
  for (size_t i = 0; i < data.size(); i += 2) {
    uint16_t v;
    std::memcpy(&v, data.data() + i, 2);
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  EXPECT_EQ(back.min_value, lo);
  EXPECT_EQ(back.max_value, hi);
  EXPECT_EQ(info.xxh3_64, back.xxh3_64);
}

TEST(RawGrid, FailureLeavesNothingBehind) {
  testing::TempDir dir;
  auto f = make_field("sphere");
  GridSampler s(*f, {8, 8, 8}, ValueType::u8);
  const std::string path = dir.file("no-such-dir/x.raw");
  EXPECT_THROW(write_raw_grid(s, path), Error);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

}  // namespace
}  // namespace brickyard
