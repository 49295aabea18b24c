// The DICOM importer against series pydicom wrote (tests/data/dicom/make_files.py, which says how
// to rerun it), every voxel checked against the generator's formula, and bad inputs.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
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

namespace fs = std::filesystem;

#if BRICKYARD_HAVE_DICOM
constexpr bool kHaveDicom = true;
#else
constexpr bool kHaveDicom = false;
#endif

#define SKIP_WITHOUT_DICOM() \
  if (!kHaveDicom) GTEST_SKIP() << "this build reads no DICOM files (install libgdcm-dev and rebuild)"

const std::string kData = BRICKYARD_SOURCE_DIR "/tests/data/dicom/";

/// The generator's formula, of the voxel's place in the sorted volume: integers in [-100, 150].
int g(int64_t x, int64_t y, int64_t z) { return int((x * 7 + y * 13 + z * 29) % 251) - 100; }

/// h(x, y, z) over `dims`, x fastest.
template <typename T, typename H>
std::vector<T> expected(const Vec3s& dims, H h) {
  std::vector<T> v;
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) v.push_back(static_cast<T>(h(x, y, z)));
  return v;
}

template <typename T>
std::vector<T> import_finest(VolumeSource& source, const std::string& store_dir) {
  EXPECT_EQ(source.type(), ValueTypeOf<T>::value);
  BuildOptions o;
  o.brick_size = 8;
  build_store(source, store_dir, o);
  Store store(store_dir);
  return testing::read_level<T>(store, store.layout().finest()).v;
}

/// The whole volume through read_slab, in slabs of `step` slices.
template <typename T>
std::vector<T> read_all(VolumeSource& source, int64_t step) {
  const Vec3s d = source.dims();
  std::vector<T> v(size_t(volume(d)));
  const size_t slice = size_t(d.x * d.y);
  for (int64_t z = 0; z < d.z; z += step) {
    const int64_t z1 = std::min(d.z, z + step);
    source.read_slab(z, z1, {reinterpret_cast<std::byte*>(v.data() + size_t(z) * slice), size_t(z1 - z) * slice * sizeof(T)});
  }
  return v;
}

nlohmann::json provenance(const VolumeSource& source) { return nlohmann::json::parse(source.describe_json()); }

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

/// Copies every file of the data directories `names` into `dir`.
void copy_series(const std::string& dir, std::initializer_list<const char*> names) {
  for (const char* name : names)
    for (const auto& entry : fs::directory_iterator(kData + name))
      fs::copy_file(entry.path(), fs::path(dir) / entry.path().filename());
}

TEST(Dicom, ShuffledCtSlicesAreSortedAlongTheNormalAndRescaledExactlyToI16) {
  SKIP_WITHOUT_DICOM();
  testing::TempDir dir;
  auto source = open_dicom_source(kData + "ct");
  const Vec3s dims{8, 7, 5};
  EXPECT_EQ(source->dims(), dims);
  // Stored pixels 10g + 1024 with intercept -1024: the values 10g fit i16, found by a measuring
  // pass (the i16 pixel type's limits, shifted by -1024, do not).
  const auto want = expected<int16_t>(dims, [](auto x, auto y, auto z) { return 10 * g(x, y, z); });
  EXPECT_EQ(import_finest<int16_t>(*source, dir.file("s")), want);
  EXPECT_FALSE(source->conversion()) << "integers stored exactly are no conversion";
  // PixelSpacing 0.75\0.5 is (rows, columns): y 0.75, x 0.5; slices 2.5 apart; the origin is the
  // first slice's position along the normal.
  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_EQ(m.spacing, Vec3d(0.5, 0.75, 2.5));
  EXPECT_EQ(m.origin, Vec3d(-20, 30.5, -40));
  const auto j = nlohmann::json::parse(m.source);
  EXPECT_EQ(j["kind"], "dicom");
  EXPECT_EQ(j["series_count"], 1);
  EXPECT_EQ(j["series_chosen_by"], "only");
  EXPECT_FALSE(j["series_uid"].get<std::string>().empty());
  EXPECT_EQ(j["files"], 5);
  EXPECT_EQ(j["first_file"], "ct_1.dcm");
  EXPECT_EQ(j["last_file"], "ct_2.dcm");
  EXPECT_EQ(j["skipped_not_dicom"], 1) << "notes.txt";
  EXPECT_EQ(j["orientation"], nlohmann::json({1, 0, 0, 0, 1, 0}));
  EXPECT_EQ(j["rescale"], nlohmann::json({{"slope", 1}, {"intercept", -1024}}));
  EXPECT_EQ(j["transfer_syntaxes"].size(), 2u) << "one slice is Implicit VR Little Endian";
  EXPECT_EQ(source->input_bytes(), uint64_t(8 * 7 * 5 * 2));
  // Slabs of any size, after a rewind, read the same values.
  source->rewind();
  EXPECT_EQ(read_all<int16_t>(*source, 2), want);
  source->rewind();
  EXPECT_EQ(read_all<int16_t>(*source, 5), want);
}

TEST(Dicom, FractionalSlopeIsStoredAsF32AlongTheNormalOfASagittalSeries) {
  SKIP_WITHOUT_DICOM();
  testing::TempDir dir;
  auto source = open_dicom_source(kData + "mr");
  const Vec3s dims{8, 7, 4};
  EXPECT_EQ(source->dims(), dims);
  // u16 pixels (g + 100) * 200, one file big-endian, times RescaleSlope 0.5.
  EXPECT_EQ(import_finest<float>(*source, dir.file("s")),
            expected<float>(dims, [](auto x, auto y, auto z) { return (g(x, y, z) + 100) * 100; }));
  ASSERT_TRUE(source->conversion());
  EXPECT_TRUE(source->conversion()->exact());
  // Orientation 0,1,0 / 0,0,-1: the normal is -x, so the slices run from x = 16 down to 10.
  EXPECT_EQ(source->spacing(), Vec3d(1.25, 1.5, 2));
  EXPECT_EQ(source->origin(), Vec3d(16, -5, 20));
  const auto j = provenance(*source);
  EXPECT_EQ(j["orientation"], nlohmann::json({0, 1, 0, 0, 0, -1}));
  EXPECT_EQ(j["normal"], nlohmann::json({-1, 0, 0}));
  EXPECT_EQ(j["rescale"], nlohmann::json({{"slope", 0.5}, {"intercept", 0}}));
  EXPECT_EQ(j["element"], "u16");
  EXPECT_TRUE(j.contains("conversion"));
}

TEST(Dicom, FramesOfAnRleCompressedMultiFrameFileAreSortedByTheirOwnPositions) {
  SKIP_WITHOUT_DICOM();
  const Vec3s dims{8, 7, 3};
  const auto want = expected<uint8_t>(dims, [](auto x, auto y, auto z) { return g(x, y, z) + 100; });
  // The file itself, or the directory holding it.
  for (const std::string& path : {kData + "multiframe/enhanced_mr.dcm", kData + "multiframe"}) {
    testing::TempDir dir;
    auto source = open_dicom_source(path);
    EXPECT_EQ(source->dims(), dims) << path;
    EXPECT_EQ(import_finest<uint8_t>(*source, dir.file("s")), want) << path;
    // The shared PixelMeasuresSequence's spacing; frames 1.5 apart, the last frame first.
    EXPECT_EQ(source->spacing(), Vec3d(0.6, 0.8, 1.5)) << path;
    EXPECT_EQ(source->origin(), Vec3d(1, 2, 5)) << path;
    EXPECT_FALSE(provenance(*source).contains("rescale")) << path;
    source->rewind();
    EXPECT_EQ(read_all<uint8_t>(*source, 1), want) << path;
  }
}

TEST(Dicom, ASingleSliceFileIsAVolumeOneSliceThick) {
  SKIP_WITHOUT_DICOM();
  auto source = open_dicom_source(kData + "ct/ct_1.dcm");
  EXPECT_EQ(source->dims(), Vec3s(8, 7, 1));
  EXPECT_EQ(source->spacing(), Vec3d(0.5, 0.75, 1));
  EXPECT_EQ(source->origin(), Vec3d(-20, 30.5, -40));
  EXPECT_EQ(read_all<int16_t>(*source, 1), expected<int16_t>(Vec3s(8, 7, 1), [](auto x, auto y, auto) {
              return 10 * g(x, y, 0);
            }));
}

TEST(Dicom, TheLargestSeriesIsChosenUnlessAnotherIsNamed) {
  SKIP_WITHOUT_DICOM();
  const std::string ct_uid = provenance(*open_dicom_source(kData + "ct"))["series_uid"];
  const std::string mr_uid = provenance(*open_dicom_source(kData + "mr"))["series_uid"];
  testing::TempDir dir;
  copy_series(dir.path().string(), {"ct", "mr"});

  auto largest = open_dicom_source(dir.path().string());
  EXPECT_EQ(largest->dims(), Vec3s(8, 7, 5));
  auto j = provenance(*largest);
  EXPECT_EQ(j["series_uid"], ct_uid);
  EXPECT_EQ(j["series_count"], 2);
  EXPECT_EQ(j["series_chosen_by"], "largest");
  ASSERT_EQ(j["other_series"].size(), 1u);
  EXPECT_EQ(j["other_series"][0]["uid"], mr_uid);
  EXPECT_EQ(j["other_series"][0]["slices"], 4);
  const std::string summary = j["summary"];
  EXPECT_NE(summary.find(ct_uid + " (5 slices, CT)"), std::string::npos) << summary;
  EXPECT_NE(summary.find(mr_uid + " (4 slices, MR)"), std::string::npos) << summary;
  EXPECT_NE(summary.find("--series"), std::string::npos) << summary;

  auto named = open_dicom_source(dir.path().string(), DicomOptions{mr_uid, {}});
  EXPECT_EQ(named->dims(), Vec3s(8, 7, 4));
  EXPECT_EQ(named->type(), ValueType::f32);
  j = provenance(*named);
  EXPECT_EQ(j["series_uid"], mr_uid);
  EXPECT_EQ(j["series_chosen_by"], "--series");
  EXPECT_EQ(j["files"], 4);
}

TEST(Dicom, AnUnknownSeriesIsRefusedListingTheSeries) {
  SKIP_WITHOUT_DICOM();
  const std::string ct_uid = provenance(*open_dicom_source(kData + "ct"))["series_uid"];
  const Error e = error_of([&] { open_dicom_source(kData + "ct", DicomOptions{"1.2.3.4", {}}); });
  EXPECT_EQ(e.code(), Errc::invalid_argument);
  EXPECT_EQ(e.field(), "--series");
  EXPECT_TRUE(mentions(e, "no series 1.2.3.4 in")) << e.what();
  EXPECT_TRUE(mentions(e, "it holds 1 series: " + ct_uid + " (5 slices, CT)")) << e.what();
}

TEST(Dicom, AMalformedValueMattersOnlyInTheSeriesImported) {
  SKIP_WITHOUT_DICOM();
  const std::string mr_uid = provenance(*open_dicom_source(kData + "mr"))["series_uid"];
  testing::TempDir dir;
  copy_series(dir.path().string(), {"ct", "mr"});
  // RescaleSlope "0.5 " (a DS, padded to even length) becomes "x.5 " in one MR slice.
  std::string bytes = testing::read_file(dir.file("mr_0.dcm"));
  const size_t at = bytes.find("0.5 ");
  ASSERT_NE(at, std::string::npos);
  ASSERT_EQ(bytes.find("0.5 ", at + 1), std::string::npos);
  bytes[at] = 'x';
  std::ofstream(dir.file("mr_0.dcm"), std::ios::binary | std::ios::trunc) << bytes;

  EXPECT_EQ(open_dicom_source(dir.path().string())->dims(), Vec3s(8, 7, 5)) << "the CT series is fine";
  const Error e = error_of([&] { open_dicom_source(dir.path().string(), DicomOptions{mr_uid, {}}); });
  EXPECT_EQ(e.file(), dir.file("mr_0.dcm"));
  EXPECT_EQ(e.field(), "RescaleSlope");
  EXPECT_TRUE(mentions(e, "RescaleSlope is 'x.5': not a number")) << e.what();
}

TEST(Dicom, IrregularSpacingIsRefusedNamingTheSlicesAndTheGaps) {
  SKIP_WITHOUT_DICOM();
  const Error e = error_of([&] { open_dicom_source(kData + "irregular"); });
  EXPECT_EQ(e.code(), Errc::format);
  EXPECT_EQ(e.file(), kData + "irregular");
  EXPECT_EQ(e.field(), "ImagePositionPatient");
  EXPECT_TRUE(mentions(e, "the gap between irr_2.dcm at (0, 0, 2) and irr_3.dcm at (0, 0, 3.5) is 1.5 mm, the median "
                          "gap 1 mm"))
      << e.what();
}

TEST(Dicom, SlicesOfAnotherSizeAreRefused) {
  SKIP_WITHOUT_DICOM();
  const Error e = error_of([&] { open_dicom_source(kData + "bad_rows"); });
  EXPECT_EQ(e.field(), "Rows");
  EXPECT_TRUE(mentions(e, "rows_1.dcm is 8 columns by 6 rows, but rows_0.dcm is 8 by 7")) << e.what();
}

TEST(Dicom, TwoSlicesAtOnePlaceAreRefused) {
  SKIP_WITHOUT_DICOM();
  const Error e = error_of([&] { open_dicom_source(kData + "duplicate"); });
  EXPECT_EQ(e.field(), "ImagePositionPatient");
  EXPECT_TRUE(mentions(e, "dup_0.dcm and dup_1.dcm lie at the same place along the slice normal")) << e.what();
}

TEST(Dicom, SlicesFacingAnotherWayAreRefused) {
  SKIP_WITHOUT_DICOM();
  const Error e = error_of([&] { open_dicom_source(kData + "orientation"); });
  EXPECT_EQ(e.field(), "ImageOrientationPatient");
  EXPECT_TRUE(mentions(e, "orient_1.dcm has ImageOrientationPatient 0\\1\\0\\-1\\0\\0, but orient_0.dcm has 1\\0\\0\\0\\1\\0"))
      << e.what();
}

TEST(Dicom, TruncatedPixelDataIsRefusedWhenItsSliceIsRead) {
  SKIP_WITHOUT_DICOM();
  auto source = open_dicom_source(kData + "bad_pixels");  // the headers are fine
  std::vector<std::byte> slab(8 * 7 * 2);
  const Error e = error_of([&] { source->read_slab(0, 2, slab); });
  EXPECT_EQ(e.file(), kData + "bad_pixels/pixels_1.dcm");
  EXPECT_EQ(e.field(), "PixelData");
  EXPECT_TRUE(mentions(e, "the pixel data is truncated: 50 bytes, but 8 columns by 7 rows of 8 bits need 56")) << e.what();
}

TEST(Dicom, ADirectoryWithoutDicomImagesIsRefusedSayingWhatItHolds) {
  SKIP_WITHOUT_DICOM();
  testing::TempDir dir;
  Error e = error_of([&] { open_dicom_source(dir.path().string()); });
  EXPECT_EQ(e.code(), Errc::not_found);
  EXPECT_EQ(e.file(), dir.path().string());
  EXPECT_TRUE(mentions(e, "no DICOM files in this directory: it holds no files")) << e.what();

  fs::copy_file(kData + "ct/notes.txt", dir.file("notes.txt"));
  e = error_of([&] { open_dicom_source(dir.path().string()); });
  EXPECT_TRUE(mentions(e, "no DICOM files in this directory: it holds 1 file that is not DICOM (notes.txt)")) << e.what();

  e = error_of([&] { open_dicom_source(dir.file("notes.txt")); });
  EXPECT_EQ(e.code(), Errc::format);
  EXPECT_TRUE(mentions(e, "not a DICOM file")) << e.what();

  e = error_of([&] { open_dicom_source(dir.file("absent")); });
  EXPECT_EQ(e.code(), Errc::not_found);
}

}  // namespace
}  // namespace brickyard
