// The wavelet field against VTK: its formula written out again here, and VTK's own output
// (tests/data/wavelet/, made by make_wavelet_reference.py with Debian's python3-vtk9), so
// this test needs no VTK.

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "core/error.h"
#include "fields/field.h"
#include "fields/grid.h"
#include "test_util.h"

namespace brickyard {
namespace {

struct VtkParams {
  double maximum = 255, sigma = 0.5, xfreq = 60, yfreq = 30, zfreq = 40, xmag = 10, ymag = 18, zmag = 5;
  FieldParamValues as_field_params() const {
    return {{"maximum", maximum}, {"standard_deviation", sigma}, {"xfreq", xfreq}, {"yfreq", yfreq},
            {"zfreq", zfreq},     {"xmag", xmag},                {"ymag", ymag},   {"zmag", zmag}};
  }
};

// vtkRTAnalyticSource's pixel operation, from Imaging/Core/vtkRTAnalyticSource.cxx, on VTK's
// normalised coordinates (x, y, z) = -p. round_terms keeps VTK's float xfactor, yfactor,
// zfactor; without it this is the exact formula.
double vtk_rt(const VtkParams& v, const Vec3d& p, bool round_terms) {
  const double x = -p.x, y = -p.y, z = -p.z;
  const double temp2 = 1.0 / (2.0 * v.sigma * v.sigma);
  double xf = v.xmag * std::sin(v.xfreq * x), yf = v.ymag * std::sin(v.yfreq * y), zf = v.zmag * std::cos(v.zfreq * z);
  if (round_terms) xf = float(xf), yf = float(yf), zf = float(zf);
  return v.maximum * std::exp(-((z * z + y * y) + x * x) * temp2) + xf + yf + zf;
}

std::vector<Vec3d> random_points(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  std::vector<Vec3d> pts;
  for (int i = 0; i < n; ++i) pts.push_back({u(rng), u(rng), u(rng)});
  return pts;
}

TEST(Wavelet, KnownValuesOfTheVtkFormula) {
  auto f = make_field("wavelet");
  EXPECT_EQ(f->domain(), Box3d(Vec3d(-0.5), Vec3d(0.5)));
  // At the centre the Gaussian is Maximum, the sines 0 and the cosine ZMag: 255 + 5.
  EXPECT_EQ(f->value({0, 0, 0}), 260.0);
  // On the +x face, x = -1/2: 255 e^{-1/2} + 10 sin(-30) + 5.
  EXPECT_NEAR(f->value({0.5, 0, 0}), 255 * std::exp(-0.5) - 10 * std::sin(30.0) + 5, 1e-5);
  // The sign: VTK's x falls as the index rises, so the sine is odd in p with the opposite sign.
  EXPECT_NEAR(f->value({0.01, 0, 0}) - f->value({-0.01, 0, 0}), -2 * 10 * std::sin(60 * 0.01), 1e-5);
  for (const Vec3d& p : random_points(2000, 1)) {
    EXPECT_NEAR(f->value(p), vtk_rt({}, p, true), 1e-12) << p;
    EXPECT_NEAR(f->value(p), vtk_rt({}, p, false), 2e-6) << p;  // the float terms' rounding only
  }
  const VtkParams other{100, 0.3, 25, 45, 11, 4, 7.5, 12};
  auto g = make_field("wavelet", other.as_field_params());
  for (const Vec3d& p : random_points(500, 2)) EXPECT_NEAR(g->value(p), vtk_rt(other, p, true), 1e-12) << p;
}

TEST(Wavelet, ParametersAreVtksDefaultsAndSigmaMustBePositive) {
  auto f = make_field("wavelet");
  const VtkParams defaults;
  for (const auto& [name, value] : defaults.as_field_params()) {
    bool found = false;
    for (const auto& p : f->params()) found = found || (p.name == name && p.value == value);
    EXPECT_TRUE(found) << name;
  }
  for (double sigma : {0.0, -0.5}) {
    try {
      make_field("wavelet", {{"standard_deviation", sigma}});
      FAIL() << sigma;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument);
      EXPECT_EQ(e.field(), "standard_deviation");
    }
  }
}

TEST(Wavelet, AnalyticGradientMatchesCentralDifferences) {
  // Differences of the exact formula: value() itself has steps of half a float ulp of each
  // magnitude (VTK's float terms), which a step of 1e-6 would amplify to about 1.
  for (const VtkParams& v : {VtkParams{}, VtkParams{100, 0.3, 25, 45, 11, 4, 7.5, 12}, VtkParams{-50, 2, 1, 2, 3, 1, -2, 3}}) {
    auto f = make_field("wavelet", v.as_field_params());
    ASSERT_TRUE(f->has_analytic_gradient());
    for (const Vec3d& p : random_points(3000, 13)) {
      Vec3d fd;
      const double h = 1e-6;
      for (int a = 0; a < 3; ++a) {
        Vec3d d{};
        d[a] = h;
        fd[a] = (vtk_rt(v, p + d, false) - vtk_rt(v, p - d, false)) / (2 * h);
      }
      EXPECT_LT(length(f->gradient(p) - fd), 1e-5 * std::max(1.0, length(fd))) << "at " << p;
    }
  }
}

TEST(Wavelet, RangeBoundsEveryValueAndEachTermTightly) {
  auto f = make_field("wavelet");
  // Gaussian from 255 e^{-3/2} (the corners) to 255, plus the sines' full +-33.
  EXPECT_NEAR(f->range().lo, 255 * std::exp(-1.5) - 33, 1e-9);
  EXPECT_EQ(f->range().hi, 288.0);
  // Low frequencies do not reach a crest inside the domain, a negative Maximum turns the
  // Gaussian over, magnitudes that floats cannot hold exactly: the bounds still hold and sit
  // on the sampled extremes of a field with one term.
  const VtkParams cases[] = {{}, {-50, 2, 1, 2, 3, 1, -2, 3}, {0, 0.5, 2.5, 0.1, 5, 0.1, 0.3, -0.7}};
  for (const VtkParams& v : cases) {
    auto g = make_field("wavelet", v.as_field_params());
    const ValueRange r = g->range();
    GridSampler s(*g, Vec3s(33), ValueType::f32);
    double lo = HUGE_VAL, hi = -HUGE_VAL;
    for (int64_t k = 0; k < 33; ++k)
      for (int64_t j = 0; j < 33; ++j)
        for (int64_t i = 0; i < 33; ++i) {
          const double value = g->value(s.position(i, j, k));
          ASSERT_TRUE(r.contains(value)) << value << " at " << s.position(i, j, k);
          lo = std::min(lo, value);
          hi = std::max(hi, value);
        }
    if (v.maximum == 0) {  // sines only, whose extremes lie on the faces and centre planes
      EXPECT_NEAR(hi - lo, r.hi - r.lo, 1e-6);
    }
  }
}

// VTK's RTData for one WholeExtent and Center, as written by make_wavelet_reference.py.
struct VtkCase {
  const char* file;
  Vec3s dims;
  VtkParams params;
};

std::vector<float> read_reference(const std::string& file, const Vec3s& dims) {
  const std::string bytes = testing::read_file(std::string(BRICKYARD_SOURCE_DIR) + "/tests/data/wavelet/" + file);
  std::vector<float> values(size_t(volume(dims)));
  EXPECT_EQ(bytes.size(), values.size() * sizeof(float)) << file;
  std::memcpy(values.data(), bytes.data(), std::min(bytes.size(), values.size() * sizeof(float)));
  static_assert(std::endian::native == std::endian::little, "the reference is little-endian");
  return values;
}

TEST(Wavelet, FloatGridsEqualVtkOutputBitForBit) {
  const VtkCase cases[] = {
      {"default_21x21x21.f32", {21, 21, 21}, {}},  // vtkRTAnalyticSource untouched
      {"odd_11x7x5.f32", {11, 7, 5}, {}},
      {"even_8x6x4.f32", {8, 6, 4}, {}},
      {"mixed_9x1x6.f32", {9, 1, 6}, {}},  // an axis of one sample
      {"params_7x9x8.f32", {7, 9, 8}, {100, 0.3, 25, 45, 11, 4, 7.5, 12}},
  };
  for (const VtkCase& c : cases) {
    const std::vector<float> vtk = read_reference(c.file, c.dims);
    auto f = make_field("wavelet", c.params.as_field_params());
    GridSampler s(*f, c.dims, ValueType::f32);
    std::vector<float> ours(vtk.size());
    s.sample_slab(0, c.dims.z, std::as_writable_bytes(std::span(ours)));
    // Float rounding at the scale of the terms: one ulp of the largest value they can sum to.
    const VtkParams& v = c.params;
    const float scale = float(std::abs(v.maximum) + std::abs(v.xmag) + std::abs(v.ymag) + std::abs(v.zmag));
    const double ulp = double(std::nextafter(scale, HUGE_VALF) - scale);
    double max_diff = 0;
    int64_t differing = 0;
    for (size_t n = 0; n < vtk.size(); ++n) {
      const double d = std::abs(double(ours[n]) - double(vtk[n]));
      ASSERT_LE(d, ulp) << c.file << " sample " << n << ": brickyard " << ours[n] << ", VTK " << vtk[n];
      max_diff = std::max(max_diff, d);
      differing += ours[n] != vtk[n];
    }
    // The bound above is what a user can rely on; bit equality is what reproducing VTK's order
    // of operations and its float terms buys with this libm (the one the reference was made with).
    EXPECT_EQ(differing, 0) << c.file << ": " << differing << " of " << vtk.size()
                            << " samples differ from VTK, by at most " << max_diff;
  }
}

}  // namespace
}  // namespace brickyard
