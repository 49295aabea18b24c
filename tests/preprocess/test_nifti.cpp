// The NIfTI importer against files nibabel wrote (tests/data/nifti/make_files.py, which says how
// to rerun it), every voxel checked against the generator's formula, and bad inputs made here.

#include <gtest/gtest.h>

#if BRICKYARD_TEST_GZIP
#include <zlib.h>
#endif

#include <cstring>
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

#if BRICKYARD_HAVE_NIFTI
constexpr bool kHaveNifti = true;
#else
constexpr bool kHaveNifti = false;
#endif

#define SKIP_WITHOUT_NIFTI() \
  if (!kHaveNifti) GTEST_SKIP() << "this build reads no NIfTI files (install libnifti2-dev and rebuild)"

const std::string kData = BRICKYARD_SOURCE_DIR "/tests/data/nifti/";
const Vec3s kDims{7, 6, 5};

/// The generator's formula: integers in [-100, 150].
int f(int64_t x, int64_t y, int64_t z) { return int((x * 7 + y * 13 + z * 29) % 251) - 100; }

/// g(x, y, z) over `dims`, x fastest.
template <typename T, typename G>
std::vector<T> expected(const Vec3s& dims, G g) {
  std::vector<T> v;
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) v.push_back(static_cast<T>(g(x, y, z)));
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

void write(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

TEST(Nifti, SignedShortsAreStoredExactlyWithTheSformsSpacingAndOrigin) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  auto source = open_nifti_source(kData + "int16.nii");
  EXPECT_EQ(source->dims(), kDims);
  EXPECT_TRUE(source->can_skip());
  EXPECT_EQ(import_finest<int16_t>(*source, dir.file("s")), expected<int16_t>(kDims, f));
  // The file's qform says origin (1, 2, 3); the sform, which wins, (10.5, -20.25, 30).
  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_EQ(m.spacing, Vec3d(0.5, 0.75, 1.25));
  EXPECT_EQ(m.origin, Vec3d(10.5, -20.25, 30));
  const auto j = nlohmann::json::parse(m.source);
  EXPECT_EQ(j["kind"], "nifti");
  EXPECT_EQ(j["version"], 1);
  EXPECT_EQ(j["datatype"], "INT16");
  EXPECT_EQ(j["qform_code"], 1);
  EXPECT_EQ(j["sform_code"], 1);
  EXPECT_EQ(j["affine_from"], "sform");
  EXPECT_EQ(j["affine_code_name"], "Scanner Anat");
  EXPECT_EQ(j["affine"], nlohmann::json({0.5, 0, 0, 10.5, 0, 0.75, 0, -20.25, 0, 0, 1.25, 30, 0, 0, 0, 1}));
  EXPECT_FALSE(j.contains("scl_slope")) << "slope 1, intercept 0 is no scaling";
  EXPECT_EQ(source->input_bytes(), uint64_t(7 * 6 * 5 * 2));
}

TEST(Nifti, GzipFloatsStreamInOrderAndRewind) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  auto source = open_nifti_source(kData + "float32.nii.gz");
  EXPECT_FALSE(source->can_skip());
  const auto want = expected<float>(kDims, [](auto x, auto y, auto z) { return f(x, y, z) / 4.0; });
  EXPECT_EQ(import_finest<float>(*source, dir.file("s")), want);
  // Read again after a rewind: the stream starts over.
  source->rewind();
  std::vector<float> again(want.size());
  source->read_slab(0, 2, {reinterpret_cast<std::byte*>(again.data()), 2 * 42 * sizeof(float)});
  source->read_slab(2, 5, {reinterpret_cast<std::byte*>(again.data() + 2 * 42), 3 * 42 * sizeof(float)});
  EXPECT_EQ(again, want);
  EXPECT_EQ(provenance(*source)["compressed"], true);
}

TEST(Nifti, PlainFilesSkipSlicesAndRewind) {
  SKIP_WITHOUT_NIFTI();
  auto source = open_nifti_source(kData + "int16.nii");
  const auto want = expected<int16_t>(kDims, f);
  std::vector<int16_t> slab(42 * 2);
  source->read_slab(3, 5, {reinterpret_cast<std::byte*>(slab.data()), slab.size() * 2});
  EXPECT_EQ(slab, std::vector<int16_t>(want.begin() + 3 * 42, want.end()));
  source->rewind();
  source->read_slab(0, 2, {reinterpret_cast<std::byte*>(slab.data()), slab.size() * 2});
  EXPECT_EQ(slab, std::vector<int16_t>(want.begin(), want.begin() + 2 * 42));
}

TEST(Nifti, HdrImgPairIsReadByEitherName) {
  SKIP_WITHOUT_NIFTI();
  const auto want = expected<uint8_t>(kDims, [](auto x, auto y, auto z) { return f(x, y, z) + 100; });
  for (const char* name : {"uint8.hdr", "uint8.img"}) {
    testing::TempDir dir;
    auto source = open_nifti_source(kData + name);
    EXPECT_EQ(import_finest<uint8_t>(*source, dir.file("s")), want) << name;
    if (std::string(name) == "uint8.hdr") {
      EXPECT_EQ(provenance(*source)["data"], kData + "uint8.img");
    }
  }
}

TEST(Nifti, Nifti2FileIsReadAndUnsignedShortsBeyondI16StayU16) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  auto source = open_nifti_source(kData + "nifti2.nii");
  EXPECT_EQ(provenance(*source)["version"], 2);
  EXPECT_EQ(import_finest<uint16_t>(*source, dir.file("s")),
            expected<uint16_t>(kDims, [](auto x, auto y, auto z) { return (f(x, y, z) + 100) * 200; }));
  EXPECT_EQ(Store(dir.file("s")).manifest().origin, Vec3d(10.5, -20.25, 30));
}

TEST(Nifti, BigEndianFileIsSwapped) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  auto source = open_nifti_source(kData + "bigendian.nii");
  EXPECT_EQ(provenance(*source)["byte_order"], "big");
  EXPECT_EQ(import_finest<int16_t>(*source, dir.file("s")), expected<int16_t>(kDims, f));
}

TEST(Nifti, WholeScalingThatFitsI16IsStoredAsI16Exactly) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  // u8 values scaled by 2 and -1024 lie in [-1024, -514]: i16 holds them, known from the type alone.
  auto source = open_nifti_source(kData + "scaled_uint8.nii");
  EXPECT_FALSE(source->conversion());
  EXPECT_EQ(import_finest<int16_t>(*source, dir.file("s")),
            expected<int16_t>(kDims, [](auto x, auto y, auto z) { return 2 * (f(x, y, z) + 100) - 1024; }));
  const auto j = provenance(*source);
  EXPECT_EQ(j["scl_slope"], 2.0);
  EXPECT_EQ(j["scl_inter"], -1024.0);
}

TEST(Nifti, WholeScalingOfShortsIsMeasuredBeforeTheTypeIsChosen) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  // i16 data with intercept -1024 (CT) may leave i16 by its type's range; this file's values do
  // not, so a measuring pass keeps them i16. Scaled by 1000 they do, and become exact f32.
  const std::string bytes = testing::read_file(kData + "int16.nii");
  const auto scaled = [&](float slope, float inter, const std::string& name) {
    std::string b = bytes;
    std::memcpy(b.data() + 112, &slope, 4);  // scl_slope, then scl_inter
    std::memcpy(b.data() + 116, &inter, 4);
    write(dir.file(name), b);
    return open_nifti_source(dir.file(name));
  };
  auto ct = scaled(1, -1024, "ct.nii");
  EXPECT_FALSE(ct->conversion());
  ASSERT_TRUE(ct->value_range_hint());
  EXPECT_EQ(ct->value_range_hint()->lo, -1124);
  EXPECT_EQ(import_finest<int16_t>(*ct, dir.file("ct")),
            expected<int16_t>(kDims, [](auto x, auto y, auto z) { return f(x, y, z) - 1024; }));
  auto wide = scaled(1000, 0, "wide.nii");
  ASSERT_TRUE(wide->conversion());
  EXPECT_TRUE(wide->conversion()->exact());
  EXPECT_EQ(import_finest<float>(*wide, dir.file("wide")),
            expected<float>(kDims, [](auto x, auto y, auto z) { return f(x, y, z) * 1000.0; }));
}

TEST(Nifti, FractionalScalingIsStoredAsF32) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  auto source = open_nifti_source(kData + "scaled_float.nii");
  ASSERT_TRUE(source->conversion());
  EXPECT_TRUE(source->conversion()->exact());
  ASSERT_TRUE(source->value_range_hint());
  EXPECT_EQ(source->value_range_hint()->lo, -100 * 0.5 + 0.25);
  EXPECT_EQ(import_finest<float>(*source, dir.file("s")),
            expected<float>(kDims, [](auto x, auto y, auto z) { return f(x, y, z) * 0.5 + 0.25; }));
}

TEST(Nifti, Int32WithinTwoTo24ConvertsExactlyAndBeyondNeedsConvert) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  auto source = open_nifti_source(kData + "int32.nii");
  ASSERT_TRUE(source->conversion());
  EXPECT_TRUE(source->conversion()->exact());
  EXPECT_EQ(import_finest<float>(*source, dir.file("s")),
            expected<float>(kDims, [](auto x, auto y, auto z) { return f(x, y, z) * 40000.0; }));

  // The first voxel made 2^24 + 1, which f32 rounds: refused unless --convert f32.
  std::string bytes = testing::read_file(kData + "int32.nii");
  const int32_t wide = (1 << 24) + 1;
  std::memcpy(bytes.data() + 352, &wide, 4);
  write(dir.file("wide.nii"), bytes);
  const Error e = error_of([&] { open_nifti_source(dir.file("wide.nii")); });
  EXPECT_EQ(e.field(), "--convert");
  EXPECT_TRUE(mentions(e, "wide.nii")) << e.what();
  NiftiOptions accept;
  accept.convert.accept_rounding = true;
  EXPECT_EQ(open_nifti_source(dir.file("wide.nii"), accept)->conversion()->inexact, 1u);
}

TEST(Nifti, FourDimensionalFileNeedsATimeStepAndImportsTheOneChosen) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  const Error none = error_of([] { open_nifti_source(kData + "4d.nii"); });
  EXPECT_EQ(none.code(), Errc::invalid_argument);
  EXPECT_EQ(none.field(), "--time-step");
  EXPECT_TRUE(mentions(none, "3 time steps")) << none.what();

  NiftiOptions o;
  o.time_step = 2;
  auto source = open_nifti_source(kData + "4d.nii", o);
  EXPECT_EQ(source->input_bytes(), uint64_t(7 * 6 * 5 * 2)) << "one volume";
  EXPECT_EQ(import_finest<int16_t>(*source, dir.file("s")),
            expected<int16_t>(kDims, [](auto x, auto y, auto z) { return f(x, y, z) + 2000; }));
  EXPECT_EQ(provenance(*source)["time_step"], 2);

  for (int64_t bad : {int64_t(3), int64_t(-1)}) {
    o.time_step = bad;
    const Error e = error_of([&] { open_nifti_source(kData + "4d.nii", o); });
    EXPECT_EQ(e.field(), "--time-step");
    EXPECT_TRUE(mentions(e, "3 steps (0 to 2)")) << e.what();
  }
}

TEST(Nifti, QformOnlyFileTakesItsOriginFromTheQform) {
  SKIP_WITHOUT_NIFTI();
  auto source = open_nifti_source(kData + "qform.nii");
  EXPECT_EQ(source->spacing(), Vec3d(1, 2, 3));
  EXPECT_EQ(source->origin(), Vec3d(-3, 4.5, 7));
  EXPECT_EQ(provenance(*source)["affine_from"], "qform");
}

TEST(Nifti, TwoDimensionalImageIsOneSlice) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  auto source = open_nifti_source(kData + "slice2d.nii");
  EXPECT_EQ(source->dims(), Vec3s(7, 6, 1));
  EXPECT_EQ(import_finest<uint8_t>(*source, dir.file("s")),
            expected<uint8_t>(Vec3s(7, 6, 1), [](auto x, auto y, auto z) { return f(x, y, z) + 100; }));
}

TEST(Nifti, UnsupportedDatatypeIsRefusedByCodeAndName) {
  SKIP_WITHOUT_NIFTI();
  const Error e = error_of([] { open_nifti_source(kData + "complex64.nii"); });
  EXPECT_EQ(e.code(), Errc::unsupported);
  EXPECT_EQ(e.field(), "datatype");
  EXPECT_TRUE(mentions(e, "complex64.nii") && mentions(e, "datatype 32 (COMPLEX64)")) << e.what();
}

TEST(Nifti, TruncatedFileIsRefusedWithItsByteCounts) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  const std::string bytes = testing::read_file(kData + "int16.nii");
  write(dir.file("cut.nii"), bytes.substr(0, bytes.size() - 100));
  const Error e = error_of([&] { open_nifti_source(dir.file("cut.nii")); });
  EXPECT_EQ(e.code(), Errc::format);
  EXPECT_EQ(e.file(), dir.file("cut.nii"));
  EXPECT_TRUE(mentions(e, "truncated: 320 bytes from byte 352") && mentions(e, "needs 420")) << e.what();

  // Compressed, the shortfall shows only when the stream runs out.
  const std::string gz = testing::read_file(kData + "float32.nii.gz");
  write(dir.file("cut.nii.gz"), gz.substr(0, gz.size() - 100));
  auto source = open_nifti_source(dir.file("cut.nii.gz"));
  std::vector<std::byte> all(7 * 6 * 5 * 4);
  const Error s = error_of([&] { source->read_slab(0, 5, all); });
  EXPECT_EQ(s.file(), dir.file("cut.nii.gz"));
  EXPECT_TRUE(mentions(s, "truncated") && mentions(s, "needs 840")) << s.what();
}

TEST(Nifti, CorruptGzipIsRefused) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  // A small file is inflated whole when its header is read: the header read fails, and the
  // error says why.
  std::string gz = testing::read_file(kData + "float32.nii.gz");
  for (size_t i = gz.size() - 60; i < gz.size() - 50; ++i) gz[i] = char(gz[i] ^ 0x5a);
  write(dir.file("bad.nii.gz"), gz);
  const Error e = error_of([&] { open_nifti_source(dir.file("bad.nii.gz")); });
  EXPECT_EQ(e.file(), dir.file("bad.nii.gz"));
  EXPECT_TRUE(mentions(e, "gzip data is corrupt")) << e.what();

#if BRICKYARD_TEST_GZIP
  // A larger one fails while streaming: in the middle, or only at its checksum after the last
  // slice (which the source reads on to check).
  std::string nii = testing::read_file(kData + "int16.nii").substr(0, 352);
  const int16_t size = 64;
  for (int a = 1; a <= 3; ++a) std::memcpy(nii.data() + 40 + 2 * a, &size, 2);
  uint32_t state = 12345;
  for (size_t i = 0; i < size_t(64 * 64 * 64 * 2); ++i) {
    state = state * 1664525u + 1013904223u;  // noise, which deflate cannot shrink
    nii.push_back(char(state >> 24));
  }
  const std::string packed = [&] {
    z_stream zs{};
    deflateInit2(&zs, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);
    std::string out(deflateBound(&zs, uLong(nii.size())), '\0');
    zs.next_in = reinterpret_cast<Bytef*>(nii.data());
    zs.avail_in = uInt(nii.size());
    zs.next_out = reinterpret_cast<Bytef*>(out.data());
    zs.avail_out = uInt(out.size());
    deflate(&zs, Z_FINISH);
    out.resize(zs.total_out);
    deflateEnd(&zs);
    return out;
  }();
  write(dir.file("good.nii.gz"), packed);
  std::vector<std::byte> all(size_t(64 * 64 * 64 * 2));
  open_nifti_source(dir.file("good.nii.gz"))->read_slab(0, 64, all);
  EXPECT_EQ(std::memcmp(all.data(), nii.data() + 352, all.size()), 0);

  std::string middle = packed, checksum = packed;
  for (size_t i = 0; i < 64; ++i) middle[middle.size() / 2 + i] = char(~middle[middle.size() / 2 + i]);
  checksum[checksum.size() - 8] = char(~checksum[checksum.size() - 8]);  // the CRC-32
  write(dir.file("middle.nii.gz"), middle);
  write(dir.file("checksum.nii.gz"), checksum);
  for (const char* name : {"middle.nii.gz", "checksum.nii.gz"}) {
    auto source = open_nifti_source(dir.file(name));
    const Error s = error_of([&] { source->read_slab(0, 64, all); });
    EXPECT_EQ(s.file(), dir.file(name));
    EXPECT_TRUE(mentions(s, "gzip data is corrupt")) << s.what();
  }
#endif
}

TEST(Nifti, HeaderGarbageIsRefusedNamingTheFile) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  std::string junk;
  for (int i = 0; i < 600; ++i) junk.push_back(char(i * 37 + 11));
  write(dir.file("junk.nii"), junk);
  const Error e = error_of([&] { open_nifti_source(dir.file("junk.nii")); });
  EXPECT_EQ(e.code(), Errc::format);
  EXPECT_EQ(e.file(), dir.file("junk.nii"));
  EXPECT_EQ(e.field(), "sizeof_hdr");

  write(dir.file("short.nii"), testing::read_file(kData + "int16.nii").substr(0, 200));
  const Error s = error_of([&] { open_nifti_source(dir.file("short.nii")); });
  EXPECT_TRUE(mentions(s, "header is truncated: 200 bytes")) << s.what();
}

TEST(Nifti, ZeroOrNegativeSizeIsRefusedNamingDim) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  for (const int16_t size : {int16_t(0), int16_t(-4)}) {
    std::string bytes = testing::read_file(kData + "int16.nii");
    std::memcpy(bytes.data() + 40 + 2 * 2, &size, 2);  // dim[2]
    write(dir.file("dims.nii"), bytes);
    const Error e = error_of([&] { open_nifti_source(dir.file("dims.nii")); });
    EXPECT_EQ(e.field(), "dim");
    EXPECT_TRUE(mentions(e, "dim[2] is " + std::to_string(size))) << e.what();
  }
}

TEST(Nifti, MissingFilesAreRefusedByName) {
  SKIP_WITHOUT_NIFTI();
  testing::TempDir dir;
  const Error e = error_of([&] { open_nifti_source(dir.file("none.nii")); });
  EXPECT_EQ(e.file(), dir.file("none.nii"));
  // A header without its image file.
  write(dir.file("lone.hdr"), testing::read_file(kData + "uint8.hdr"));
  const Error img = error_of([&] { open_nifti_source(dir.file("lone.hdr")); });
  EXPECT_TRUE(mentions(img, "lone.img")) << img.what();
}

}  // namespace
}  // namespace brickyard
