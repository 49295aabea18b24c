#include <gtest/gtest.h>

#include <cmath>

#include "renderers/common/frame.h"

using namespace brickyard;

TEST(FrameBuffers, AllocatesOnlyTheBuffersAskedFor) {
  FrameBuffers f(8, 4, FrameOutputs{.depth = true, .normals = false});
  EXPECT_EQ(f.width(), 8);
  EXPECT_EQ(f.depth.size(), 32u);
  EXPECT_TRUE(f.normal.empty());
  EXPECT_TRUE(std::isinf(f.depth(3, 2)));
}

TEST(FrameBuffers, ColourConversionClampsAndRoundsAndMapsNaNToBlack) {
  Image<Rgbaf> c(3, 1);
  c(0, 0) = {0.5f, 2.0f, -1.0f, 1};
  c(1, 0) = {NAN, 1.0f / 255.0f, 0.999f, 1};
  const ImageRGBA8 out = to_rgba8(c);
  EXPECT_EQ(out(0, 0), (Rgba8{128, 255, 0, 255}));
  EXPECT_EQ(out(1, 0), (Rgba8{0, 1, 255, 255}));
}

TEST(FrameStats, PhasesAccumulateByName) {
  FrameStats s;
  s.add_phase("render", 0.5);
  s.add_phase("prepare", 0.25);
  s.add_phase("render", 0.5);
  EXPECT_DOUBLE_EQ(s.phase("render"), 1.0);
  EXPECT_DOUBLE_EQ(s.phase("missing"), 0.0);
  EXPECT_NE(s.to_json().find("\"prepare\""), std::string::npos);
}

TEST(FrameStats, AFrameBelowTheQualityAskedSaysWhyInItsJson) {
  FrameStats s;
  EXPECT_NE(s.to_json().find("\"below_quality\": null"), std::string::npos) << s.to_json();
  s.add_below_quality("a pool too small");
  s.add_below_quality("out of passes");
  EXPECT_EQ(s.below_quality, "a pool too small; out of passes");
  EXPECT_NE(s.to_json().find("\"below_quality\": \"a pool too small; out of passes\""), std::string::npos) << s.to_json();
}

TEST(FrameBuffers, ResolvingSupersamplesAveragesColourAndKeepsTheCentreRaysDepthAndNormal) {
  // 2x1 pixels at factor 3: every sub-pixel's colour encodes its position, so the mean is
  // known; the middle sub-pixel (1, 1) of each block alone carries a finite depth and a normal.
  FrameBuffers fine(6, 3, FrameOutputs{.depth = true, .normals = true});
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 6; ++x) {
      fine.color(x, y) = {float(x), float(y), x < 3 ? 1.0f : 0.0f, (x + y) % 2 ? 1.0f : 0.0f};
      fine.normal(x, y) = {0, 0, 0};
    }
  fine.depth(1, 1) = 2.5f, fine.normal(1, 1) = {0, 1, 0};
  fine.depth(4, 1) = 7.0f, fine.normal(4, 1) = {1, 0, 0};
  fine.depth(3, 0) = 9.0f;  // not a centre: never seen
  const FrameBuffers coarse = resolve_supersampled(fine, 3);
  ASSERT_EQ(coarse.width(), 2);
  ASSERT_EQ(coarse.height(), 1);
  EXPECT_FLOAT_EQ(coarse.color(0, 0).r, 1.0f);  // mean of x = 0, 1, 2
  EXPECT_FLOAT_EQ(coarse.color(1, 0).r, 4.0f);
  EXPECT_FLOAT_EQ(coarse.color(0, 0).g, 1.0f);
  EXPECT_FLOAT_EQ(coarse.color(0, 0).b, 1.0f);
  EXPECT_FLOAT_EQ(coarse.color(1, 0).b, 0.0f);
  EXPECT_FLOAT_EQ(coarse.color(0, 0).a, 4.0f / 9.0f);  // a checkerboard's odd cells in a 3x3 block
  EXPECT_FLOAT_EQ(coarse.color(1, 0).a, 5.0f / 9.0f);
  EXPECT_FLOAT_EQ(coarse.depth(0, 0), 2.5f);
  EXPECT_FLOAT_EQ(coarse.depth(1, 0), 7.0f);
  EXPECT_EQ(coarse.normal(0, 0), (Vec3f{0, 1, 0}));
  EXPECT_EQ(coarse.normal(1, 0), (Vec3f{1, 0, 0}));
  // Factor 1 is the identity; buffers the fine frame lacks stay absent.
  FrameBuffers colour_only(4, 2, FrameOutputs{.depth = false, .normals = false});
  colour_only.color(3, 1) = {0.25f, 0.5f, 0.75f, 1};
  const FrameBuffers same = resolve_supersampled(colour_only, 1);
  EXPECT_EQ(same.color, colour_only.color);
  EXPECT_TRUE(same.depth.empty());
  EXPECT_TRUE(same.normal.empty());
}
