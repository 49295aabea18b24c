// cubic.h: the trilinear cubic along a ray and its first root, against independent
// evaluations (nested linear interpolation of the corners, a dense scan for sign changes) and
// closed forms.
//
// Both first-root finders, first_root (bisection) and first_root_falsi (Neubauer/Marmitt's
// repeated linear interpolation, Illinois variant), pass every first-root case (the FirstRoot
// suite runs once per finder); on random trilinear cells they agree on whether there is a root
// and, where the crossing is not ill-conditioned, on where it is; first_root_falsi gives
// first_root's answer exactly wherever no crossing is refined (tangents, knots, no root, bad
// input), and converges within few evaluations of g.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <optional>
#include <ostream>
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

/// |c0| + |c1| L + |c2| L^2 + |c3| L^3: the size g's values can reach on [0, L], the scale
/// first_root's relative tolerance refers to.
double magnitude(const Cubic& g, double L) {
  return std::fabs(g.c0) + std::fabs(g.c1) * L + std::fabs(g.c2) * L * L + std::fabs(g.c3) * L * L * L;
}

/// A random ray through the unit cell, clipped to it: entry u0, direction du, and the length of
/// the parameter's range inside the cell (u0 + s du for s in [0, length]). Directions are
/// random unit vectors, so every path through the cell is drawn, corners and edges included.
template <typename Rng>
double random_ray_through_cell(Rng& rng, double u0[3], double du[3]) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> normal;
  double p[3], d[3];
  double norm = 0;
  for (int a = 0; a < 3; ++a) p[a] = unit(rng), d[a] = normal(rng), norm += d[a] * d[a];
  norm = std::sqrt(norm);
  double t0 = -std::numeric_limits<double>::infinity(), t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    d[a] /= norm;
    if (d[a] == 0) continue;
    const double ta = -p[a] / d[a], tb = (1 - p[a]) / d[a];
    t0 = std::max(t0, std::min(ta, tb));
    t1 = std::min(t1, std::max(ta, tb));
  }
  for (int a = 0; a < 3; ++a) u0[a] = std::clamp(p[a] + t0 * d[a], 0.0, 1.0), du[a] = d[a];
  return t1 - t0;
}

// --- first roots, through either finder ---------------------------------------------------

/// One of the two first-root finders, at its default settings.
struct Finder {
  const char* name;
  std::optional<double> (*find)(const Cubic& g, double length);
};

void PrintTo(const Finder& f, std::ostream* os) { *os << f.name; }

const Finder kFinders[] = {
    {"first_root", [](const Cubic& g, double length) { return first_root(g, length); }},
    {"first_root_falsi", [](const Cubic& g, double length) { return first_root_falsi(g, length); }},
};

class FirstRoot : public ::testing::TestWithParam<Finder> {
 protected:
  static std::optional<double> first_root(const Cubic& g, double length) { return GetParam().find(g, length); }
};

TEST_P(FirstRoot, OfSimpleRoots) {
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

TEST_P(FirstRoot, FindsTangentAndTripleRoots) {
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

TEST_P(FirstRoot, AtTheIntervalEnds) {
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

TEST_P(FirstRoot, WithoutRootsAndOfZero) {
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
  // NaN coefficients: no root, rather than a NaN one.
  EXPECT_FALSE(first_root(Cubic{std::nan(""), 1.0, 0.0, 0.0}, 1.0));
  EXPECT_FALSE(first_root(Cubic{-0.5, 1.0, std::nan(""), 0.0}, 1.0));
}

TEST_P(FirstRoot, OfNearlyLinearCubics) {
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

TEST_P(FirstRoot, IsScaleInvariant) {
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

TEST_P(FirstRoot, OfTrilinearCubicsIsTheFirstSignChange) {
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

INSTANTIATE_TEST_SUITE_P(Cubic, FirstRoot, ::testing::ValuesIn(kFinders),
                         [](const auto& param_info) { return std::string(param_info.param.name); });

// --- first_root_falsi against first_root --------------------------------------------------

TEST(Cubic, FalsiGivesFirstRootsAnswerWhereNoCrossingIsRefined) {
  // Where the first root is decided at a knot (the entry, an extremum touching zero, the exit)
  // or there is none, the falsi finder must not differ from first_root at all: the same value,
  // bit for bit, or nullopt for both. Each case is checked to be such a case, so that the
  // comparison is not of two refinements that happen to agree.
  const double nan = std::nan("");
  struct Case {
    Cubic g;
    double length;
  };
  const Case cases[] = {
      {Cubic{0.09, -0.6, 1.0, 0.0}, 1.0},                 // tangent, coefficients rounded
      {Cubic{0.140625, -0.75, 1.0, 0.0}, 1.0},            // tangent, exact
      {from_roots(0.375, 0.375, -1.0, -1.0), 1.0},        // tangent from below
      {from_roots(0.4375, 0.4375, -0.0625), 1.0},         // tangent after a root before 0
      {from_roots(0.5, 0.5, 0.5), 1.0},                   // dyadic triple root
      {Cubic{0.09 + 1e-9, -0.6, 1.0, 0.0}, 1.0},          // just above a tangent
      {Cubic{0.0, 1.0, -3.0, 1.0}, 1.0},                  // zero at the entry
      {Cubic{-0.5, 0.5, 0.0, 0.0}, 1.0},                  // zero at the exit
      {Cubic{0.0, 1.0, 1.0, 1.0}, 0.0},                   // length 0, zero there
      {Cubic{1e-3, 1.0, 1.0, 1.0}, 0.0},                  // length 0, none
      {Cubic{0.0, 1.0, 0.0, 0.0}, -1.0},                  // negative length
      {Cubic{0.0, 1.0, 0.0, 0.0}, nan},                   // NaN length
      {Cubic{nan, 1.0, 0.0, 0.0}, 1.0},                   // NaN coefficient
      {Cubic{-0.5, 1.0, 0.0, nan}, 1.0},                  //
      {Cubic{}, 1.0},                                     // identically zero
      {Cubic{1.0, -1.0, 1.0, 0.0}, 10.0},                 // positive throughout
      {from_roots(1.5, 2.0, 3.0), 1.0},                   // roots beyond the interval
      {from_roots(-0.5, -0.2, 3.0), 1.0},                 // roots before it
      {from_roots(-1e-9, 2.0, 3.0), 1.0},                 // just before 0
      {Cubic{0.3, 1.0, 0.0, 1e-20}, 1.0},                 // nearly linear, root before 0
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(::testing::Message() << "g = " << c.g.c0 << " + " << c.g.c1 << " s + " << c.g.c2 << " s^2 + " << c.g.c3
                                      << " s^3 on [0, " << c.length << "]");
    EXPECT_NE(first_root_bracket(c.g, c.length, 1e-12).kind, RootBracket::crossing);
    const auto want = first_root(c.g, c.length), got = first_root_falsi(c.g, c.length);
    ASSERT_EQ(bool(got), bool(want));
    if (want) {
      EXPECT_EQ(*got, *want);  // bit for bit
    }
  }
}

TEST(Cubic, FalsiAgreesWithFirstRootOnRandomTrilinearCells) {
  // 100000 random cells (corners in [-1, 1], an isovalue in [-0.5, 0.5]) and random rays
  // through them: both finders find a root, or neither does; every root lies in [0, length],
  // is finite, and both agree to 1e-9 of the length where the crossing is clear (|g'| at the
  // root times the length at least 1e-6 of g's size over the segment). There the root moves
  // by at most the rounding of g (~1e-16 of its size) over that slope, far below 1e-9;
  // flatter crossings are ill-conditioned, and where each finder lands in the band of
  // rounding noise around the root is not a difference between them.
  std::mt19937_64 rng(2004);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  int roots = 0, clear = 0, none = 0;
  double worst = 0;
  for (int trial = 0; trial < 100000; ++trial) {
    double c[8], u0[3], du[3];
    for (double& v : c) v = value(rng);
    const double offset = 0.5 * value(rng);
    const double length = random_ray_through_cell(rng, u0, du);
    const Cubic g = trilinear_cubic(c, offset, u0, du);
    const auto want = first_root(g, length), got = first_root_falsi(g, length);
    ASSERT_EQ(bool(got), bool(want)) << "trial " << trial;
    if (!want) {
      ++none;
      continue;
    }
    ++roots;
    for (double r : {*want, *got}) {
      ASSERT_TRUE(std::isfinite(r)) << "trial " << trial;
      ASSERT_GE(r, 0.0) << "trial " << trial;
      ASSERT_LE(r, length) << "trial " << trial;
    }
    if (std::fabs(g.derivative(*want)) * length < 1e-6 * magnitude(g, length)) continue;
    ++clear;
    const double err = std::fabs(*got - *want) / length;
    worst = std::max(worst, err);
    ASSERT_LE(err, 1e-9) << "trial " << trial << ": " << *got << " against " << *want << " on [0, " << length << "]";
  }
  std::cout << "[ measured ] first_root_falsi vs first_root: " << roots << " roots (" << clear << " clear), " << none
            << " none; worst difference / length " << worst << "\n";
  // Not vacuous: many of each.
  EXPECT_GT(clear, 20000);
  EXPECT_GT(none, 20000);
}

TEST(Cubic, FalsiAgreesWithFirstRootNearTangents) {
  // The hard cases: random cells with the isovalue moved to within 1e-4 to 1e-16 (relative)
  // of an extremum's value along the ray, above or below it, so that the extremum just touches,
  // just crosses or just misses the isosurface. Both finders find a root or neither does; each
  // root is one, |g| there within the relative tolerance; clear crossings agree to 1e-9 of the
  // length. Flat ones do not need to: a crossing 1e-16 below an extremum is anywhere within
  // ~1e-8 of it in double arithmetic.
  std::mt19937_64 rng(2002);
  std::uniform_real_distribution<double> unit(0.0, 1.0), value(-1.0, 1.0);
  int roots = 0, clear = 0, flat = 0, none = 0;
  double worst = 0, worst_flat = 0;
  for (int trial = 0; trial < 50000; ++trial) {
    double c[8], u0[3], du[3];
    for (double& v : c) v = value(rng);
    const double length = random_ray_through_cell(rng, u0, du);
    Cubic g = trilinear_cubic(c, 0.0, u0, du);
    double crit[2];
    const int nc = quadratic_roots_in(3 * g.c3, 2 * g.c2, g.c1, 0, length, crit);
    const double nudge = std::pow(10.0, -4 - 12 * unit(rng)) * (trial % 2 ? 1 : -1);
    if (nc == 0) continue;
    g.c0 -= g(crit[trial % nc]) * (1 + nudge);
    const auto want = first_root(g, length), got = first_root_falsi(g, length);
    ASSERT_EQ(bool(got), bool(want)) << "trial " << trial;
    if (!want) {
      ++none;
      continue;
    }
    ++roots;
    const double mag = magnitude(g, length);
    for (double r : {*want, *got}) {
      ASSERT_GE(r, 0.0) << "trial " << trial;
      ASSERT_LE(r, length) << "trial " << trial;
      ASSERT_LE(std::fabs(g(r)), 1.01e-12 * mag) << "trial " << trial << " at " << r;
    }
    const double err = std::fabs(*got - *want) / length;
    if (std::fabs(g.derivative(*want)) * length < 1e-6 * mag) {
      ++flat;
      worst_flat = std::max(worst_flat, err);
      continue;
    }
    ++clear;
    worst = std::max(worst, err);
    ASSERT_LE(err, 1e-9) << "trial " << trial << ": " << *got << " against " << *want << " on [0, " << length << "]";
  }
  std::cout << "[ measured ] near tangents: " << roots << " roots (" << clear << " clear, " << flat << " flat), "
            << none << " none; worst difference / length " << worst << " clear, " << worst_flat << " flat\n";
  EXPECT_GT(clear, 3000);
  EXPECT_GT(flat, 3000);
  EXPECT_GT(none, 3000);
}

TEST(Cubic, FalsiConvergesInFewEvaluations) {
  // On clear crossings of random trilinear cells the Illinois iteration narrows the bracket to
  // 1e-12 of the length within 16 evaluations of g, 10 at most on average (8 measured), within 1e-12 of
  // first_root's root. Plain regula falsi keeps one end fixed wherever g is convex or concave
  // over the bracket and converges only linearly; without the minimum step the far end stays
  // put for dozens of halvings after the root is found (both measured: either fails here).
  // The steps bound the work: with 2, two evaluations, and most roots are still coarse.
  std::mt19937_64 rng(2002);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  int clear = 0, most = 0, coarse_after_two = 0;
  long total = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    double c[8], u0[3], du[3];
    for (double& v : c) v = value(rng);
    const double length = random_ray_through_cell(rng, u0, du);
    const Cubic g = trilinear_cubic(c, 0.0, u0, du);
    const RootBracket b = first_root_bracket(g, length, 1e-12);
    if (b.kind != RootBracket::crossing) continue;
    const double want = *first_root(g, length);
    if (std::fabs(g.derivative(want)) * length < 1e-3 * magnitude(g, length)) continue;
    ++clear;
    int evaluations = 0;
    auto counted = [&](double s) { return ++evaluations, g(s); };
    const double got = falsi_crossing(counted, b.lo, b.hi, b.glo, b.ghi, 64, 1e-12 * length);
    ASSERT_NEAR(got, want, 1e-12 * length) << "trial " << trial;
    ASSERT_LE(evaluations, 16) << "trial " << trial;
    most = std::max(most, evaluations);
    total += evaluations;
    evaluations = 0;
    const double two = falsi_crossing(counted, b.lo, b.hi, b.glo, b.ghi, 2, 1e-12 * length);
    coarse_after_two += std::fabs(two - want) > 1e-12 * length;
    ASSERT_EQ(evaluations, 2) << "trial " << trial;
  }
  std::cout << "[ measured ] first_root_falsi: " << double(total) / clear << " evaluations on average, " << most
            << " at most, over " << clear << " clear crossings\n";
  EXPECT_GT(clear, 5000);
  EXPECT_LE(total, 10L * clear);
  EXPECT_GT(coarse_after_two, clear / 2);
}

TEST(Cubic, FalsiIsFiniteOnExtremeScales) {
  // Finite cubics of any size and lengths from 1e-12 to 1e12: a root, if any, is a number in
  // [0, length], never NaN, and the falsi finder finds one exactly when first_root does. Half
  // the cubics have random coefficients (mostly decided at a knot: one term dwarfs the rest);
  // half have three random roots in [-L, 2L] and values from 1e-290 to 1e307: their clear
  // crossings agree with first_root to 1e-9, also where the squares of the coefficients
  // overflow (past 1e154) and the derivative's roots were lost.
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> value(-1.0, 1.0), place(-1.0, 2.0);
  std::uniform_int_distribution<int> exponent(-300, 300), length_exponent(-12, 12);
  int crossings = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    const int e = length_exponent(rng);
    const double length = std::pow(10.0, e);
    Cubic g;
    if (trial % 2 == 0) {
      g = {value(rng) * std::pow(10.0, exponent(rng)), value(rng) * std::pow(10.0, exponent(rng)),
           value(rng) * std::pow(10.0, exponent(rng)), value(rng) * std::pow(10.0, exponent(rng))};
    } else {
      // |g| on [0, L] up to about 27 * 10^(k + 3e): k up to 306 - 3e keeps it finite, and from
      // -290 - 3e its values normal (subnormal ones have too few bits to place a root).
      const int k = std::uniform_int_distribution<int>(-290 - 3 * std::min(e, 0), 306 - 3 * std::max(e, 0))(rng);
      g = from_roots(place(rng) * length, place(rng) * length, place(rng) * length, value(rng) * std::pow(10.0, k));
    }
    const auto want = first_root(g, length), got = first_root_falsi(g, length);
    ASSERT_EQ(bool(got), bool(want)) << "trial " << trial;
    if (!got) continue;
    ASSERT_FALSE(std::isnan(*got)) << "trial " << trial;
    ASSERT_GE(*got, 0.0) << "trial " << trial;
    ASSERT_LE(*got, length) << "trial " << trial;
    const RootBracket b = first_root_bracket(g, length, 1e-12);
    if (b.kind != RootBracket::crossing) continue;
    ++crossings;
    if (std::fabs(g.derivative(*want)) * length >= 1e-6 * magnitude(g, length)) {
      ASSERT_NEAR(*got, *want, 1e-9 * length) << "trial " << trial;
    }
  }
  EXPECT_GT(crossings, 3000);
  // Values near the largest double at both ends: g(b) - g(a) overflows, the falsi point must not.
  int evaluations = 0;
  auto line = [&](double s) { return ++evaluations, 1.5e308 * (2 * s - 1); };
  EXPECT_EQ(falsi_crossing(line, 0.0, 1.0, -1.5e308, 1.5e308, 64, 1e-12), 0.5);
  EXPECT_LE(evaluations, 1);
}

// --- the cubic, its maximum, bisect_crossing ---------------------------------------------

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

}  // namespace
}  // namespace brickyard
