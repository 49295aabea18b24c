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
