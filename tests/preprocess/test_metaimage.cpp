// The MetaImage importer against files written by VTK's vtkMetaImageWriter (MetaIO itself:
// tests/data/metaimage/make_files.py), whose values are a known formula of the voxel index, and
// against variants that writer cannot produce (big-endian data, a rotation, compressed int),
// written here by hand. Bad files are written into a temporary directory.

#include <gtest/gtest.h>

#if BRICKYARD_TEST_GZIP
#include <zlib.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <vector>

#include <nlohmann/json.hpp>

#include "builder_test_util.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "test_util.h"

namespace brickyard {
namespace {

const std::string kData = BRICKYARD_SOURCE_DIR "/tests/data/metaimage/";
const Vec3s kDims{7, 6, 5};

/// The generator's formula (make_files.py): every file's values are a function of it.
int f(int64_t x, int64_t y, int64_t z) { return int((x * 7 + y * 13 + z * 29) % 251); }

template <typename T>
std::vector<T> expected(const std::function<T(int)>& value, const Vec3s& dims = kDims) {
  std::vector<T> v;
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) v.push_back(value(f(x, y, z)));
  return v;
}

template <typename S>
std::string to_bytes(const std::vector<S>& v, bool big_endian = false) {
  std::string out(v.size() * sizeof(S), '\0');
  std::memcpy(out.data(), v.data(), out.size());
  if (big_endian)
    for (size_t i = 0; i < v.size(); ++i) std::reverse(out.begin() + long(i * sizeof(S)), out.begin() + long((i + 1) * sizeof(S)));
  return out;
}

#if BRICKYARD_TEST_GZIP
/// zlib's compress2 output (RFC 1950), what MetaIO writes.
std::string zlib_compress(const std::string& data) {
  uLongf size = compressBound(uLong(data.size()));
  std::string out(size, '\0');
  compress2(reinterpret_cast<Bytef*>(out.data()), &size, reinterpret_cast<const Bytef*>(data.data()), uLong(data.size()), 6);
  out.resize(size);
  return out;
}
#endif

/// A header of 7x6x5 voxels of `type` with `extra` lines, ending with ElementDataFile = LOCAL.
std::string header(const std::string& type, const std::string& extra = "") {
  return "ObjectType = Image\nNDims = 3\nBinaryData = True\n" + extra + "DimSize = 7 6 5\nElementType = " + type +
         "\nElementDataFile = LOCAL\n";
}

template <typename T>
std::vector<T> import_finest(const std::string& file, const std::string& store_dir, const ConvertOptions& convert = {}) {
  auto source = open_metaimage_source(file, convert);
  BuildOptions o;
  o.brick_size = 8;
  build_store(*source, store_dir, o);
  Store store(store_dir);
  return testing::read_level<T>(store, store.layout().finest()).v;
}

nlohmann::json source_of(const std::string& store_dir) {
  return nlohmann::json::parse(Store(store_dir).manifest().source);
}

TEST(MetaImage, AttachedShortKeepsNegativeValuesExactly) {
  testing::TempDir dir;
  const std::string file = kData + "short_attached.mha";
  EXPECT_EQ(open_metaimage_source(file)->type(), ValueType::i16);
  EXPECT_EQ(open_metaimage_source(file)->dims(), kDims);
  EXPECT_EQ(import_finest<int16_t>(file, dir.file("s")), expected<int16_t>([](int v) { return int16_t(v - 100); }));
  const nlohmann::json src = source_of(dir.file("s"));
  EXPECT_EQ(src["kind"], "metaimage");
  EXPECT_EQ(src["path"], file);
  EXPECT_EQ(src["data"], file);
  EXPECT_EQ(src["element_type"], "MET_SHORT");
  EXPECT_EQ(src["compression"], "none");
  EXPECT_EQ(src["endianness"], "little");
  EXPECT_EQ(src["anatomical_orientation"], "???");
}

TEST(MetaImage, DetachedUnsignedCharIsPlacedByElementSpacingAndOffset) {
  testing::TempDir dir;
  const std::string file = kData + "uchar_detached.mhd";
  auto source = open_metaimage_source(file);
  EXPECT_EQ(source->type(), ValueType::u8);
  EXPECT_TRUE(source->can_skip());  // memory-mapped through the raw source
  EXPECT_EQ(import_finest<uint8_t>(file, dir.file("s")), expected<uint8_t>([](int v) { return uint8_t(v); }));
  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_EQ(m.spacing, Vec3d(0.5, 1.25, 2));
  EXPECT_EQ(m.origin, Vec3d(-3.5, 1, 10.25));
  const nlohmann::json src = nlohmann::json::parse(m.source);
  EXPECT_EQ(src["path"], file);
  EXPECT_EQ(src["data"], kData + "uchar_detached.raw");
  EXPECT_EQ(src["element_type"], "MET_UCHAR");
}

TEST(MetaImage, CompressedDataStreamsSlabBySlab) {
  testing::TempDir dir;
#if BRICKYARD_TEST_GZIP
  auto source = open_metaimage_source(kData + "float_compressed.mha");
  EXPECT_EQ(source->type(), ValueType::f32);
  EXPECT_FALSE(source->can_skip());
  EXPECT_EQ(import_finest<float>(kData + "float_compressed.mha", dir.file("f")),
            expected<float>([](int v) { return float(v - 100) / 4.0f; }));
  EXPECT_EQ(source_of(dir.file("f"))["compression"], "zlib");
  // Detached compressed data (.mhd naming a .zraw).
  EXPECT_EQ(import_finest<uint16_t>(kData + "ushort_compressed.mhd", dir.file("u")),
            expected<uint16_t>([](int v) { return uint16_t(v * 100); }));
  // Read twice: rewind starts the stream over.
  source = open_metaimage_source(kData + "float_compressed.mha");
  std::vector<std::byte> a(size_t(volume(kDims)) * 4), b(a.size());
  source->read_slab(0, 2, std::span(a).first(size_t(2 * 7 * 6 * 4)));
  source->read_slab(2, 5, std::span(a).subspan(size_t(2 * 7 * 6 * 4)));
  source->rewind();
  source->read_slab(0, 5, b);
  EXPECT_EQ(a, b);
#else
  try {
    open_metaimage_source(kData + "float_compressed.mha");
    ADD_FAILURE() << "opened compressed data without zlib";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("needs zlib"), std::string::npos) << e.what();
  }
#endif
}

TEST(MetaImage, TwoDimensionalImageIsOneSliceThick) {
#if BRICKYARD_TEST_GZIP
  testing::TempDir dir;
  const Vec3s dims{7, 6, 1};
  EXPECT_EQ(open_metaimage_source(kData + "uchar_2d.mha")->dims(), dims);
  EXPECT_EQ(import_finest<uint8_t>(kData + "uchar_2d.mha", dir.file("s")),
            expected<uint8_t>([](int v) { return uint8_t(v); }, dims));
#endif
}

// vtkMetaImageWriter writes the machine's byte order only: big-endian files are written here,
// under both of MetaIO's names for the byte order.
TEST(MetaImage, BigEndianDataIsSwapped) {
  testing::TempDir dir;
  const auto u16 = expected<uint16_t>([](int v) { return uint16_t(v * 257); });
  std::ofstream(dir.file("be.mha"), std::ios::binary) << header("MET_USHORT", "ElementByteOrderMSB = True\n") << to_bytes(u16, true);
  EXPECT_EQ(import_finest<uint16_t>(dir.file("be.mha"), dir.file("be")), u16);
  EXPECT_EQ(source_of(dir.file("be"))["endianness"], "big");
#if BRICKYARD_TEST_GZIP
  const auto i16 = expected<int16_t>([](int v) { return int16_t((v - 125) * 200); });
  const std::string packed = zlib_compress(to_bytes(i16, true));
  std::ofstream(dir.file("bez.mha"), std::ios::binary)
      << header("MET_SHORT", "BinaryDataByteOrderMSB = True\nCompressedData = True\nCompressedDataSize = " +
                                 std::to_string(packed.size()) + "\n")
      << packed;
  EXPECT_EQ(import_finest<int16_t>(dir.file("bez.mha"), dir.file("bez")), i16);
#endif
}

TEST(MetaImage, IntWithin2To24ConvertsExactly) {
  testing::TempDir dir;
  const std::string file = kData + "int_attached.mha";
  auto source = open_metaimage_source(file);
  EXPECT_EQ(source->type(), ValueType::f32);
  ASSERT_TRUE(source->conversion());
  EXPECT_TRUE(source->conversion()->exact());
  const auto values = expected<float>([](int v) { return float((v - 100) * 65536); });
  EXPECT_EQ(source->conversion()->min, *std::min_element(values.begin(), values.end()));  // -100 * 65536
  EXPECT_EQ(source->conversion()->max, *std::max_element(values.begin(), values.end()));  // 123 * 65536
  EXPECT_EQ(import_finest<float>(file, dir.file("i")), values);
  EXPECT_TRUE(source_of(dir.file("i")).contains("conversion"));
}

TEST(MetaImage, DoubleConvertsWithItsRelativeErrorReported) {
  testing::TempDir dir;
  const std::string file = kData + "double_attached.mha";
  auto source = open_metaimage_source(file);
  EXPECT_EQ(source->type(), ValueType::f32);
  ASSERT_TRUE(source->conversion());
  double worst = 0;
  for (const double d : expected<double>([](int v) { return (v - 100) / 10.0; }))
    if (d != 0) worst = std::max(worst, std::fabs(double(float(d)) - d) / std::fabs(d));
  EXPECT_GT(worst, 0);
  EXPECT_EQ(source->conversion()->max_rel_error, worst);
  EXPECT_NE(source->conversion()->summary().find("largest relative error"), std::string::npos);
  EXPECT_EQ(import_finest<float>(file, dir.file("d")), expected<float>([](int v) { return float((v - 100) / 10.0); }));
}

// Compressed data of a type a store does not hold: measured in a pass before the build, refused
// beyond 2^24 unless --convert f32 accepts the rounding, then streamed again.
TEST(MetaImage, CompressedIntIsMeasuredBeforeTheBuild) {
#if BRICKYARD_TEST_GZIP
  testing::TempDir dir;
  auto i32 = expected<int32_t>([](int v) { return (v - 100) * 1000; });
  i32[17] = (1 << 24) + 1;  // rounds to 2^24
  const std::string packed = zlib_compress(to_bytes(i32));
  std::ofstream(dir.file("i.mha"), std::ios::binary)
      << header("MET_INT", "CompressedData = True\nCompressedDataSize = " + std::to_string(packed.size()) + "\n") << packed;
  try {
    open_metaimage_source(dir.file("i.mha"));
    ADD_FAILURE() << "rounded i32 values without --convert f32";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("--convert f32"), std::string::npos) << e.what();
  }
  ConvertOptions accept;
  accept.accept_rounding = true;
  EXPECT_EQ(open_metaimage_source(dir.file("i.mha"), accept)->conversion()->inexact, 1u);
  std::vector<float> as_float(i32.begin(), i32.end());
  EXPECT_EQ(import_finest<float>(dir.file("i.mha"), dir.file("s"), accept), as_float);
#endif
}

// VTK writes an identity TransformMatrix only: a rotated header is written here, with the
// spaces, CRLF line ends and synonyms (Position, Orientation, ElementSize) other writers use.
TEST(MetaImage, TransformMatrixAndOrientationAreRecordedNotApplied) {
  testing::TempDir dir;
  const auto u8 = expected<uint8_t>([](int v) { return uint8_t(v); });
  std::ofstream(dir.file("rot.mha"), std::ios::binary)
      << "ObjectType = Image\r\n  NDims=3  \r\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\r\nCenterOfRotation = 1 2 3\r\n"
         "Position = 4 5 6\r\nElementSize = 2 3 4\r\nAnatomicalOrientation = RAI\r\nSomeUnknownKey = ignored\r\n"
         "DimSize = 7 6 5\r\nElementType = MET_UCHAR\r\nElementDataFile = LOCAL\r\n"
      << to_bytes(u8);
  EXPECT_EQ(import_finest<uint8_t>(dir.file("rot.mha"), dir.file("s")), u8);
  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_EQ(m.spacing, Vec3d(2, 3, 4));  // ElementSize, there being no ElementSpacing
  EXPECT_EQ(m.origin, Vec3d(4, 5, 6));   // not rotated: the grid is axis-aligned
  const nlohmann::json src = nlohmann::json::parse(m.source);
  EXPECT_EQ(src["transform"]["matrix"], nlohmann::json({0, 1, 0, -1, 0, 0, 0, 0, 1}));
  EXPECT_EQ(src["transform"]["center_of_rotation"], nlohmann::json({1, 2, 3}));
  EXPECT_EQ(src["anatomical_orientation"], "RAI");
  EXPECT_FALSE(src.contains("SomeUnknownKey"));
}

void expect_error(const std::string& path, Errc code, const std::string& text) {
  try {
    auto source = open_metaimage_source(path);
    std::vector<std::byte> slab(size_t(volume(source->dims())) * size_of(source->type()));
    source->read_slab(0, source->dims().z, slab);
    FAIL() << "accepted " << path;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

TEST(MetaImage, BadFilesAreClearErrors) {
  testing::TempDir dir;
  auto write = [&](const std::string& name, const std::string& content) {
    std::ofstream(dir.file(name), std::ios::binary) << content;
    return dir.file(name);
  };
  const std::string voxels(7 * 6 * 5, '\1');
  expect_error(write("short.mha", header("MET_UCHAR") + std::string(100, '\1')), Errc::format,
               "field 'DimSize': data is truncated: 100 bytes after the header, but DimSize 7x6x5 of MET_UCHAR needs 210");
  expect_error(write("long.mha", header("MET_UCHAR") + voxels + "x"), Errc::format, "data is longer than DimSize says");
  expect_error(write("nodims.mha", "NDims = 3\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" + voxels), Errc::format,
               "field 'DimSize': missing required key");
  expect_error(write("twodims.mha", "NDims = 3\nDimSize = 7 6\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" + voxels),
               Errc::format, "field 'DimSize': '7 6' has 2 sizes, NDims 3 needs 3");
  expect_error(write("zerodim.mha", "NDims = 3\nDimSize = 7 0 5\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"),
               Errc::format, "every size must be at least 1");
  expect_error(write("ndims.mha", "NDims = 4\nDimSize = 7 6 5 1\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" + voxels),
               Errc::unsupported, "field 'NDims': NDims 4");
  expect_error(write("type.mha", header("MET_BLOB") + voxels), Errc::format, "field 'ElementType': unknown ElementType 'MET_BLOB'");
  expect_error(write("long_type.mha", header("MET_LONG") + voxels), Errc::unsupported,
               "field 'ElementType': ElementType 'MET_LONG' is not supported");
  expect_error(write("rgb.mha", header("MET_UCHAR", "ElementNumberOfChannels = 3\n") + voxels + voxels + voxels),
               Errc::unsupported, "field 'ElementNumberOfChannels': 3 channels per voxel");
  expect_error(write("ascii.mha", header("MET_UCHAR", "BinaryData = False\n") + "1 2 3\n"), Errc::unsupported,
               "field 'BinaryData'");
  expect_error(write("tube.mha", "ObjectType = Tube\nNDims = 3\nDimSize = 7 6 5\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"), Errc::unsupported, "ObjectType 'Tube'");
  expect_error(write("missing.mhd", "NDims = 3\nDimSize = 7 6 5\nElementType = MET_UCHAR\nElementDataFile = nothere.raw\n"),
               Errc::not_found, "field 'ElementDataFile': the data file 'nothere.raw' does not exist");
  expect_error(write("list.mhd", "NDims = 3\nDimSize = 7 6 5\nElementType = MET_UCHAR\nElementDataFile = LIST 2D\na.raw\n"),
               Errc::unsupported, "field 'ElementDataFile'");
  expect_error(write("pattern.mhd", "NDims = 3\nDimSize = 7 6 5\nElementType = MET_UCHAR\nElementDataFile = s%03d.raw 1 5 1\n"),
               Errc::unsupported, "data split over several files");
  expect_error(write("noend.mha", "NDims = 3\nDimSize = 7 6 5\nElementType = MET_UCHAR\n"), Errc::format,
               "no ElementDataFile line");
  expect_error(write("binary.mha", std::string("\x89PNG\r\n\x1a\n", 8) + voxels), Errc::format, "not a MetaImage header");
  expect_error(write("bigsize.mha", header("MET_UCHAR", "CompressedData = True\nCompressedDataSize = 5000\n") + voxels),
               Errc::format, "field 'CompressedDataSize': CompressedDataSize 5000 is larger than the 210 bytes after the header");
#if BRICKYARD_TEST_GZIP
  // The VTK file with its deflate blocks damaged (its two-byte zlib header kept).
  std::string damaged = testing::read_file(kData + "float_compressed.mha");
  const size_t data = damaged.find("ElementDataFile = LOCAL\n") + 24;
  for (size_t i = data + 2; i + 4 < damaged.size(); ++i) damaged[i] = char(damaged[i] ^ 0x5a);
  expect_error(write("corrupt.mha", damaged), Errc::format, "field 'CompressedData': the zlib data is corrupt after");
  const std::string part = zlib_compress(std::string(100, '\1'));
  expect_error(write("zshort.mha", header("MET_UCHAR", "CompressedData = True\nCompressedDataSize = " +
                                                           std::to_string(part.size()) + "\n") + part),
               Errc::format, "the compressed data ends after 100 decompressed bytes, but DimSize 7x6x5 of MET_UCHAR needs 210");
  const std::string more = zlib_compress(voxels + voxels);
  expect_error(write("zlong.mha", header("MET_UCHAR", "CompressedData = True\nCompressedDataSize = " +
                                                          std::to_string(more.size()) + "\n") + more),
               Errc::format, "holds more than the 210 bytes DimSize 7x6x5 of MET_UCHAR needs");
#endif
}

}  // namespace
}  // namespace brickyard
