#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include "core/error.h"
#include "core/image.h"
#include "renderers/common/metrics.h"
#include "test_util.h"

using namespace brickyard;

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

FrameBuffers make_frame(int w, int h, bool depth = true, bool normals = true) {
  return FrameBuffers(w, h, FrameOutputs{.depth = depth, .normals = normals});
}

/// A frame whose every pixel is a hit: colours on a 1/64 grid in [0, 0.75] (exact in float,
/// with room for offsets), depths on a 1/16 grid in [2, 6], unit normals.
FrameBuffers random_frame(int w, int h, uint32_t seed) {
  FrameBuffers f = make_frame(w, h);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> c(0, 48), d(32, 96);
  std::uniform_real_distribution<float> u(-1, 1);
  for (size_t i = 0; i < f.color.size(); ++i) {
    f.color.data()[i] = {c(rng) / 64.0f, c(rng) / 64.0f, c(rng) / 64.0f, 1.0f};
    f.depth.data()[i] = d(rng) / 16.0f;
    f.normal.data()[i] = normalize(Vec3f(u(rng), u(rng), 1.0f));
  }
  return f;
}

void set_grey(FrameBuffers& f, float v) {
  for (size_t i = 0; i < f.color.size(); ++i) f.color.data()[i] = {v, v, v, 1};
}

double ssim_of(const FrameBuffers& a, const FrameBuffers& b) { return compare_frames(a, b, 1.0).ssim; }

/// Wang et al.'s mean SSIM computed directly: a full 2D 11x11 window per pixel, in double,
/// cut at the image edge and renormalised like the separable version.
double brute_force_ssim(const Image<Rgbaf>& x, const Image<Rgbaf>& y) {
  std::array<double, 11> g{};
  for (int k = 0; k < 11; ++k) g[k] = std::exp(-double((k - 5) * (k - 5)) / (2 * 1.5 * 1.5));
  auto lum = [](const Rgbaf& c) { return 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b; };
  const double c1 = 1e-4, c2 = 9e-4;
  double sum = 0;
  for (int py = 0; py < x.height(); ++py)
    for (int px = 0; px < x.width(); ++px) {
      double ws = 0, mx = 0, my = 0, xx = 0, yy = 0, xy = 0;
      for (int dy = -5; dy <= 5; ++dy)
        for (int dx = -5; dx <= 5; ++dx) {
          const int sx = px + dx, sy = py + dy;
          if (sx < 0 || sy < 0 || sx >= x.width() || sy >= x.height()) continue;
          const double w = g[dx + 5] * g[dy + 5], a = lum(x(sx, sy)), b = lum(y(sx, sy));
          ws += w;
          mx += w * a;
          my += w * b;
          xx += w * a * a;
          yy += w * b * b;
          xy += w * a * b;
        }
      mx /= ws, my /= ws, xx /= ws, yy /= ws, xy /= ws;
      const double sxx = xx - mx * mx, syy = yy - my * my, sxy = xy - mx * my;
      sum += ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2));
    }
  return sum / double(x.size());
}

}  // namespace

// --- percentile -------------------------------------------------------------------------------

TEST(Percentile, NearestRankOfKnownValues) {
  std::vector<double> v(100);
  std::iota(v.begin(), v.end(), 1.0);
  std::shuffle(v.begin(), v.end(), std::mt19937(7));
  EXPECT_EQ(percentile(v, 99), 99.0);
  EXPECT_EQ(percentile(v, 100), 100.0);
  EXPECT_EQ(percentile(v, 50), 50.0);
  EXPECT_EQ(percentile(v, 0), 1.0);
  EXPECT_EQ(percentile(v, 0.5), 1.0);
  EXPECT_EQ(percentile(v, 1.5), 2.0);
  std::vector<double> few = {5, 1, 3};  // ranks ceil(p/100 * 3)
  EXPECT_EQ(percentile(few, 33), 1.0);
  EXPECT_EQ(percentile(few, 34), 3.0);
  EXPECT_EQ(percentile(few, 99), 5.0);
  std::vector<double> none;
  EXPECT_EQ(percentile(none, 99), 0.0);
}

TEST(Percentile, RejectsPercentOutsideZeroToHundred) {
  std::vector<double> v = {1, 2};
  EXPECT_THROW(percentile(v, 101), Error);
  EXPECT_THROW(percentile(v, -1), Error);
  EXPECT_THROW(percentile(v, std::nan("")), Error);
}

// --- compare_frames ---------------------------------------------------------------------------

TEST(CompareFrames, IdenticalFramesHaveNoError) {
  const FrameBuffers f = random_frame(37, 23, 1);
  const ImageError e = compare_frames(f, f, 0.5);
  EXPECT_EQ(e.rmse, 0.0);
  EXPECT_TRUE(std::isinf(e.psnr_db) && e.psnr_db > 0);
  EXPECT_EQ(e.ssim, 1.0);
  EXPECT_EQ(e.depth_mean, 0.0);
  EXPECT_EQ(e.depth_p99, 0.0);
  EXPECT_EQ(e.depth_max, 0.0);
  EXPECT_EQ(e.depth_pixels, f.color.size());
  EXPECT_EQ(e.normal_mean_deg, 0.0);
  EXPECT_EQ(e.normal_p99_deg, 0.0);
  EXPECT_EQ(e.normal_pixels, f.color.size());
  EXPECT_EQ(e.coverage_mismatch, 0u);
  EXPECT_EQ(e.coverage_mismatch_fraction, 0.0);
  EXPECT_EQ(e.nonfinite_color_pixels, 0u);
  const std::string json = e.to_json();
  EXPECT_NE(json.find("\"psnr_db\": null"), std::string::npos) << json;
  EXPECT_NE(json.find("\"ssim\": 1.0"), std::string::npos) << json;
}

TEST(CompareFrames, ConstantColourOffsetGivesExactRmseAndPsnr) {
  const FrameBuffers ref = random_frame(40, 30, 2);
  for (float d : {0.125f, 1.0f / 64, 0.25f}) {
    FrameBuffers test = ref;
    for (size_t i = 0; i < test.color.size(); ++i) {
      Rgbaf& c = test.color.data()[i];
      c = {c.r + d, c.g + d, c.b + d, c.a};
    }
    const ImageError e = compare_frames(test, ref, 1.0);
    EXPECT_EQ(e.rmse, double(d));
    EXPECT_DOUBLE_EQ(e.psnr_db, 20.0 * std::log10(1.0 / d));
    EXPECT_EQ(e.to_json().find("null"), std::string::npos);
  }
}

TEST(CompareFrames, ColourErrorIsRmsOverChannelsAndPixels) {
  FrameBuffers ref = make_frame(2, 1), test = make_frame(2, 1);
  test.color(0, 0) = {0.5f, 0, 0, 1};  // one channel of six off by 0.5
  EXPECT_DOUBLE_EQ(compare_frames(test, ref, 1).rmse, std::sqrt(0.25 / 6));
}

TEST(CompareFrames, SsimOfConstantImagesMatchesTheLuminanceTerm) {
  // No variance anywhere: SSIM = (2ab + C1) / (a^2 + b^2 + C1) at every pixel, at any size,
  // including images smaller than the 11x11 window.
  for (auto [w, h] : {std::pair{1, 1}, {3, 2}, {11, 11}, {40, 70}}) {
    FrameBuffers a = make_frame(w, h), b = make_frame(w, h);
    set_grey(a, 0.5f);
    set_grey(b, 0.25f);
    const double expect = (2 * 0.5 * 0.25 + 1e-4) / (0.25 + 0.0625 + 1e-4);
    EXPECT_NEAR(ssim_of(a, b), expect, 1e-6) << w << "x" << h;
  }
}

TEST(CompareFrames, SsimMatchesDirectTwoDimensionalWindow) {
  const FrameBuffers a = random_frame(29, 17, 3), b = random_frame(29, 17, 4);
  FrameBuffers c = a;  // a blurred-ish copy: correlated with a
  for (int y = 0; y < c.height(); ++y)
    for (int x = 1; x < c.width(); ++x) {
      const Rgbaf& p = a.color(x - 1, y);
      const Rgbaf& q = a.color(x, y);
      c.color(x, y) = {0.5f * (p.r + q.r), 0.5f * (p.g + q.g), 0.5f * (p.b + q.b), 1};
    }
  EXPECT_NEAR(ssim_of(a, b), brute_force_ssim(a.color, b.color), 1e-5);
  EXPECT_NEAR(ssim_of(a, c), brute_force_ssim(a.color, c.color), 1e-5);
  const FrameBuffers small_a = random_frame(4, 3, 5), small_b = random_frame(4, 3, 6);
  EXPECT_NEAR(ssim_of(small_a, small_b), brute_force_ssim(small_a.color, small_b.color), 1e-5);
}

TEST(CompareFrames, SsimIsOneForItselfSymmetricAndDropsWithNoiseAndBlur) {
  // A smooth image with edges: a disc on a gradient.
  const int w = 96, h = 80;
  FrameBuffers ref = make_frame(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool in = (x - 48) * (x - 48) + (y - 40) * (y - 40) < 25 * 25;
      const float v = in ? 0.8f : 0.1f + 0.3f * float(x) / float(w);
      ref.color(x, y) = {v, v, v, 1};
    }
  auto noisy = [&](float sigma) {
    FrameBuffers f = ref;
    std::mt19937 rng(11);
    std::normal_distribution<float> n(0, sigma);
    for (size_t i = 0; i < f.color.size(); ++i) {
      const float v = f.color.data()[i].r + n(rng);
      f.color.data()[i] = {v, v, v, 1};
    }
    return f;
  };
  auto blurred = [&](int r) {
    FrameBuffers f = ref;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        float s = 0;
        int c = 0;
        for (int dx = -r; dx <= r; ++dx)
          if (x + dx >= 0 && x + dx < w) s += ref.color(x + dx, y).r, ++c;
        f.color(x, y) = {s / c, s / c, s / c, 1};
      }
    return f;
  };
  EXPECT_EQ(ssim_of(ref, ref), 1.0);
  const FrameBuffers n1 = noisy(0.02f), n2 = noisy(0.1f), b1 = blurred(1), b2 = blurred(4);
  EXPECT_LT(ssim_of(n1, ref), 1.0);
  EXPECT_LT(ssim_of(n2, ref), ssim_of(n1, ref));
  EXPECT_LT(ssim_of(b1, ref), 1.0);
  EXPECT_LT(ssim_of(b2, ref), ssim_of(b1, ref));
  EXPECT_EQ(ssim_of(n2, ref), ssim_of(ref, n2));
  EXPECT_EQ(ssim_of(b2, ref), ssim_of(ref, b2));
}

TEST(CompareFrames, SsimDoesNotDependOnTheThreadCount) {
  const FrameBuffers a = random_frame(300, 257, 8), b = random_frame(300, 257, 9);
  const double many = ssim_of(a, b);
  double one = 0;
  tbb::task_arena arena(1);
  arena.execute([&] { one = ssim_of(a, b); });
  EXPECT_EQ(one, many);
}

TEST(CompareFrames, DepthOffsetIsMeasuredInVoxels) {
  FrameBuffers ref = random_frame(30, 20, 10);
  FrameBuffers test = ref;
  for (size_t i = 0; i < test.depth.size(); ++i) test.depth.data()[i] += 0.75f;  // exact on the 1/16 grid
  // Misses in both frames, and in one only, are left out of the depth figures.
  test.depth(0, 0) = kInf;
  ref.depth(0, 0) = kInf;
  test.depth(1, 0) = kInf;
  const ImageError e = compare_frames(test, ref, 0.125);
  EXPECT_EQ(e.depth_mean, 6.0);
  EXPECT_EQ(e.depth_max, 6.0);
  EXPECT_EQ(e.depth_p99, 6.0);
  EXPECT_EQ(e.depth_pixels, ref.depth.size() - 2);
  EXPECT_EQ(e.coverage_mismatch, 1u);  // (1, 0): only the reference hits
}

TEST(CompareFrames, DepthPercentileAndMaximumOfKnownErrors) {
  FrameBuffers ref = make_frame(10, 10, true, false), test = make_frame(10, 10, true, false);
  for (int i = 0; i < 100; ++i) {
    ref.depth.data()[i] = 10.0f;
    test.depth.data()[i] = 10.0f + 0.5f * float(i + 1);  // errors 1, 2, ..., 100 voxels
  }
  const ImageError e = compare_frames(test, ref, 0.5);
  EXPECT_EQ(e.depth_max, 100.0);
  EXPECT_EQ(e.depth_p99, 99.0);
  EXPECT_DOUBLE_EQ(e.depth_mean, 50.5);
  EXPECT_EQ(e.normal_pixels, 0u);  // no normal buffers: no normal figures
}

TEST(CompareFrames, NormalsRotatedByTenDegreesGiveTenDegrees) {
  FrameBuffers ref = make_frame(16, 16), test = make_frame(16, 16);
  const double rot = 10.0 * kPi / 180.0;
  for (int i = 0; i < 256; ++i) {
    const double phi = 2 * kPi * i / 256.0, theta = kPi * (i % 16) / 16.0 + 0.1;
    // Rotate n(theta, phi) by 10 degrees towards the pole along its meridian.
    auto n = [&](double t) {
      return Vec3f(float(std::sin(t) * std::cos(phi)), float(std::sin(t) * std::sin(phi)), float(std::cos(t)));
    };
    ref.normal.data()[i] = n(theta);
    test.normal.data()[i] = n(theta + rot);
  }
  test.normal(0, 0) = Vec3f(0.0f);  // no normal in one frame: not compared
  const ImageError e = compare_frames(test, ref, 1);
  EXPECT_EQ(e.normal_pixels, 255u);
  EXPECT_NEAR(e.normal_mean_deg, 10.0, 1e-4);
  EXPECT_NEAR(e.normal_p99_deg, 10.0, 1e-4);
}

TEST(CompareFrames, CountsCoverageMismatchByDepthOrElseByAlpha) {
  // Reference hits a 10x10 square at (5, 5); the test the same square moved 3 pixels right:
  // 3 columns of 10 hit only by the reference, 3 only by the test.
  const int w = 32, h = 24;
  FrameBuffers ref = make_frame(w, h, true, false), test = make_frame(w, h, true, false);
  for (int y = 5; y < 15; ++y)
    for (int x = 5; x < 15; ++x) {
      ref.depth(x, y) = 1.0f;
      test.depth(x + 3, y) = 1.0f;
      ref.color(x, y).a = 1.0f;
      test.color(x + 3, y).a = 1.0f;
    }
  const ImageError e = compare_frames(test, ref, 1);
  EXPECT_EQ(e.coverage_mismatch, 60u);
  EXPECT_DOUBLE_EQ(e.coverage_mismatch_fraction, 60.0 / (w * h));
  EXPECT_EQ(e.depth_pixels, 70u);

  // Without depth buffers, alpha > 1/2 decides; a half-covered pixel is not a hit.
  FrameBuffers ra = make_frame(w, h, false, false), ta = make_frame(w, h, false, false);
  ra.color = ref.color;
  ta.color = test.color;
  ta.color(0, 0).a = 0.5f;
  ta.color(1, 0).a = 0.75f;
  EXPECT_EQ(compare_frames(ta, ra, 1).coverage_mismatch, 61u);
  // Depth in one frame only: alpha decides for both, and there are no depth figures.
  EXPECT_EQ(compare_frames(test, ra, 1).coverage_mismatch, 60u);
  EXPECT_EQ(compare_frames(test, ra, 1).depth_pixels, 0u);
}

TEST(CompareFrames, RejectsDifferentSizesAndBadVoxelSize) {
  const FrameBuffers a = make_frame(8, 8), b = make_frame(8, 9), c = make_frame(9, 8);
  try {
    compare_frames(a, b, 1);
    FAIL() << "no exception";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("8x9"), std::string::npos) << e.what();
  }
  EXPECT_THROW(compare_frames(a, c, 1), Error);
  EXPECT_THROW(write_error_maps(a, c, 1, "/nonexistent/x"), Error);
  FrameBuffers bad_depth = make_frame(8, 8);
  bad_depth.depth = FloatImage(4, 4);
  EXPECT_THROW(compare_frames(bad_depth, a, 1), Error);
  for (double v : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    try {
      compare_frames(a, a, v);
      FAIL() << "voxel size " << v << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument);
      EXPECT_EQ(e.field(), "voxel_size");
    }
  }
}

TEST(CompareFrames, NonFiniteInputCountsAsMaximalErrorNeverNaN) {
  const FrameBuffers ref = random_frame(20, 20, 12);
  FrameBuffers test = ref;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Colour: 4 pixels with every channel NaN or infinite, each channel counts an error of 1.
  test.color(0, 0) = {nan, nan, nan, 1};
  test.color(5, 5) = {kInf, -kInf, nan, 1};
  test.color(6, 5) = {nan, nan, nan, nan};
  test.color(19, 19) = {nan, nan, nan, 1};
  ImageError e = compare_frames(test, ref, 1);
  EXPECT_EQ(e.nonfinite_color_pixels, 4u);
  EXPECT_DOUBLE_EQ(e.rmse, std::sqrt(4.0 / 400.0));
  EXPECT_TRUE(std::isfinite(e.psnr_db));
  EXPECT_TRUE(std::isfinite(e.ssim));
  EXPECT_LT(e.ssim, 1.0);
  EXPECT_GT(e.ssim, 0.0);
  // NaN in the reference is an error too, and symmetric.
  EXPECT_EQ(compare_frames(ref, test, 1).rmse, e.rmse);
  EXPECT_EQ(compare_frames(ref, test, 1).ssim, e.ssim);
  EXPECT_EQ(compare_frames(test, test, 1).nonfinite_color_pixels, 4u);
  EXPECT_TRUE(std::isfinite(compare_frames(test, test, 1).ssim));

  // A NaN normal is 180 degrees off; a NaN depth is a miss, hence a coverage mismatch.
  test = ref;
  test.normal(3, 3) = Vec3f(nan, 0, 1);
  test.depth(4, 4) = nan;
  e = compare_frames(test, ref, 1);
  EXPECT_DOUBLE_EQ(e.normal_mean_deg, 180.0 / 400.0);
  EXPECT_EQ(e.depth_pixels, 399u);
  EXPECT_EQ(e.coverage_mismatch, 1u);
  EXPECT_EQ(e.depth_mean, 0.0);
  const std::string json = e.to_json();
  EXPECT_EQ(json.find("nan"), std::string::npos) << json;
}

TEST(CompareFrames, EmptyFramesCompareAsIdentical) {
  const ImageError e = compare_frames(FrameBuffers{}, FrameBuffers{}, 1);
  EXPECT_EQ(e.rmse, 0.0);
  EXPECT_EQ(e.ssim, 1.0);
  EXPECT_EQ(e.coverage_mismatch_fraction, 0.0);
}

TEST(CompareFrames, HandlesAMegapixelFrame) {
  // Correctness at size (many SSIM chunks); the time is measured by no test, see the report.
  const FrameBuffers ref = random_frame(1024, 1024, 13);
  FrameBuffers test = ref;
  for (size_t i = 0; i < test.color.size(); i += 7) test.color.data()[i].g += 0.25f;
  const ImageError same = compare_frames(ref, ref, 1);
  EXPECT_EQ(same.ssim, 1.0);
  const ImageError e = compare_frames(test, ref, 1);
  EXPECT_LT(e.ssim, 1.0);
  EXPECT_NEAR(e.rmse, std::sqrt(0.0625 / 3 * std::ceil(1024.0 * 1024 / 7) / (1024.0 * 1024)), 1e-12);
}

// --- heat maps --------------------------------------------------------------------------------

TEST(ErrorColormap, RunsFromBlackToPaleYellowWithRisingLuminance) {
  EXPECT_EQ(error_colormap(0), (Rgba8{0, 0, 0, 255}));
  const Rgba8 top = error_colormap(1);
  EXPECT_GE(top.r, 245);
  EXPECT_GE(top.g, 250);
  EXPECT_LT(top.b, 190);
  EXPECT_EQ(error_colormap(-3), error_colormap(0));
  EXPECT_EQ(error_colormap(7), error_colormap(1));
  EXPECT_EQ(error_colormap(std::nan("")), error_colormap(0));
  auto lin = [](uint8_t u) {
    const double c = u / 255.0;
    return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
  };
  double prev = -1;
  for (int i = 0; i <= 255; ++i) {
    const Rgba8 c = error_colormap(i / 255.0);
    const double y = 0.2126 * lin(c.r) + 0.7152 * lin(c.g) + 0.0722 * lin(c.b);
    EXPECT_GE(y, prev) << i;
    prev = y;
  }
}

TEST(ErrorColormap, ColorizeSaturatesAtTheScaleAndGreysOutNaN) {
  FloatImage err(4, 1);
  err(0, 0) = 0;
  err(1, 0) = 2;
  err(2, 0) = 9;
  err(3, 0) = std::numeric_limits<float>::quiet_NaN();
  const ImageRGBA8 img = colorize_error(err, 4);
  EXPECT_EQ(img(0, 0), error_colormap(0));
  EXPECT_EQ(img(1, 0), error_colormap(0.5));
  EXPECT_EQ(img(2, 0), error_colormap(1));
  EXPECT_EQ(img(3, 0), kNoDataGrey);
  const ImageRGBA8 zero = colorize_error(err, 0);
  EXPECT_EQ(zero(0, 0), error_colormap(0));
  EXPECT_EQ(zero(1, 0), error_colormap(1));
}

TEST(ErrorMaps, WritesFourMapsWithScalesThatReadBack) {
  brickyard::testing::TempDir dir;
  const int w = 48, h = 32;
  FrameBuffers ref = random_frame(w, h, 14);
  FrameBuffers test = ref;
  for (size_t i = 0; i < test.depth.size(); ++i) test.depth.data()[i] += 0.5f;  // 2 voxels of 0.25
  test.color(3, 3).r += 0.25f;                                                   // one colour error
  test.depth(0, 0) = kInf;                                                       // reference only
  ref.depth(1, 0) = kInf;                                                        // test only
  ref.depth(2, 0) = kInf;
  test.depth(2, 0) = kInf;  // neither
  const ErrorMaps maps = write_error_maps(test, ref, 0.25, dir.file("frame"));
  ASSERT_EQ(maps.paths.size(), 4u);
  EXPECT_EQ(maps.paths[0], dir.file("frame-color.png"));
  EXPECT_EQ(maps.paths[1], dir.file("frame-depth.png"));
  EXPECT_EQ(maps.paths[2], dir.file("frame-normal.png"));
  EXPECT_EQ(maps.paths[3], dir.file("frame-coverage.png"));
  for (const auto& p : maps.paths) {
    ASSERT_TRUE(std::filesystem::exists(p)) << p;
    const ImageRGBA8 img = read_png(p);
    EXPECT_EQ(img.width(), w);
    EXPECT_EQ(img.height(), h);
  }
  // One colour error in 1536 pixels: p99 is 0, so the scale is the maximum, sqrt(0.25^2 / 3).
  EXPECT_NEAR(maps.color_scale, 0.25 / std::sqrt(3.0), 1e-7);
  EXPECT_EQ(read_png(maps.paths[0])(3, 3), error_colormap(1));
  EXPECT_EQ(read_png(maps.paths[0])(4, 3), error_colormap(0));
  EXPECT_EQ(maps.depth_scale_voxels, 2.0);
  EXPECT_EQ(maps.normal_scale_deg, 0.0);
  const ImageRGBA8 depth = read_png(maps.paths[1]);
  EXPECT_EQ(depth(0, 0), kNoDataGrey);
  EXPECT_EQ(depth(5, 5), error_colormap(1));
  const ImageRGBA8 cov = read_png(maps.paths[3]);
  EXPECT_EQ(cov(0, 0), kReferenceOnlyColor);
  EXPECT_EQ(cov(1, 0), kTestOnlyColor);
  EXPECT_EQ(cov(2, 0), kNoDataGrey);
  EXPECT_EQ(cov(5, 5), kBothHitGrey);
  EXPECT_EQ(maps.test_only, 1u);
  EXPECT_EQ(maps.reference_only, 1u);
}

TEST(ErrorMaps, SkipsMapsWhoseBuffersAreAbsent) {
  brickyard::testing::TempDir dir;
  const FrameBuffers a = make_frame(8, 6, false, false);
  FrameBuffers b = make_frame(8, 6, true, true);
  const ErrorMaps maps = write_error_maps(a, b, 1, dir.file("x"));
  ASSERT_EQ(maps.paths.size(), 2u);
  EXPECT_EQ(maps.paths[0], dir.file("x-color.png"));
  EXPECT_EQ(maps.paths[1], dir.file("x-coverage.png"));
  EXPECT_FALSE(std::filesystem::exists(dir.file("x-depth.png")));
  EXPECT_EQ(maps.depth_scale_voxels, 0.0);
  EXPECT_EQ(maps.color_scale, 0.0);  // identical colour: no error, bottom colour everywhere
  EXPECT_EQ(read_png(maps.paths[0])(0, 0), error_colormap(0));
}
