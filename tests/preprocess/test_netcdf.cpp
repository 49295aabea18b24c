// The netCDF importer against files netCDF4-python wrote (tests/data/netcdf/make_files.py, which
// says how to rerun it and what each file holds), every voxel checked against the generator's
// formula, and bad inputs refused by name.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "builder_test_util.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "test_util.h"

namespace brickyard {
namespace {

#if BRICKYARD_HAVE_NETCDF
constexpr bool kHaveNetcdf = true;
#else
constexpr bool kHaveNetcdf = false;
#endif

#define SKIP_WITHOUT_NETCDF() \
  if (!kHaveNetcdf) GTEST_SKIP() << "this build reads no netCDF files (install libnetcdf-dev and rebuild)"

const std::string kData = BRICKYARD_SOURCE_DIR "/tests/data/netcdf/";

/// The generator's formula.
int64_t f(int64_t x, int64_t y, int64_t z) { return (x * 7 + y * 13 + z * 29) % 251; }

/// g(x, y, z) over `dims`, x fastest.
template <typename T, typename G>
std::vector<T> expected(const Vec3s& dims, G g) {
  std::vector<T> v;
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) v.push_back(static_cast<T>(g(x, y, z)));
  return v;
}

/// Every voxel through read_slab, in one call.
template <typename T>
std::vector<T> read_all(VolumeSource& source) {
  EXPECT_EQ(source.type(), ValueTypeOf<T>::value);
  std::vector<T> v(size_t(volume(source.dims())));
  source.read_slab(0, source.dims().z, {reinterpret_cast<std::byte*>(v.data()), v.size() * sizeof(T)});
  return v;
}

/// Builds a store of 8^3 bricks with the default options (the source's background, tolerance 0).
template <typename T>
std::vector<T> import_finest(VolumeSource& source, const std::string& store_dir) {
  EXPECT_EQ(source.type(), ValueTypeOf<T>::value);
  BuildOptions o;
  o.brick_size = 8;
  build_store(source, store_dir, o);
  Store store(store_dir);
  return testing::read_level<T>(store, store.layout().finest()).v;
}

nlohmann::json provenance(const VolumeSource& source) { return nlohmann::json::parse(source.describe_json()); }

std::unique_ptr<VolumeSource> open(const std::string& file, const std::string& variable = "",
                                   std::optional<int64_t> time_step = std::nullopt) {
  NetcdfOptions o;
  o.variable = variable;
  o.time_step = time_step;
  return open_netcdf_source(kData + file, o);
}

/// The Error that `open` throws (an empty one, after a failure, when it throws none).
template <typename F>
Error error_of(F open) {
  try {
    open();
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "no error";
  return Error(Errc::internal, "");
}

bool mentions(const Error& e, const std::string& text) { return std::string(e.what()).find(text) != std::string::npos; }

// ocean.nc: temp(time, depth, lat, lon), 16x10x4 per step; land is the continent lon >= 7,
// lat <= 8 and the island lon 2, lat 3, at _FillValue 1e20.
const Vec3s kOcean{16, 10, 4};
bool land(int64_t x, int64_t y) { return (x >= 7 && y <= 8) || (x == 2 && y == 3); }
double ocean(int64_t x, int64_t y, int64_t z, int t) { return 10 + double(f(x, y, z) % 31) / 4 + t; }

TEST(Netcdf, OceanStepKeepsItsValuesCoordinatesAndStoresLandAsEmptyBricks) {
  SKIP_WITHOUT_NETCDF();
  testing::TempDir dir;
  auto source = open("ocean.nc", "", 0);
  EXPECT_EQ(source->dims(), kOcean);
  // The smallest ocean value is 10: missing voxels are one below, and the default background.
  EXPECT_EQ(source->background(), 9);
  ASSERT_TRUE(source->value_range_hint());
  EXPECT_EQ(source->value_range_hint()->lo, 9);
  EXPECT_EQ(source->value_range_hint()->hi, 17.5);
  EXPECT_FALSE(source->may_contain_nonfinite());
  EXPECT_FALSE(source->conversion()) << "floats are stored as they are";
  EXPECT_EQ(source->input_bytes(), uint64_t(16 * 10 * 4 * 4)) << "one time step";
  const auto want = expected<float>(kOcean, [](auto x, auto y, auto z) { return land(x, y) ? 9.0 : ocean(x, y, z, 0); });
  EXPECT_EQ(import_finest<float>(*source, dir.file("s")), want);

  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_EQ(m.spacing, Vec3d(0.5, 0.25, 10));
  EXPECT_EQ(m.origin, Vec3d(10, -5, 5));
  EXPECT_EQ(m.background, 9);
  EXPECT_EQ(m.min_value, 9);
  EXPECT_EQ(m.max_value, 17.5);
  // 2x2x1 finest bricks: the one over lon 8..15, lat 0..7 (with its apron, lon 7.., lat ..8) is
  // all land, so constant at the background: empty, with --constant-tolerance 0.
  const auto& finest = m.stats[size_t(m.layout().finest())];
  EXPECT_EQ(finest.bricks, 4);
  EXPECT_EQ(finest.empty, 1);
  EXPECT_EQ(finest.constant, 1);

  const auto j = nlohmann::json::parse(m.source);
  EXPECT_EQ(j["kind"], "netcdf");
  EXPECT_EQ(j["path"], kData + "ocean.nc");
  EXPECT_EQ(j["format"], "netCDF-4");
  EXPECT_EQ(j["variable"], "temp");
  EXPECT_EQ(j["type"], "float");
  EXPECT_EQ(j["dimensions"], nlohmann::json({"time", "depth", "lat", "lon"}));
  EXPECT_EQ(j["sizes"], nlohmann::json({2, 4, 10, 16}));
  EXPECT_EQ(j["units"], "degC");
  EXPECT_EQ(j["long_name"], "sea water temperature");
  EXPECT_EQ(j["time_steps"], 2);
  EXPECT_EQ(j["time_step"], 0);
  EXPECT_EQ(j["time_value"], 0.0);
  EXPECT_EQ(j["time_units"], "days since 2000-01-01 00:00:00");
  EXPECT_EQ(j["coordinates"]["x"], nlohmann::json({{"variable", "lon"}, {"first", 10.0}, {"last", 17.5}, {"units", "degrees_east"}}));
  EXPECT_EQ(j["coordinates"]["y"]["variable"], "lat");
  EXPECT_EQ(j["coordinates"]["z"], nlohmann::json({{"variable", "depth"}, {"first", 5.0}, {"last", 35.0}, {"units", "m"}}));
  EXPECT_EQ(j["fill_value"], nlohmann::json({double(1e20f)}));
  EXPECT_EQ(j["missing_voxels"], (9 * 9 + 1) * 4);
  EXPECT_EQ(j["missing_as"], 9.0);
  EXPECT_FALSE(j.contains("scale_factor"));
}

TEST(Netcdf, SecondTimeStepHasItsOwnValuesAndBackground) {
  SKIP_WITHOUT_NETCDF();
  auto source = open("ocean.nc", "temp", 1);
  EXPECT_EQ(source->background(), 10);
  EXPECT_EQ(read_all<float>(*source),
            expected<float>(kOcean, [](auto x, auto y, auto z) { return land(x, y) ? 10.0 : ocean(x, y, z, 1); }));
  const auto j = provenance(*source);
  EXPECT_EQ(j["time_step"], 1);
  EXPECT_EQ(j["time_value"], 31.0);
}

TEST(Netcdf, SlabsSkipSlicesAndRewind) {
  SKIP_WITHOUT_NETCDF();
  auto source = open("ocean.nc", "", 0);
  EXPECT_TRUE(source->can_skip());
  const auto want = expected<float>(kOcean, [](auto x, auto y, auto z) { return land(x, y) ? 9.0 : ocean(x, y, z, 0); });
  const size_t slice = 16 * 10;
  std::vector<float> slab(2 * slice);
  source->read_slab(2, 4, {reinterpret_cast<std::byte*>(slab.data()), slab.size() * 4});
  EXPECT_EQ(slab, std::vector<float>(want.begin() + 2 * long(slice), want.end()));
  source->rewind();
  source->read_slab(0, 2, {reinterpret_cast<std::byte*>(slab.data()), slab.size() * 4});
  EXPECT_EQ(slab, std::vector<float>(want.begin(), want.begin() + 2 * long(slice)));
}

TEST(Netcdf, FourDimensionalVariableNeedsATimeStepInRange) {
  SKIP_WITHOUT_NETCDF();
  const Error none = error_of([] { open("ocean.nc"); });
  EXPECT_EQ(none.code(), Errc::invalid_argument);
  EXPECT_EQ(none.file(), kData + "ocean.nc");
  EXPECT_EQ(none.field(), "--time-step");
  EXPECT_TRUE(mentions(none, "variable 'temp' holds 2 time steps (dimension 'time')") && mentions(none, "0 to 1"))
      << none.what();
  for (int64_t bad : {int64_t(2), int64_t(-1)}) {
    const Error e = error_of([&] { open("ocean.nc", "", bad); });
    EXPECT_EQ(e.field(), "--time-step");
    EXPECT_TRUE(mentions(e, "outside the 2 steps of variable 'temp' (0 to 1)")) << e.what();
  }
}

// packed.nc: shorts over z 3, y 4, x 5, without coordinate variables.
const Vec3s kPacked{5, 4, 3};

TEST(Netcdf, FractionalScaleAndOffsetUnpackToF32AndFillValuesBecomeTheBackground) {
  SKIP_WITHOUT_NETCDF();
  testing::TempDir dir;
  auto source = open("packed.nc", "sst");
  auto missing = [](auto x, auto y, auto z) { return (x + 2 * y + 3 * z) % 7 == 0; };
  // Unpacked in double with the float attributes' values, then rounded once to f32.
  auto value = [](auto x, auto y, auto z) { return double(f(x, y, z) * 10 - 1000) * double(0.01f) + double(20.0f); };
  double lo = INFINITY;
  for (int64_t z = 0; z < 3; ++z)
    for (int64_t y = 0; y < 4; ++y)
      for (int64_t x = 0; x < 5; ++x)
        if (!missing(x, y, z)) lo = std::min(lo, value(x, y, z));
  const double background = std::floor(lo) - 1;
  EXPECT_EQ(source->background(), background);
  ASSERT_TRUE(source->conversion());
  EXPECT_EQ(source->conversion()->from, ElementType::f64);
  EXPECT_EQ(import_finest<float>(*source, dir.file("s")), expected<float>(kPacked, [&](auto x, auto y, auto z) {
              return missing(x, y, z) ? background : value(x, y, z);
            }));
  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_EQ(m.spacing, Vec3d(1.0));
  EXPECT_EQ(m.origin, Vec3d(0.0));
  EXPECT_EQ(m.background, background);
  const auto j = nlohmann::json::parse(m.source);
  EXPECT_EQ(j["format"], "classic");
  EXPECT_EQ(j["scale_factor"], double(0.01f));
  EXPECT_EQ(j["add_offset"], 20.0);
  EXPECT_EQ(j["fill_value"], nlohmann::json({-32767.0}));
  EXPECT_EQ(j["coordinates"], nlohmann::json::object());
  EXPECT_TRUE(j.contains("conversion"));
}

TEST(Netcdf, WholeScaleAndOffsetStayI16AndEveryMissingValueIsMarked) {
  SKIP_WITHOUT_NETCDF();
  testing::TempDir dir;
  // Scaled by 1 and -1000, shorts may leave i16 by their type's range; these values do not, so
  // a measuring pass keeps them i16. missing_value lists 32767 and -32768: both are missing.
  auto source = open("packed.nc", "level");
  auto missing = [](auto x, auto y, auto z) { return (x + y + z) % 5 <= 1; };
  int64_t lo = std::numeric_limits<int64_t>::max();
  for (int64_t z = 0; z < 3; ++z)
    for (int64_t y = 0; y < 4; ++y)
      for (int64_t x = 0; x < 5; ++x)
        if (!missing(x, y, z)) lo = std::min(lo, f(x, y, z) * 100 - 1000);
  EXPECT_FALSE(source->conversion());
  EXPECT_EQ(source->background(), double(lo - 1));
  ASSERT_TRUE(source->value_range_hint());
  EXPECT_EQ(source->value_range_hint()->lo, double(lo - 1));
  EXPECT_EQ(import_finest<int16_t>(*source, dir.file("s")), expected<int16_t>(kPacked, [&](auto x, auto y, auto z) {
              return missing(x, y, z) ? lo - 1 : f(x, y, z) * 100 - 1000;
            }));
  const auto j = provenance(*source);
  EXPECT_EQ(j["missing_value"], nlohmann::json({32767.0, -32768.0}));
  EXPECT_EQ(j["missing_voxels"], 24);
  EXPECT_EQ(j["missing_as"], double(lo - 1));
}

TEST(Netcdf, OnlyThreeDimensionalDoubleIsChosenConvertedExactlyAndPlacedByItsCoordinates) {
  SKIP_WITHOUT_NETCDF();
  testing::TempDir dir;
  auto source = open("double3d.nc");  // mask(y, x) is 2D: density is the only candidate
  const Vec3s dims{7, 6, 5};
  EXPECT_EQ(source->dims(), dims);
  EXPECT_EQ(source->spacing(), Vec3d(2, 0.5, 0.25));
  EXPECT_EQ(source->origin(), Vec3d(100, -3, 0));
  EXPECT_EQ(source->background(), 0) << "no fill values";
  ASSERT_TRUE(source->conversion());
  EXPECT_TRUE(source->conversion()->exact());
  EXPECT_EQ(source->conversion()->from, ElementType::f64);
  EXPECT_EQ(source->input_bytes(), uint64_t(7 * 6 * 5 * 8));
  EXPECT_EQ(import_finest<float>(*source, dir.file("s")),
            expected<float>(dims, [](auto x, auto y, auto z) { return double(f(x, y, z)) / 8; }));
  const auto j = provenance(*source);
  EXPECT_EQ(j["format"], "64-bit offset");
  EXPECT_EQ(j["variable"], "density");
  EXPECT_EQ(j["units"], "kg m-3");
  EXPECT_EQ(j["coordinates"]["z"]["units"], "km");
  EXPECT_FALSE(j.contains("time_steps"));
}

TEST(Netcdf, ElementTypesMapOntoStoredTypesAndWideIntegersNeedConvert) {
  SKIP_WITHOUT_NETCDF();
  const Vec3s dims{4, 3, 2};
  EXPECT_EQ(read_all<int8_t>(*open("types.nc", "b")), expected<int8_t>(dims, [](auto x, auto y, auto z) { return f(x, y, z) - 50; }));
  EXPECT_EQ(read_all<uint8_t>(*open("types.nc", "ub")),
            expected<uint8_t>(dims, [](auto x, auto y, auto z) { return f(x, y, z) + 100; }));
  EXPECT_EQ(read_all<uint16_t>(*open("types.nc", "us")),
            expected<uint16_t>(dims, [](auto x, auto y, auto z) { return f(x, y, z) * 800; }));
  auto i = open("types.nc", "i");
  ASSERT_TRUE(i->conversion());
  EXPECT_TRUE(i->conversion()->exact());
  EXPECT_EQ(i->conversion()->from, ElementType::i32);
  EXPECT_EQ(read_all<float>(*i), expected<float>(dims, [](auto x, auto y, auto z) { return f(x, y, z) * 40000 - 1000000; }));
  EXPECT_EQ(read_all<float>(*open("types.nc", "ui")),
            expected<float>(dims, [](auto x, auto y, auto z) { return f(x, y, z) * 100000; }));

  // 2^24 + 1, which f32 rounds: refused unless --convert f32.
  const Error wide = error_of([] { open("types.nc", "wide"); });
  EXPECT_EQ(wide.field(), "--convert");
  EXPECT_EQ(wide.file(), kData + "types.nc");
  NetcdfOptions accept;
  accept.variable = "wide";
  accept.convert.accept_rounding = true;
  EXPECT_EQ(open_netcdf_source(kData + "types.nc", accept)->conversion()->inexact, 1u);

  for (const auto& [variable, type] : {std::pair{"i64", "int64"}, std::pair{"names", "string"}}) {
    const Error e = error_of([&] { open("types.nc", variable); });
    EXPECT_EQ(e.code(), Errc::unsupported);
    EXPECT_EQ(e.field(), variable);
    EXPECT_TRUE(mentions(e, std::string("variable '") + variable + "' is " + type)) << e.what();
  }
}

TEST(Netcdf, VariableChoiceIsRefusedWhenUnknownOrAmbiguous) {
  SKIP_WITHOUT_NETCDF();
  const Error unknown = error_of([] { open("ocean.nc", "TEMP"); });
  EXPECT_EQ(unknown.code(), Errc::not_found);
  EXPECT_EQ(unknown.file(), kData + "ocean.nc");
  EXPECT_EQ(unknown.field(), "--variable");
  EXPECT_TRUE(mentions(unknown, "no variable named 'TEMP'; the file has 'time(time)', 'depth(depth)', 'lat(lat)', "
                                "'lon(lon)', 'temp(time, depth, lat, lon)'"))
      << unknown.what();

  const Error two = error_of([] { open("packed.nc"); });
  EXPECT_EQ(two.code(), Errc::invalid_argument);
  EXPECT_EQ(two.field(), "--variable");
  EXPECT_TRUE(mentions(two, "the file has 2 3D or 4D variables ('sst', 'level'): choose one with --variable")) << two.what();
}

TEST(Netcdf, ShapesOtherThanZyxOrTimeZyxAreRefusedNamingTheVariable) {
  SKIP_WITHOUT_NETCDF();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"surface", "variable surface(y, x) has 2 dimensions"},
      {"series", "variable series(time, y, x) is a 2D field over time ('time' is named time)"},
      {"bands", "the first of its 4 dimensions, 'band', is neither unlimited nor named time"},
      {"five", "variable five(band, c, z, y, x) has 5 dimensions"}};
  for (const auto& [variable, text] : cases) {
    const Error e = error_of([&] { open("layouts.nc", variable); });
    EXPECT_EQ(e.code(), Errc::unsupported) << variable;
    EXPECT_EQ(e.file(), kData + "layouts.nc");
    EXPECT_EQ(e.field(), variable);
    EXPECT_TRUE(mentions(e, text)) << e.what();
  }
}

TEST(Netcdf, NonUniformOrDescendingCoordinatesAreRefusedNamingThem) {
  SKIP_WITHOUT_NETCDF();
  const Error uneven = error_of([] { open("nonuniform.nc", "uneven"); });
  EXPECT_EQ(uneven.code(), Errc::unsupported);
  EXPECT_EQ(uneven.field(), "x");
  EXPECT_TRUE(mentions(uneven, "coordinate variable 'x' is not uniform: its step from index 0 to 1 is 1, the mean "
                               "step 1.25"))
      << uneven.what();
  const Error flipped = error_of([] { open("nonuniform.nc", "flipped"); });
  EXPECT_EQ(flipped.field(), "lat");
  EXPECT_TRUE(mentions(flipped, "coordinate variable 'lat' runs from 10 to 0")) << flipped.what();
  // Steps within 0.1% of the mean are a uniform grid.
  auto nearly = open("nonuniform.nc", "nearly");
  EXPECT_EQ(nearly->spacing(), Vec3d(1, 1, 1));
  EXPECT_EQ(read_all<float>(*nearly), expected<float>(Vec3s(4, 3, 2), [](auto x, auto y, auto z) { return f(x, y, z); }));
}

TEST(Netcdf, OtherFilesAreRefusedWithNetcdfsReason) {
  SKIP_WITHOUT_NETCDF();
  testing::TempDir dir;
  std::ofstream(dir.file("notes.nc")) << "these are not the data you are looking for\n";
  const Error e = error_of([&] { open_netcdf_source(dir.file("notes.nc")); });
  EXPECT_EQ(e.code(), Errc::format);
  EXPECT_EQ(e.file(), dir.file("notes.nc"));
  EXPECT_TRUE(mentions(e, "not a netCDF file: NetCDF: Unknown file format")) << e.what();

  const Error none = error_of([&] { open_netcdf_source(dir.file("none.nc")); });
  EXPECT_EQ(none.file(), dir.file("none.nc"));
}

}  // namespace
}  // namespace brickyard
