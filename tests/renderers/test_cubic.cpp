// cubic.h: the trilinear cubic along a ray and its first root, against independent
// evaluations (nested linear interpolation of the corners, a dense scan for sign changes) and
// closed forms.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <optional>
#include <random>

#include "renderers/common/cubic.h"

namespace brickyard {
namespace {

/// (s - a)(s - b)(s - c) * k, expanded.
Cubic from_roots(double a, double b, double c, double k = 1) {
  return {-k * a * b * c, k * (a * b + b * c + a * c), -k * (a + b + c), k};
}

/// Trilinear interpolation of corners c (index dx + 2 dy + 4 dz) at local u, by nested linear
/// interpolation: independent of trilinear_cubic's expansion into powers of the ray parameter.
double direct_trilinear(const double c[8], double ux, double uy, double uz) {
  auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
  const double y0 = lerp(lerp(c[0], c[1], ux), lerp(c[2], c[3], ux), uy);
  const double y1 = lerp(lerp(c[4], c[5], ux), lerp(c[6], c[7], ux), uy);
  return lerp(y0, y1, uz);
}

/// The exact gradient of direct_trilinear at u: each component is the difference of the two
/// faces across its axis, bilinearly interpolated over the other two.
void direct_gradient(const double c[8], double ux, double uy, double uz, double grad[3]) {
  auto bilerp = [](double a, double b, double c2, double d, double s, double t) {
    return (a + (b - a) * s) + ((c2 + (d - c2) * s) - (a + (b - a) * s)) * t;
  };
  grad[0] = bilerp(c[1] - c[0], c[3] - c[2], c[5] - c[4], c[7] - c[6], uy, uz);
  grad[1] = bilerp(c[2] - c[0], c[3] - c[1], c[6] - c[4], c[7] - c[5], ux, uz);
  grad[2] = bilerp(c[4] - c[0], c[5] - c[1], c[6] - c[2], c[7] - c[3], ux, uy);
}

TEST(Cubic, FirstRootOfSimpleRoots) {
  // Three simple roots: the first in [0, length] is returned, to full precision.
  const Cubic g = from_roots(0.2, 0.5, 0.9);
  auto r = first_root(g, 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.2, 1e-15);
  // The interval starts past the first root: shift by evaluating on [0.3, 1] via a substitution.
  const Cubic shifted = from_roots(0.2 - 0.3, 0.5 - 0.3, 0.9 - 0.3);
  r = first_root(shifted, 0.7);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.2, 1e-15);
  // Negative leading coefficient, a single real root.
  const Cubic one{0.3, 1.0, 0.0, -2.0};  // -2 s^3 + s + 0.3: one real root near 0.8
  r = first_root(one, 2.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(one(*r), 0.0, 1e-15);
  EXPECT_GT(*r, 0.5);
  // Linear and quadratic polynomials are cubics too.
  r = first_root(Cubic{-0.25, 1.0, 0.0, 0.0}, 1.0);
  ASSERT_TRUE(r);
  EXPECT_DOUBLE_EQ(*r, 0.25);
  r = first_root(Cubic{0.06, -0.5, 1.0, 0.0}, 1.0);  // (s - 0.2)(s - 0.3)
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.2, 1e-15);
}

TEST(Cubic, FirstRootFindsTangentAndTripleRoots) {
  // (s - 0.3)^2: touches zero without changing sign. 0.09 is not a double, so the rounded
  // polynomial has a double root moved by up to sqrt(eps) (two close roots, or a minimum a
  // rounding error above zero): found either way, within that conditioning.
  auto r = first_root(Cubic{0.09, -0.6, 1.0, 0.0}, 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.3, 1e-7);
  // (s - 0.375)^2, exact in binary: found to full precision.
  r = first_root(Cubic{0.140625, -0.75, 1.0, 0.0}, 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.375, 1e-12);
  // -(s - 0.3)^2 (s + 1): a tangent root of a true cubic, the extremum from below.
  r = first_root(from_roots(0.3, 0.3, -1.0, -1.0), 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.3, 1e-7);
  r = first_root(from_roots(0.375, 0.375, -1.0, -1.0), 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.375, 1e-12);
  // A tangent root after a simple root that lies before the interval.
  r = first_root(from_roots(0.4375, 0.4375, -0.0625), 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.4375, 1e-12);
  // Triple roots: dyadic (exact critical point) and not.
  r = first_root(from_roots(0.5, 0.5, 0.5), 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.5, 1e-12);
  r = first_root(from_roots(0.3, 0.3, 0.3), 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.3, 1e-5);  // a triple root is ill-conditioned: cbrt(eps) ~ 1e-5
  EXPECT_LE(std::fabs(from_roots(0.3, 0.3, 0.3)(*r)), 1e-15);
  // Slightly above a tangent (no root in exact arithmetic, beyond the tolerance): none.
  EXPECT_FALSE(first_root(Cubic{0.09 + 1e-9, -0.6, 1.0, 0.0}, 1.0));
}

TEST(Cubic, FirstRootAtTheIntervalEnds) {
  EXPECT_EQ(first_root(Cubic{0.0, 1.0, -3.0, 1.0}, 1.0), 0.0);  // g(0) = 0
  auto r = first_root(Cubic{-0.5, 0.5, 0.0, 0.0}, 1.0);        // g(1) = 0 exactly
  ASSERT_TRUE(r);
  EXPECT_EQ(*r, 1.0);
  r = first_root(from_roots(0.75, 2.0, 3.0), 0.75);  // root exactly at length, cubic
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.75, 1e-15);
  // Just outside either end: no root.
  EXPECT_FALSE(first_root(from_roots(-1e-9, 2.0, 3.0), 1.0));
  EXPECT_FALSE(first_root(from_roots(1.0 + 1e-9, 2.0, 3.0), 1.0));
  // Length 0: only an exact zero at s = 0 counts.
  EXPECT_EQ(first_root(Cubic{0.0, 1.0, 1.0, 1.0}, 0.0), 0.0);
  EXPECT_FALSE(first_root(Cubic{1e-3, 1.0, 1.0, 1.0}, 0.0));
  // A negative or NaN length is no interval.
  EXPECT_FALSE(first_root(Cubic{0.0, 1.0, 0.0, 0.0}, -1.0));
  EXPECT_FALSE(first_root(Cubic{0.0, 1.0, 0.0, 0.0}, std::nan("")));
}

TEST(Cubic, FirstRootWithoutRootsAndOfZero) {
  EXPECT_FALSE(first_root(Cubic{1.0, 0.0, 0.0, 0.0}, 1.0));
  EXPECT_FALSE(first_root(Cubic{1.0, -1.0, 1.0, 0.0}, 10.0));   // s^2 - s + 1 > 0
  EXPECT_FALSE(first_root(from_roots(1.5, 2.0, 3.0), 1.0));      // roots beyond the interval
  EXPECT_FALSE(first_root(from_roots(-0.5, -0.2, 3.0), 1.0));    // roots before it
  // Two roots inside a sub-interval between critical points cannot hide: (s-0.4)(s-0.6)(s-5).
  auto r = first_root(from_roots(0.4, 0.6, 5.0), 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.4, 1e-15);
  // Identically zero: everywhere a root, the first is 0.
  EXPECT_EQ(first_root(Cubic{}, 1.0), 0.0);
  EXPECT_EQ(first_root(Cubic{}, 0.0), 0.0);
}

TEST(Cubic, FirstRootOfNearlyLinearCubics) {
  // A cubic term far below the rest must neither create nor lose roots.
  for (double c3 : {1e-20, -1e-20, 1e-12, -1e-12, 1e-8}) {
    const Cubic g{-0.3, 1.0, 0.0, c3};
    auto r = first_root(g, 1.0);
    ASSERT_TRUE(r) << c3;
    EXPECT_NEAR(*r, 0.3, 1e-7) << c3;
    EXPECT_LE(std::fabs(g(*r)), 1e-15) << c3;
  }
  for (double c2 : {1e-18, -1e-18}) {
    auto r = first_root(Cubic{-0.3, 1.0, c2, 1e-18}, 1.0);
    ASSERT_TRUE(r);
    EXPECT_NEAR(*r, 0.3, 1e-15);
  }
  EXPECT_FALSE(first_root(Cubic{0.3, 1.0, 0.0, 1e-20}, 1.0));
}

TEST(Cubic, FirstRootIsScaleInvariant) {
  // Multiplying a cubic by any positive or negative scale changes neither its roots nor whether
  // a tangent root is found: the tolerance is relative. (s - 0.375)^2 has exact coefficients,
  // and so do its multiples by powers of two: its tangent root is found to full precision.
  // Decimal scales round the coefficients, which moves a double root by up to sqrt(eps) ~ 1e-8
  // (two close simple roots or none): it must still be found, within that conditioning.
  const Cubic simple = from_roots(0.2, 0.5, 0.9);
  const Cubic tangent{0.140625, -0.75, 1.0, 0.0};
  const Cubic none{0.140625 + 1e-6, -0.75, 1.0, 0.0};
  // Scales past 1e154, where the squares of the derivative's coefficients overflow, too.
  for (double k : {0x1p-100, -0x1p-100, 0x1p100, -0x1p100, 0x1p1000, -0x1p1000, 1e-30, -1e-30, 1e-15, 1e15, 1e30,
                   -1e30, 1e200, -1e300}) {
    auto scaled = [k](Cubic g) { return Cubic{g.c0 * k, g.c1 * k, g.c2 * k, g.c3 * k}; };
    const double log2k = std::fabs(std::log2(std::fabs(k)));
    const bool exact = log2k == 100 || log2k == 1000;
    auto r = first_root(scaled(simple), 1.0);
    ASSERT_TRUE(r) << k;
    EXPECT_NEAR(*r, 0.2, 1e-15) << k;
    r = first_root(scaled(tangent), 1.0);
    ASSERT_TRUE(r) << k;
    EXPECT_NEAR(*r, 0.375, exact ? 1e-12 : 1e-7) << k;
    EXPECT_FALSE(first_root(scaled(none), 1.0)) << k;
  }
  // Coefficients of very different sizes: 1e30 s - 1e30 * 0.25 with a 1e-30 cubic term.
  auto r = first_root(Cubic{-0.25e30, 1e30, 0.0, 1e-30}, 1.0);
  ASSERT_TRUE(r);
  EXPECT_NEAR(*r, 0.25, 1e-15);
  // Long and short intervals: the root of s - 0.25 L over [0, L].
  for (double L : {1e-12, 1e-6, 1e6}) {
    r = first_root(Cubic{-0.25 * L, 1.0, 0.0, 0.0}, L);
    ASSERT_TRUE(r) << L;
    EXPECT_NEAR(*r, 0.25 * L, 1e-15 * L) << L;
  }
}

TEST(Cubic, CubicMaxAtEndsAndCriticalPoints) {
  double where = -1;
  // -(s - 0.3)^2 + 2: maximum 2 at 0.3.
  EXPECT_NEAR(cubic_max(Cubic{2 - 0.09, 0.6, -1.0, 0.0}, 1.0, where), 2.0, 1e-15);
  EXPECT_NEAR(where, 0.3, 1e-12);
  // Increasing: at the far end.
  EXPECT_DOUBLE_EQ(cubic_max(Cubic{0.0, 1.0, 0.0, 1.0}, 2.0, where), 10.0);
  EXPECT_EQ(where, 2.0);
  // Decreasing: at s = 0.
  EXPECT_DOUBLE_EQ(cubic_max(Cubic{1.0, -1.0, 0.0, 0.0}, 2.0, where), 1.0);
  EXPECT_EQ(where, 0.0);
  // Constant: the first place.
  EXPECT_DOUBLE_EQ(cubic_max(Cubic{3.0, 0, 0, 0}, 1.0, where), 3.0);
  EXPECT_EQ(where, 0.0);
  // A local maximum inside and a larger value at the end: (s-0.2)(s-0.6)(s-1) has a local max
  // near 0.37; on [0, 2] the end wins, on [0, 0.9] the interior maximum does.
  const Cubic g = from_roots(0.2, 0.6, 1.0);
  EXPECT_DOUBLE_EQ(cubic_max(g, 2.0, where), g(2.0));
  EXPECT_EQ(where, 2.0);
  const double m = cubic_max(g, 0.9, where);
  EXPECT_GT(where, 0.2);
  EXPECT_LT(where, 0.6);
  EXPECT_NEAR(g.derivative(where), 0.0, 1e-12);
  // Brute force: no sampled value exceeds it.
  for (int i = 0; i <= 9000; ++i) EXPECT_LE(g(0.9 * i / 9000), m + 1e-15);
  // Length 0: the value at 0.
  EXPECT_DOUBLE_EQ(cubic_max(g, 0.0, where), g(0.0));
}

TEST(Cubic, BisectCrossingEndsWithTheSecantOfItsLastBracket) {
  // A straight line: the secant is its root, with or without bisections.
  for (int steps : {0, 1, 6}) {
    const double t = bisect_crossing([](double m) { return 2 * m - 0.6; }, 0.0, 1.0, -0.6, 1.4, steps);
    EXPECT_NEAR(t, 0.3, 1e-15) << steps;
  }
  // A value exactly on the isovalue at the far end is the crossing.
  EXPECT_EQ(bisect_crossing([](double) { return 1.0; }, 0.0, 1.0, -1.0, 0.0, 6), 1.0);
  // Curved functions: after 6 bisections the secant of the last bracket (1/64 wide) lands at
  // least 16 times closer than the bracket's midpoint could promise (1/128).
  struct Case {
    double (*g)(double);
    double root;
  };
  const Case cases[] = {
      {[](double m) { return m * m * m - 0.02; }, std::cbrt(0.02)},
      {[](double m) { return std::exp(3 * m) - 2.0; }, std::log(2.0) / 3},
  };
  for (const Case& c : cases) {
    int evaluations = 0;
    const double t = bisect_crossing([&](double m) { return ++evaluations, c.g(m); }, 0.0, 1.0, c.g(0.0), c.g(1.0), 6);
    EXPECT_EQ(evaluations, 6);
    EXPECT_NEAR(t, c.root, 1.0 / 128 / 16);
  }
  // Decreasing through the isovalue, and a crossing exactly at a bisection midpoint.
  EXPECT_NEAR(bisect_crossing([](double m) { return 0.4 - m; }, 0.0, 1.0, 0.4, -0.6, 6), 0.4, 1e-15);
  EXPECT_EQ(bisect_crossing([](double m) { return m - 0.5; }, 0.0, 1.0, -0.5, 0.5, 6), 0.5);
}

TEST(Cubic, TrilinearCubicMatchesDirectInterpolation) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0), value(-1.0, 1.0);
  double worst = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    // Scales from 1e-30 to 1e30, with an offset inside the corner range.
    const double scale = std::pow(10.0, std::uniform_int_distribution<int>(-30, 30)(rng));
    double c[8];
    for (double& v : c) v = value(rng) * scale;
    const double offset = value(rng) * scale;
    // A segment between two random points of the cell; the cubic's parameter is s in [0, L].
    double u0[3], u1[3], du[3];
    const double L = trial % 3 == 0 ? 1.0 : unit(rng) * 2 + 1e-3;
    for (int a = 0; a < 3; ++a) {
      u0[a] = unit(rng), u1[a] = unit(rng);
      if (trial % 7 == 0) u1[a] = u0[a];  // axis-parallel and degenerate segments
      du[a] = (u1[a] - u0[a]) / L;
    }
    const Cubic g = trilinear_cubic(c, offset, u0, du);
    double mag = 0;
    for (double v : c) mag = std::max(mag, std::fabs(v - offset));
    for (int i = 0; i <= 16; ++i) {
      const double s = L * i / 16;
      const double direct = direct_trilinear(c, u0[0] + s * du[0], u0[1] + s * du[1], u0[2] + s * du[2]) - offset;
      const double err = std::fabs(g(s) - direct) / mag;
      worst = std::max(worst, err);
      ASSERT_LE(err, 1e-12) << "trial " << trial << " s " << s;
    }
    // The derivative against the exact gradient along the segment.
    const double s = L * unit(rng);
    double grad[3];
    direct_gradient(c, u0[0] + s * du[0], u0[1] + s * du[1], u0[2] + s * du[2], grad);
    const double slope = grad[0] * du[0] + grad[1] * du[1] + grad[2] * du[2];
    ASSERT_LE(std::fabs(g.derivative(s) - slope), 1e-12 * mag * (std::fabs(du[0]) + std::fabs(du[1]) + std::fabs(du[2]) + 1));
  }
  std::cout << "[ measured ] trilinear_cubic vs direct interpolation: worst relative error " << worst << "\n";
}

TEST(Cubic, FirstRootOfTrilinearCubicsIsTheFirstSignChange) {
  // Random cells and segments: the first root agrees with a dense scan for a sign change, and
  // no sign change of the direct interpolation lies before the root returned.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0), value(-1.0, 1.0);
  int found = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    double c[8], u0[3], du[3];
    for (double& v : c) v = value(rng);
    for (int a = 0; a < 3; ++a) u0[a] = unit(rng), du[a] = unit(rng) - u0[a];
    const Cubic g = trilinear_cubic(c, 0.0, u0, du);
    auto direct = [&](double s) {
      return direct_trilinear(c, u0[0] + s * du[0], u0[1] + s * du[1], u0[2] + s * du[2]);
    };
    const auto r = first_root(g, 1.0);
    constexpr int n = 2048;
    std::optional<double> scan;
    for (int i = 1; i <= n && !scan; ++i)
      if ((direct(double(i - 1) / n) < 0) != (direct(double(i) / n) < 0)) scan = double(i) / n;
    if (scan) {
      ASSERT_TRUE(r) << "trial " << trial;
      EXPECT_LE(*r, *scan + 1e-12) << "trial " << trial;
      EXPECT_GE(*r, *scan - 1.0 / n - 1e-12) << "trial " << trial;
      ++found;
    }
    if (r) {
      EXPECT_LE(std::fabs(direct(*r)), 1e-12) << "trial " << trial;
    }
  }
  EXPECT_GT(found, 500);
}

}  // namespace
}  // namespace brickyard
