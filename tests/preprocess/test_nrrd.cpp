#include <gtest/gtest.h>

#if BRICKYARD_TEST_GZIP
#include <zlib.h>
#endif

#include <cstring>
#include <fstream>
#include <vector>

#include "builder_test_util.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "test_util.h"

namespace brickyard {
namespace {

template <typename S>
std::string to_bytes(const std::vector<S>& v, bool big_endian = false) {
  std::string out(v.size() * sizeof(S), '\0');
  std::memcpy(out.data(), v.data(), out.size());
  if (big_endian)
    for (size_t i = 0; i < v.size(); ++i) std::reverse(out.begin() + long(i * sizeof(S)), out.begin() + long((i + 1) * sizeof(S)));
  return out;
}

#if BRICKYARD_TEST_GZIP
std::string gzip(const std::string& data) {
  z_stream zs{};
  deflateInit2(&zs, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);  // +16: gzip wrapper
  std::string out(deflateBound(&zs, uLong(data.size())), '\0');
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  zs.avail_in = uInt(data.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = uInt(out.size());
  deflate(&zs, Z_FINISH);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}
#endif

template <typename T>
std::vector<T> import_finest(const std::string& nrrd, const std::string& store_dir) {
  auto source = open_nrrd_source(nrrd);
  BuildOptions o;
  o.brick_size = 8;
  build_store(*source, store_dir, o);
  Store store(store_dir);
  return testing::read_level<T>(store, store.layout().finest()).v;
}

TEST(Nrrd, AttachedRawUnsignedChar) {
  testing::TempDir dir;
  std::vector<uint8_t> v(5 * 6 * 7);
  for (size_t i = 0; i < v.size(); ++i) v[i] = uint8_t(i * 13);
  std::ofstream(dir.file("a.nrrd"), std::ios::binary)
      << "NRRD0004\n# a comment\ntype: unsigned char\ndimension: 3\nsizes: 5 6 7\nencoding: raw\n"
         "spacings: 0.5 1 2\nspace origin: (1,2,3)\n\n"
      << to_bytes(v);
  EXPECT_EQ(import_finest<uint8_t>(dir.file("a.nrrd"), dir.file("s")), v);
  const Manifest m = Store(dir.file("s")).manifest();
  EXPECT_EQ(m.spacing, Vec3d(0.5, 1, 2));
  EXPECT_EQ(m.origin, Vec3d(1, 2, 3));
  EXPECT_NE(m.source.find("\"kind\":\"nrrd\""), std::string::npos);
}

TEST(Nrrd, DetachedBigEndianUnsignedShortWithSpaceDirections) {
  testing::TempDir dir;
  std::vector<uint16_t> v(9 * 4 * 3);
  for (size_t i = 0; i < v.size(); ++i) v[i] = uint16_t(i * 611);
  std::ofstream(dir.file("d.raw"), std::ios::binary) << to_bytes(v, true);
  std::ofstream(dir.file("d.nhdr")) << "NRRD0005\ntype: uint16\ndimension: 3\nsizes: 9 4 3\nendian: big\nencoding: raw\n"
                                       "space directions: (0,0,3) (0,4,0) (2,0,0)\ndata file: d.raw\n";
  EXPECT_EQ(import_finest<uint16_t>(dir.file("d.nhdr"), dir.file("s")), v);
  EXPECT_EQ(Store(dir.file("s")).manifest().spacing, Vec3d(3, 4, 2));
}

TEST(Nrrd, GzipFloatStreamsAndSignedShortStaysSignedShort) {
  testing::TempDir dir;
#if BRICKYARD_TEST_GZIP
  std::vector<float> f(10 * 10 * 10);
  for (size_t i = 0; i < f.size(); ++i) f[i] = float(i) * 0.25f - 7.0f;
  std::ofstream(dir.file("g.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: float\ndimension: 3\nsizes: 10 10 10\nendian: little\nencoding: gzip\n\n" << gzip(to_bytes(f));
  EXPECT_EQ(import_finest<float>(dir.file("g.nrrd"), dir.file("s")), f);
#endif

  std::vector<int16_t> s(6 * 5 * 4);
  for (size_t i = 0; i < s.size(); ++i) s[i] = int16_t(int(i) * 300 - 20000);
  std::ofstream(dir.file("h.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: short\ndimension: 3\nsizes: 6 5 4\nendian: little\nencoding: raw\n\n" << to_bytes(s);
  EXPECT_EQ(open_nrrd_source(dir.file("h.nrrd"))->type(), ValueType::i16);
  EXPECT_EQ(import_finest<int16_t>(dir.file("h.nrrd"), dir.file("t")), s);
  // Big-endian signed bytes and shorts, gzip-streamed where zlib is there, stay native too.
  std::vector<int8_t> b(6 * 5 * 4);
  for (size_t i = 0; i < b.size(); ++i) b[i] = int8_t(int(i % 256) - 128);
  std::ofstream(dir.file("b.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: signed char\ndimension: 3\nsizes: 6 5 4\nencoding: raw\n\n" << to_bytes(b);
  EXPECT_EQ(import_finest<int8_t>(dir.file("b.nrrd"), dir.file("b")), b);
#if BRICKYARD_TEST_GZIP
  std::ofstream(dir.file("hz.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: int16\ndimension: 3\nsizes: 6 5 4\nendian: big\nencoding: gzip\n\n" << gzip(to_bytes(s, true));
  EXPECT_EQ(open_nrrd_source(dir.file("hz.nrrd"))->type(), ValueType::i16);
  EXPECT_EQ(import_finest<int16_t>(dir.file("hz.nrrd"), dir.file("hz")), s);
#endif
}

TEST(Nrrd, IntAndDoubleConvertToFloatWithTheirErrorMeasured) {
  testing::TempDir dir;
  // Integers within 2^24 convert exactly.
  std::vector<int32_t> small(4 * 4 * 4);
  for (size_t i = 0; i < small.size(); ++i) small[i] = int32_t(i) * 250000 - 8000000;
  std::ofstream(dir.file("i.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: int\ndimension: 3\nsizes: 4 4 4\nendian: little\nencoding: raw\n\n" << to_bytes(small);
  auto source = open_nrrd_source(dir.file("i.nrrd"));
  ASSERT_TRUE(source->conversion());
  EXPECT_TRUE(source->conversion()->exact());
  EXPECT_EQ(source->conversion()->min, -8000000);
  std::vector<float> expected(small.begin(), small.end());
  EXPECT_EQ(import_finest<float>(dir.file("i.nrrd"), dir.file("i")), expected);
  EXPECT_NE(Store(dir.file("i")).manifest().source.find("\"conversion\""), std::string::npos);

  // Beyond 2^24 they are refused, naming the option that accepts the rounding...
  std::vector<uint32_t> big(4 * 4 * 4, 7);
  big[5] = (1u << 24) + 1;  // rounds to 2^24
  std::ofstream(dir.file("u.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: uint\ndimension: 3\nsizes: 4 4 4\nendian: little\nencoding: raw\n\n" << to_bytes(big);
  try {
    open_nrrd_source(dir.file("u.nrrd"));
    ADD_FAILURE() << "rounded u32 values without --convert f32";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    for (const char* text : {"u.nrrd", "--convert f32", "1 of its u32 values", "by up to 1"})
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
  // ... which, accepted, is reported exactly.
  ConvertOptions accept;
  accept.accept_rounding = true;
  source = open_nrrd_source(dir.file("u.nrrd"), accept);
  EXPECT_EQ(source->conversion()->inexact, 1u);
  EXPECT_EQ(source->conversion()->max_abs_error, 1.0);
  EXPECT_EQ(source->conversion()->worst_value, double((1u << 24) + 1));

  // Doubles convert with their largest relative error reported.
  std::vector<double> d(4 * 4 * 4, 0.5);
  d[3] = 0.1;
  std::ofstream(dir.file("d.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: double\ndimension: 3\nsizes: 4 4 4\nendian: little\nencoding: raw\n\n" << to_bytes(d);
  source = open_nrrd_source(dir.file("d.nrrd"));
  EXPECT_EQ(source->type(), ValueType::f32);
  EXPECT_EQ(source->conversion()->inexact, 1u);
  EXPECT_DOUBLE_EQ(source->conversion()->max_rel_error, std::fabs(double(0.1f) - 0.1) / 0.1);
  EXPECT_NE(source->conversion()->summary().find("largest relative error"), std::string::npos);
}

void expect_error(const std::string& path, Errc code, const std::string& text) {
  try {
    auto source = open_nrrd_source(path);
    std::vector<std::byte> slab(size_t(volume(source->dims())) * size_of(source->type()));
    source->read_slab(0, source->dims().z, slab);
    FAIL() << "accepted " << path;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

TEST(Nrrd, BadFilesAreClearErrors) {
  testing::TempDir dir;
  std::ofstream(dir.file("magic.nrrd")) << "PNG\n";
  expect_error(dir.file("magic.nrrd"), Errc::format, "not a NRRD file");
  std::ofstream(dir.file("nosizes.nrrd")) << "NRRD0004\ntype: float\ndimension: 3\nencoding: raw\nendian: little\n\n";
  expect_error(dir.file("nosizes.nrrd"), Errc::format, "field 'sizes'");
  std::ofstream(dir.file("short.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nendian: little\nencoding: raw\n\n" << std::string(50, 'x');
  expect_error(dir.file("short.nrrd"), Errc::format, "truncated");
  std::ofstream(dir.file("ascii.nrrd")) << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n\n1 2 3 4 5 6 7 8\n";
  expect_error(dir.file("ascii.nrrd"), Errc::unsupported, "encoding 'ascii'");
  std::ofstream(dir.file("2d.nrrd")) << "NRRD0004\ntype: uchar\ndimension: 2\nsizes: 2 2\nencoding: raw\n\nabcd";
  expect_error(dir.file("2d.nrrd"), Errc::unsupported, "dimension 2");
#if BRICKYARD_TEST_GZIP
  std::ofstream(dir.file("gzshort.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: gzip\n\n" << gzip(std::string(100, 'x'));
  expect_error(dir.file("gzshort.nrrd"), Errc::format, "truncated");
  // zlib would pass bytes without a gzip header through as they are: named as not gzip.
  std::ofstream(dir.file("gznot.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: gzip\n\n" << std::string(5000, 'x');
  expect_error(dir.file("gznot.nrrd"), Errc::format, "starts with 78 78, not gzip's 1f 8b");
  std::string damaged = gzip(std::string(4096, 'x'));
  for (size_t i = 12; i < damaged.size() - 8; ++i) damaged[i] = char(damaged[i] ^ 0x5a);
  std::ofstream(dir.file("gzbad.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 16 16 16\nencoding: gzip\n\n" << damaged;
  expect_error(dir.file("gzbad.nrrd"), Errc::format, "the gzip data is corrupt after");
#endif
  std::ofstream(dir.file("flat.nrrd"), std::ios::binary)
      << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 1 0 1\nencoding: raw\n\n12345678";
  expect_error(dir.file("flat.nrrd"), Errc::format, "positive, finite");
  std::ofstream(dir.file("type.nrrd")) << "NRRD0004\ntype: block\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n12345678";
  expect_error(dir.file("type.nrrd"), Errc::unsupported, "NRRD type 'block'");
}

// Found by fuzzing (tests/fuzz/regressions/nrrd/): numbers in the header that do not fit were
// std::stoll's bare out_of_range, or undefined conversions and overflows.
TEST(Nrrd, HeaderNumbersThatDoNotFitAreClearErrors) {
  testing::TempDir dir;
  const std::string head = "NRRD0004\ntype: uchar\ndimension: 3\nencoding: raw\n";
  auto write = [&](const std::string& name, const std::string& fields) {
    std::ofstream(dir.file(name), std::ios::binary) << head << fields << "\n12345678";
    return dir.file(name);
  };
  expect_error(write("skip-text.nrrd", "sizes: 2 2 2\nbyte skip: ten\n"), Errc::format, "field 'byte skip': 'ten' is not an integer");
  expect_error(write("skip-big.nrrd", "sizes: 2 2 2\nbyte skip: 99999999999999999999\n"), Errc::format,
               "field 'byte skip': '99999999999999999999' is out of range");
  expect_error(write("skip-neg.nrrd", "sizes: 2 2 2\nbyte skip: -2\n"), Errc::format, "byte skip -2");
  expect_error(write("skip-far.nrrd", "sizes: 2 2 2\nbyte skip: 9223372036854775807\n"), Errc::format,
               "field 'byte skip': the data would start at byte");
  expect_error(write("huge.nrrd", "sizes: 1e300 1 1\n"), Errc::format, "field 'sizes'");
  expect_error(write("overflow.nrrd", "sizes: 4000000000 4000000000 4000000000\n"), Errc::format,
               "field 'sizes': sizes 4000000000x4000000000x4000000000 overflow a 64-bit byte count");
}

}  // namespace
}  // namespace brickyard
