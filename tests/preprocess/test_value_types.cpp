// Value types end to end through the build: every stored type round-trips bit-exactly, fields
// quantise onto the signed ranges, 32-bit integers and doubles convert to f32 with what the
// conversion did measured before the build, and a background (given or found on the border)
// makes noisy empty space empty while the data stays exact.

#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <vector>

#include "builder_test_util.h"
#include "core/error.h"
#include "core/raw_volume.h"
#include "preprocess/background.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

BuildOptions small_bricks() {
  BuildOptions o;
  o.brick_size = 8;
  return o;
}

template <typename T>
std::string bytes_of(const std::vector<T>& v, bool big_endian = false) {
  std::string s(v.size() * sizeof(T), '\0');
  std::memcpy(s.data(), v.data(), s.size());
  if (big_endian)
    for (size_t i = 0; i < v.size(); ++i) std::reverse(s.begin() + long(i * sizeof(T)), s.begin() + long((i + 1) * sizeof(T)));
  return s;
}

void write(const std::string& path, const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; }

std::unique_ptr<VolumeSource> raw(const std::string& path, const Vec3s& dims, ElementType type,
                                  ConvertOptions convert = {}, bool little_endian = true) {
  RawFileSpec spec;
  spec.dims = dims;
  spec.type = type;
  spec.convert = convert;
  spec.little_endian = little_endian;
  return open_raw_source(path, spec);
}

/// Values over T's whole range, both extremes included.
template <typename T>
std::vector<T> spread(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<T> v(n);
  for (auto& x : v) {
    if constexpr (std::is_same_v<T, float>) x = std::uniform_real_distribution<float>(-3e4f, 3e4f)(rng);
    else x = T(std::uniform_int_distribution<int>(std::numeric_limits<T>::lowest(), std::numeric_limits<T>::max())(rng));
  }
  v[1] = std::numeric_limits<T>::lowest(), v[n - 2] = std::numeric_limits<T>::max();
  return v;
}

template <typename T>
void expect_round_trip(const testing::TempDir& dir) {
  const ValueType type = ValueTypeOf<T>::value;
  const std::string name(to_string(type));
  SCOPED_TRACE(name);
  const Vec3s dims{21, 17, 13};
  const std::vector<T> v = spread<T>(size_t(volume(dims)), 7);
  write(dir.file(name + ".raw"), bytes_of(v));
  const BuildResult r = build_store(*raw(dir.file(name + ".raw"), dims, element_type(type)), dir.file(name), small_bricks());
  Store store(dir.file(name));
  EXPECT_EQ(store.format().type, type);
  EXPECT_EQ(r.manifest.min_value, double(*std::min_element(v.begin(), v.end())));
  EXPECT_EQ(r.manifest.max_value, double(*std::max_element(v.begin(), v.end())));
  uint64_t counted = 0;
  for (uint64_t c : r.manifest.histogram.counts) counted += c;
  EXPECT_EQ(counted, uint64_t(volume(dims)));
  export_raw(store, store.layout().finest(), export_region(store, store.layout().finest(), {}), dir.file(name + ".back"));
  EXPECT_EQ(testing::read_file(dir.file(name + ".back")), testing::read_file(dir.file(name + ".raw")));
  EXPECT_EQ(read_raw_sidecar(dir.file(name + ".back.json")).type, type);
  // Every coarser level is the 2x average the reference pyramid computes (signed ones floor).
  testing::Grid<T> expected{dims, v};
  for (int level = store.layout().finest() - 1; level >= 0; --level) {
    expected = testing::halve(expected);
    ASSERT_TRUE(testing::read_level<T>(store, level).v == expected.v) << "level " << level;
  }
}

TEST(ValueTypes, EveryStoredTypeRoundTripsBitExactlyThroughImportAndExport) {
  testing::TempDir dir;
  expect_round_trip<uint8_t>(dir);
  expect_round_trip<int8_t>(dir);
  expect_round_trip<uint16_t>(dir);
  expect_round_trip<int16_t>(dir);
  expect_round_trip<float>(dir);
}

TEST(ValueTypes, FieldsQuantiseOntoTheWholeSignedRange) {
  auto field = make_field("sphere");
  const ValueRange q = field->range();
  for (ValueType type : {ValueType::i8, ValueType::i16}) {
    GridSampler s(*field, {17, 17, 17}, type);
    std::vector<std::byte> bytes(size_t(17 * 17 * 17) * size_of(type));
    s.sample_slab(0, 17, bytes);
    double lo = INFINITY, hi = -INFINITY;
    extend_range(bytes, type, lo, hi);
    EXPECT_GE(lo, integer_min(type));
    EXPECT_LE(hi, integer_max(type));
    EXPECT_LT(lo, 0) << to_string(type) << ": the negative half is used";
    // The extremes of the field map onto the extremes of the type, and back.
    EXPECT_EQ(double(quantize<int16_t>(q.lo, q)), -32768.0);
    EXPECT_EQ(double(quantize<int16_t>(q.hi, q)), 32767.0);
    EXPECT_EQ(double(quantize<int8_t>(q.lo, q)), -128.0);
    EXPECT_DOUBLE_EQ(dequantize(-128, ValueType::i8, q), q.lo);
    EXPECT_DOUBLE_EQ(dequantize(32767, ValueType::i16, q), q.hi);
  }
}

TEST(ValueTypes, ThirtyTwoBitIntegersConvertExactlyWithin24BitsAndOnlyOnRequestBeyond) {
  testing::TempDir dir;
  const Vec3s dims{9, 8, 7};
  std::vector<int32_t> small(size_t(volume(dims)));
  for (size_t i = 0; i < small.size(); ++i) small[i] = int32_t(i * 31337) - (1 << 23);
  small[4] = -(1 << 24), small[5] = 1 << 24;  // the exact limits
  write(dir.file("i32.raw"), bytes_of(small, true));
  auto source = raw(dir.file("i32.raw"), dims, ElementType::i32, {}, /*little_endian=*/false);
  EXPECT_EQ(source->type(), ValueType::f32);
  ASSERT_TRUE(source->conversion());
  EXPECT_TRUE(source->conversion()->exact());
  const BuildResult r = build_store(*source, dir.file("i32"), small_bricks());
  ASSERT_TRUE(r.conversion);
  EXPECT_NE(r.conversion->find("converted i32 -> f32"), std::string::npos) << *r.conversion;
  EXPECT_NE(r.conversion->find("exact"), std::string::npos) << *r.conversion;
  Store store(dir.file("i32"));
  EXPECT_EQ(testing::read_level<float>(store, store.layout().finest()).v, std::vector<float>(small.begin(), small.end()));
  EXPECT_NE(store.manifest().source.find("\"conversion\""), std::string::npos);
  EXPECT_NE(store.manifest().source.find("\"element_type\":\"i32\""), std::string::npos);

  // One value past 2^24: refused before anything is built, naming the option...
  std::vector<uint32_t> wide(size_t(volume(dims)), 3);
  wide[10] = (1u << 24) + 1;
  wide[11] = 4000000100u;  // floats there are 256 apart: it rounds to 4000000000, the worst error
  write(dir.file("u32.raw"), bytes_of(wide));
  try {
    raw(dir.file("u32.raw"), dims, ElementType::u32);
    ADD_FAILURE() << "accepted a rounding conversion";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    for (const char* text : {"u32.raw", "--convert f32", "2 of its u32 values exceed 2^24"})
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir.file("u32")));
  // ... and accepted with it, the worst error reported.
  ConvertOptions accept;
  accept.accept_rounding = true;
  source = raw(dir.file("u32.raw"), dims, ElementType::u32, accept);
  const ConversionReport c = *source->conversion();
  EXPECT_EQ(c.inexact, 2u);
  EXPECT_EQ(c.max_abs_error, 100.0);
  EXPECT_EQ(c.worst_value, 4000000100.0);
  EXPECT_EQ(build_store(*source, dir.file("u32"), small_bricks()).manifest.format.type, ValueType::f32);
}

TEST(ValueTypes, DoublesConvertWithTheLargestRelativeErrorReported) {
  testing::TempDir dir;
  const Vec3s dims{6, 5, 4};
  std::vector<double> v(size_t(volume(dims)));
  double worst = 0;
  for (size_t i = 0; i < v.size(); ++i) {
    v[i] = 0.1 * double(i) - 3.3;
    if (v[i] != 0) worst = std::max(worst, std::fabs(double(float(v[i])) - v[i]) / std::fabs(v[i]));
  }
  write(dir.file("d.raw"), bytes_of(v));
  auto source = raw(dir.file("d.raw"), dims, ElementType::f64);
  EXPECT_DOUBLE_EQ(source->conversion()->max_rel_error, worst);
  EXPECT_LT(worst, 0.5 * FLT_EPSILON + 1e-12);
  build_store(*source, dir.file("d"), small_bricks());
  Store store(dir.file("d"));
  const auto got = testing::read_level<float>(store, store.layout().finest()).v;
  for (size_t i = 0; i < v.size(); ++i) ASSERT_EQ(got[i], float(v[i])) << i;

  // A NaN among doubles is a non-finite voxel as in any f32 file: refused with its position.
  v[3 + 6 * (2 + 5 * 1)] = std::numeric_limits<double>::quiet_NaN();
  write(dir.file("n.raw"), bytes_of(v));
  source = raw(dir.file("n.raw"), dims, ElementType::f64);
  EXPECT_EQ(source->conversion()->nonfinite, 1u);
  try {
    build_store(*source, dir.file("n"), small_bricks());
    ADD_FAILURE() << "built a store of NaN";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("the first at (3, 2, 1)"), std::string::npos) << e.what();
  }
}

/// A CT-like head on n^3 i16 voxels: air -1024 with noise of +-12 around a ball of tissue (40,
/// the same noise) inside a shell of bone (1000).
std::vector<int16_t> ct_head(int n) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> noise(-12, 12);
  std::vector<int16_t> v;
  const double c = 0.5 * (n - 1), r = 0.3 * n;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double d = std::hypot(x - c, y - c, z - c) / r;
        v.push_back(int16_t(d < 1 ? (d > 0.85 ? 1000 : 40 + noise(rng)) : -1024 + noise(rng)));
      }
  return v;
}

TEST(Background, AutoTakesTheBordersMedianAndEmptiesNoisyAirWhileTheDataStaysExact) {
  testing::TempDir dir;
  const int n = 96;
  const std::vector<int16_t> v = ct_head(n);
  write(dir.file("ct.raw"), bytes_of(v));
  auto source = raw(dir.file("ct.raw"), {n, n, n}, ElementType::i16);
  EXPECT_NEAR(estimate_background(*source), -1024, 2);

  const BuildResult plain = build_store(*source, dir.file("plain"), small_bricks());
  BuildOptions o = small_bricks();
  o.background_auto = true;
  o.constant_tolerance = 40;
  const BuildResult air = build_store(*source, dir.file("air"), o);
  const int finest = int(plain.manifest.stats.size()) - 1;
  const auto share = [&](const BuildResult& r) {
    return double(r.manifest.stats[size_t(finest)].empty) / double(r.manifest.stats[size_t(finest)].bricks);
  };
  EXPECT_EQ(share(plain), 0.0);
  EXPECT_GT(share(air), 0.6);
  EXPECT_NEAR(air.manifest.background, -1024, 2);
  EXPECT_NE(air.manifest.build.find("\"background\":\"auto\""), std::string::npos);
  // Flattened air lies within the tolerance of the data; everything else is exact (the tissue's
  // noise is within 40 of itself too, but it is not the background: it stays).
  Store store(dir.file("air"));
  const auto got = testing::read_level<int16_t>(store, store.layout().finest()).v;
  for (size_t i = 0; i < v.size(); ++i) {
    if (v[i] > -900) ASSERT_EQ(got[i], v[i]) << i;
    else ASSERT_LE(std::abs(int(got[i]) - int(v[i])), 40) << i;
  }
  // The same import again is up to date without reading the data; an explicit background is
  // another build.
  EXPECT_TRUE(build_store(*source, dir.file("air"), o).up_to_date);
  o.background_auto = false;
  o.background = -1024;
  EXPECT_THROW(build_store(*source, dir.file("air"), o), Error);
  o.background = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(build_store(*source, dir.file("nan"), o), Error);
}

}  // namespace
}  // namespace brickyard
