#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "fields/field.h"

namespace brickyard {
namespace {

constexpr double kPiD = 3.14159265358979323846;

std::vector<Vec3d> random_points(const Box3d& box, int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Vec3d> pts;
  for (int i = 0; i < n; ++i) pts.push_back(box.lo + box.extent() * Vec3d(u(rng), u(rng), u(rng)));
  return pts;
}

Vec3d central_difference(const Field& f, const Vec3d& p, double h) {
  Vec3d g;
  for (int a = 0; a < 3; ++a) {
    Vec3d d{};
    d[a] = h;
    g[a] = (f.value(p + d) - f.value(p - d)) / (2 * h);
  }
  return g;
}

TEST(FieldRegistry, ListsEveryFieldAndRejectsUnknownNames) {
  const std::vector<std::string> expected = {"marschner-lobb", "sphere", "torus", "gyroid",
                                             "fbm", "menger", "sparse-blobs", "linear", "wavelet", "shepp-logan"};
  EXPECT_EQ(field_names(), expected);
  for (const auto& info : field_catalog()) {
    EXPECT_FALSE(info.description.empty());
    for (const auto& p : info.params) EXPECT_FALSE(p.doc.empty()) << info.name << "." << p.name;
  }
  try {
    make_field("perlin");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("known fields: marschner-lobb, sphere"), std::string::npos) << e.what();
  }
}

TEST(FieldRegistry, UnknownAndInvalidParametersAreNamed) {
  try {
    make_field("fbm", {{"octave", 3}});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "octave");
    EXPECT_NE(std::string(e.what()).find("octaves"), std::string::npos) << e.what();
  }
  EXPECT_THROW(make_field("fbm", {{"octaves", 2.5}}), Error);
  EXPECT_THROW(make_field("fbm", {{"octaves", 0}}), Error);
  EXPECT_THROW(make_field("sphere", {{"radius", -1}}), Error);
  EXPECT_THROW(make_field("torus", {{"minor", 0.5}}), Error);
  EXPECT_THROW(make_field("sphere", {{"radius", NAN}}), Error);
  auto f = make_field("fbm", {{"octaves", 3}});
  bool found = false;
  for (const auto& p : f->params()) found = found || (p.name == "octaves" && p.value == 3);
  EXPECT_TRUE(found);
}

// Marschner & Lobb's definition, written out independently of the implementation.
double marschner_lobb_reference(double x, double y, double z) {
  const double alpha = 0.25, fm = 6.0;
  const double r = std::sqrt(x * x + y * y);
  const double rho_r = std::cos(2 * kPiD * fm * std::cos(kPiD * r / 2));
  return (1 - std::sin(kPiD * z / 2) + alpha * (1 + rho_r)) / (2 * (1 + alpha));
}

TEST(MarschnerLobb, MatchesTheDefinition) {
  auto f = make_field("marschner-lobb");
  EXPECT_EQ(f->domain(), Box3d(Vec3d(-1.0), Vec3d(1.0)));
  EXPECT_NEAR(f->value({0, 0, 0}), 0.6, 1e-15);
  EXPECT_NEAR(f->value({0, 0, 1}), 0.2, 1e-15);   // sin(pi/2) = 1
  EXPECT_NEAR(f->value({0, 0, -1}), 1.0, 1e-15);  // the maximum
  for (const Vec3d& p : random_points(f->domain(), 2000, 1))
    EXPECT_NEAR(f->value(p), marschner_lobb_reference(p.x, p.y, p.z), 1e-14);
}

TEST(SignedDistance, SphereZeroOnTheSurfaceWithRadialUnitNormals) {
  auto f = make_field("sphere");
  EXPECT_NEAR(f->value({0.5, 0.5, 0.5}), -0.35, 1e-15);
  for (const Vec3d& p : random_points({Vec3d(-1.0), Vec3d(1.0)}, 500, 2)) {
    const Vec3d dir = normalize(p);
    const Vec3d s = Vec3d(0.5) + dir * 0.35;
    EXPECT_NEAR(f->value(s), 0.0, 1e-15);
    const Vec3d n = f->gradient(s);
    EXPECT_NEAR(length(n - dir), 0.0, 1e-12);
    EXPECT_NEAR(f->value(s + dir * 0.1), 0.1, 1e-12);
  }
  EXPECT_NEAR(f->range().lo, -0.35, 1e-15);
  EXPECT_NEAR(f->range().hi, std::sqrt(0.75) - 0.35, 1e-15);
}

TEST(SignedDistance, TorusZeroOnTheTube) {
  auto f = make_field("torus");
  EXPECT_NEAR(f->value({0.8, 0.5, 0.5}), -0.1, 1e-15);  // on the centre line of the tube
  for (double phi = 0; phi < 2 * kPiD; phi += 0.1)
    for (double theta = 0; theta < 2 * kPiD; theta += 0.1) {
      const Vec3d ring{0.5 + 0.3 * std::cos(phi), 0.5 + 0.3 * std::sin(phi), 0.5};
      const Vec3d n{std::cos(theta) * std::cos(phi), std::cos(theta) * std::sin(phi), std::sin(theta)};
      const Vec3d s = ring + n * 0.1;
      EXPECT_NEAR(f->value(s), 0.0, 1e-14);
      EXPECT_NEAR(length(f->gradient(s) - n), 0.0, 1e-12);
    }
}

TEST(Gyroid, KnownValues) {
  auto f = make_field("gyroid");
  EXPECT_NEAR(f->value({0, 0, 0}), 0.0, 1e-15);
  // At x = 1/8 (w x = pi/2 for 2 periods), y = z = 0: sin(pi/2) cos 0 + 0 + 0 * cos = 1.
  EXPECT_NEAR(f->value({0.125, 0, 0}), 1.0, 1e-15);
}

TEST(Menger, SolidFractionIsExactlyTwentyOverTwentySevenPerLevel) {
  for (int levels = 0; levels <= 3; ++levels) {
    auto f = make_field("menger", {{"levels", double(levels)}});
    const int n = static_cast<int>(std::pow(3, levels)) * 2;  // two samples per finest cell
    int64_t solid = 0;
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) solid += f->value({(x + 0.5) / n, (y + 0.5) / n, (z + 0.5) / n}) > 0.5;
    EXPECT_EQ(solid, static_cast<int64_t>(std::pow(20, levels) * 8)) << "levels " << levels;
  }
  auto f = make_field("menger");
  EXPECT_EQ(f->value({0.5, 0.5, 0.5}), 0.0);
  EXPECT_EQ(f->value({0.0, 0.0, 0.0}), 1.0);
  EXPECT_EQ(f->value({1.0, 1.0, 1.0}), 1.0);
  EXPECT_EQ(f->value({1.5, 0.0, 0.0}), 0.0);  // outside the domain
}

TEST(SheppLogan, HounsfieldUnitsOfEachTissue) {
  auto f = make_field("shepp-logan");
  EXPECT_TRUE(f->integer_valued());
  EXPECT_EQ(f->value({0.0, 0.0, 0.0}), 20.0);     // brain: 2.00 - 0.98 = 1.02
  EXPECT_EQ(f->value({0.22, 0.0, 0.0}), 0.0);     // right ventricle: 1.02 - 0.02 = 1.00, water
  EXPECT_EQ(f->value({-0.22, 0.0, 0.0}), 0.0);    // left ventricle
  EXPECT_EQ(f->value({0.0, 0.35, 0.0}), 30.0);    // the large tumour: 1.03
  EXPECT_EQ(f->value({0.0, -0.1, 0.0}), 30.0);    // a small one
  EXPECT_EQ(f->value({0.0, 0.0, 0.795}), 1000.0); // skull above the brain (z between 0.78 and 0.81)
  EXPECT_EQ(f->value({0.68, 0.0, 0.0}), 1000.0);  // skull at the side (x between 0.6624 and 0.69)
  EXPECT_EQ(f->value({0.95, 0.0, 0.0}), -1000.0); // air
  EXPECT_EQ(f->value({-1.0, -1.0, -1.0}), -1000.0);
  // The ventricles are tilted by -18 and +18 degrees: mirror images of each other in x.
  EXPECT_EQ(f->value({0.22 + 0.3 * std::sin(18 * kPi / 180), 0.3 * std::cos(18 * kPi / 180), 0.0}), 0.0);
  EXPECT_EQ(f->value({-0.22 - 0.3 * std::sin(18 * kPi / 180), 0.3 * std::cos(18 * kPi / 180), 0.0}), 0.0);
  // Along the other tilt, out of the ventricle into the brain.
  EXPECT_EQ(f->value({0.22 + 0.3 * std::sin(18 * kPi / 180), -0.3 * std::cos(18 * kPi / 180), 0.0}), 20.0);
  EXPECT_EQ(f->value({0.22 - 0.3 * std::sin(18 * kPi / 180), -0.3 * std::cos(18 * kPi / 180), 0.0}), 0.0);
}

TEST(SheppLogan, SkullVolumeIsTheDifferenceOfTwoEllipsoids) {
  // Midpoint rule on a 160^3 lattice over [-1, 1]^3 against 4/3 pi (a1 b1 c1 - a2 b2 c2): the
  // brain's ellipsoid lies inside the skull's, so every point at 1000 HU is between them.
  auto f = make_field("shepp-logan");
  const int n = 160;
  std::vector<double> row(n);
  int64_t skull = 0;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y) {
      f->sample_row({-1 + 1.0 / n, -1 + (2 * y + 1.0) / n, -1 + (2 * z + 1.0) / n}, 2.0 / n, n, row.data());
      for (double v : row) skull += v == 1000.0;
    }
  const double measured = double(skull) * 8.0 / (double(n) * n * n);
  const double expected = 4.0 / 3.0 * kPi * (0.69 * 0.92 * 0.81 - 0.6624 * 0.874 * 0.78);
  EXPECT_NEAR(measured, expected, 0.02 * expected);
}

TEST(SparseBlobs, MostOfTheDomainIsExactlyZero) {
  auto f = make_field("sparse-blobs");
  int64_t zeros = 0, total = 0;
  double hi = 0;
  const int n = 48;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double v = f->value({x / (n - 1.0), y / (n - 1.0), z / (n - 1.0)});
        ASSERT_TRUE(f->range().contains(v));
        zeros += v == 0.0;
        hi = std::max(hi, v);
        ++total;
      }
  EXPECT_GT(double(zeros) / double(total), 0.9);
  EXPECT_LT(double(zeros) / double(total), 0.999);
  EXPECT_GT(hi, 0.5);
}

TEST(Fbm, DeterministicPerSeedAndSpreadOverItsRange) {
  auto a = make_field("fbm"), b = make_field("fbm"), c = make_field("fbm", {{"seed", 2}});
  double sum = 0, sum2 = 0;
  int differ = 0;
  const auto pts = random_points(a->domain(), 4000, 5);
  for (const Vec3d& p : pts) {
    const double v = a->value(p);
    EXPECT_EQ(v, b->value(p));
    differ += v != c->value(p);
    ASSERT_TRUE(a->range().contains(v));
    sum += v;
    sum2 += v * v;
  }
  const double mean = sum / double(pts.size()), stddev = std::sqrt(sum2 / double(pts.size()) - mean * mean);
  EXPECT_GT(differ, 3900);
  EXPECT_LT(std::abs(mean), 0.1);
  EXPECT_GT(stddev, 0.1);
}

// Every field: row sampling equals point evaluation, values stay in range(), and analytic
// gradients agree with central differences away from discontinuities (wavelet's, whose values
// carry VTK's float rounding, are checked in test_wavelet.cpp).
class EveryField : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryField, RowSamplingEqualsPointEvaluation) {
  auto f = make_field(GetParam());
  const Box3d d = f->domain();
  const int n = 37;
  std::vector<double> row(n);
  for (const Vec3d& p : random_points(d, 50, 9)) {
    const double dx = d.extent().x / (n - 1);
    const Vec3d p0{d.lo.x, p.y, p.z};
    f->sample_row(p0, dx, n, row.data());
    for (int i = 0; i < n; ++i) {
      const double v = f->value({p0.x + i * dx, p0.y, p0.z});
      EXPECT_EQ(row[size_t(i)], v);
      EXPECT_TRUE(f->range().contains(v)) << v;
    }
  }
}

class SmoothField : public ::testing::TestWithParam<std::string> {};

TEST_P(SmoothField, AnalyticGradientMatchesCentralDifferences) {
  auto f = make_field(GetParam());
  ASSERT_TRUE(f->has_analytic_gradient());
  int checked = 0;
  for (const Vec3d& p : random_points(f->domain(), 3000, 13)) {
    if (GetParam() == "sparse-blobs" && f->value(p) == 0.0) continue;
    const Vec3d g = f->gradient(p), fd = central_difference(*f, p, 1e-6);
    EXPECT_LT(length(g - fd), 1e-5 * std::max(1.0, length(fd))) << "at " << p;
    ++checked;
  }
  EXPECT_GT(checked, 20);
}

INSTANTIATE_TEST_SUITE_P(Fields, EveryField,
                         ::testing::Values("marschner-lobb", "sphere", "torus", "gyroid", "fbm", "menger",
                                           "sparse-blobs", "wavelet"),
                         [](const auto& param_info) {
                           std::string s = param_info.param;
                           for (char& ch : s)
                             if (ch == '-') ch = '_';
                           return s;
                         });

INSTANTIATE_TEST_SUITE_P(Fields, SmoothField,
                         ::testing::Values("marschner-lobb", "sphere", "torus", "gyroid", "sparse-blobs"),
                         [](const auto& param_info) {
                           std::string s = param_info.param;
                           for (char& ch : s)
                             if (ch == '-') ch = '_';
                           return s;
                         });

TEST(Fbm, NumericalGradientIsFiniteAndConsistent) {
  auto f = make_field("fbm");
  EXPECT_FALSE(f->has_analytic_gradient());
  for (const Vec3d& p : random_points(f->domain(), 200, 17)) {
    const Vec3d g = f->gradient(p), fd = central_difference(*f, p, 1e-5);
    EXPECT_LT(length(g - fd), 1e-3 * std::max(1.0, length(fd)));
  }
}

}  // namespace
}  // namespace brickyard
