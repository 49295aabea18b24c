#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/image.h"
#include "test_util.h"

namespace brickyard {
namespace {

TEST(Png, WritesAndReadsBackEveryPixel) {
  testing::TempDir dir;
  ImageRGBA8 img(37, 21);
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x)
      img(x, y) = {uint8_t(x * 7), uint8_t(y * 11), uint8_t(x ^ y), uint8_t(255 - x)};
  const std::string path = dir.file("a.png");
  write_png(path, img);
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
  const ImageRGBA8 back = read_png(path);
  ASSERT_EQ(back.width(), 37);
  ASSERT_EQ(back.height(), 21);
  EXPECT_EQ(back, img);
}

TEST(Png, ReadingGarbageNamesTheFile) {
  testing::TempDir dir;
  const std::string path = dir.file("not.png");
  std::ofstream(path) << "this is not a png";
  try {
    read_png(path);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.file(), path);
  }
}

TEST(Png, TruncatedFileIsAFormatError) {
  testing::TempDir dir;
  ImageRGBA8 img(64, 64, {1, 2, 3, 4});
  const std::string path = dir.file("t.png");
  write_png(path, img);
  std::filesystem::resize_file(path, std::filesystem::file_size(path) / 2);
  EXPECT_THROW(read_png(path), Error);
}

TEST(Png, WritingIntoAMissingDirectoryFailsCleanly) {
  testing::TempDir dir;
  const std::string path = dir.file("missing/x.png");
  try {
    write_png(path, ImageRGBA8(4, 4));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::io);
    EXPECT_EQ(e.file(), path);
  }
}

TEST(FloatImage, HoldsValuesRowMajor) {
  FloatImage depth(3, 2, 1.5f);
  depth(2, 1) = -4.0f;
  EXPECT_EQ(depth.row(1)[2], -4.0f);
  EXPECT_EQ(depth.data()[5], -4.0f);
  EXPECT_EQ(depth(0, 0), 1.5f);
  EXPECT_THROW(FloatImage(-1, 3), Error);
}

}  // namespace
}  // namespace brickyard
