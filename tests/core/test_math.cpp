#include <gtest/gtest.h>

#include <iostream>

#include "core/camera.h"
#include "core/math.h"

namespace brickyard {
namespace {

TEST(Vec3, ArithmeticAndProducts) {
  const Vec3d a{1, 2, 3}, b{4, -5, 6};
  EXPECT_EQ(a + b, Vec3d(5, -3, 9));
  EXPECT_EQ(a - b, Vec3d(-3, 7, -3));
  EXPECT_EQ(a * 2.0, Vec3d(2, 4, 6));
  EXPECT_EQ(2.0 * a, Vec3d(2, 4, 6));
  EXPECT_EQ(a * b, Vec3d(4, -10, 18));
  EXPECT_DOUBLE_EQ(dot(a, b), 4 - 10 + 18);
  EXPECT_EQ(cross(Vec3d(1, 0, 0), Vec3d(0, 1, 0)), Vec3d(0, 0, 1));
  EXPECT_DOUBLE_EQ(dot(cross(a, b), a), 0.0);
  EXPECT_DOUBLE_EQ(length(Vec3d(3, 4, 12)), 13.0);
  EXPECT_EQ(min(a, b), Vec3d(1, -5, 3));
  EXPECT_EQ(max(a, b), Vec3d(4, 2, 6));
  EXPECT_EQ(Vec3i(Vec3d(1.7, -2.2, 3.9)), Vec3i(1, -2, 3));
  EXPECT_EQ(volume(Vec3s(2048, 2048, 2048)), int64_t(1) << 33);
}

TEST(PowUint, MatchesTheLibraryWithinItsRoundings) {
  // Bases over [0, 1] (a specular term's n.h) and beyond, every exponent up to 4096.
  double worst = 0;
  for (unsigned n = 0; n <= 4096; n = n < 64 ? n + 1 : n * 2)
    for (int i = 0; i <= 1000; ++i) {
      const double x = i / 1000.0 * (i % 7 == 0 ? 1.02 : 1.0);
      const double want = std::pow(x, double(n)), got = pow_uint(x, n);
      if (want == 0 || !std::isfinite(want)) {
        EXPECT_EQ(got, want) << x << "^" << n;
        continue;
      }
      const double rel = std::abs(got - want) / want;
      worst = std::max(worst, rel);
      // Squaring doubles the relative error so far: (n - 1) roundings' worth, n u with pow's.
      ASSERT_LE(rel, double(n + 1) * 0x1p-53) << x << "^" << n;
    }
  EXPECT_EQ(pow_uint(0.0, 0), 1.0);
  EXPECT_EQ(pow_uint(2.0, 10), 1024.0);
  EXPECT_EQ(pow_uint(-0.5, 3), -0.125);
  std::cout << "[ measured ] pow_uint against std::pow: worst relative error " << worst << "\n";
}

TEST(Log2Fast, MatchesTheLibraryAcrossTheDoubleRange) {
  // Every binade's mantissa, finely around the sqrt(2) fold and the powers of two.
  double worst = 0;
  for (int e = -1021; e <= 1023; e += 7)
    for (int i = 0; i <= 4096; ++i) {
      const double x = std::ldexp(1.0 + double(i) / 4096.0, e);
      worst = std::max(worst, std::abs(log2_fast(x) - std::log2(x)));
    }
  for (double x : {std::sqrt(2.0), std::nextafter(std::sqrt(2.0), 2.0), std::nextafter(std::sqrt(2.0), 0.0), 1.0, 2.0, 0.5})
    worst = std::max(worst, std::abs(log2_fast(x) - std::log2(x)));
  EXPECT_LT(worst, 2e-9);
  EXPECT_EQ(log2_fast(1.0), 0.0);
  EXPECT_EQ(log2_fast(8.0), 3.0);
  EXPECT_EQ(log2_fast(0.0), -std::numeric_limits<double>::infinity());
  EXPECT_EQ(log2_fast(std::numeric_limits<double>::infinity()), std::numeric_limits<double>::infinity());
  EXPECT_TRUE(std::isnan(log2_fast(std::nan(""))));
  EXPECT_TRUE(std::isnan(log2_fast(-1.0)));
  EXPECT_NEAR(log2_fast(std::numeric_limits<double>::denorm_min()), -1074.0, 1e-12);
}

TEST(Vec3, NormalizeKeepsZeroVectorFinite) {
  EXPECT_EQ(normalize(Vec3f{}), Vec3f{});
  const Vec3f n = normalize(Vec3f{0, 3, 4});
  EXPECT_FLOAT_EQ(length(n), 1.0f);
  EXPECT_FLOAT_EQ(n.z, 0.8f);
}

TEST(Vec3, MajorAxisPicksLargestMagnitude) {
  EXPECT_EQ(major_axis(Vec3d(-5, 1, 2)), 0);
  EXPECT_EQ(major_axis(Vec3d(0, -0.5, 0.1)), 1);
  EXPECT_EQ(major_axis(Vec3d(0, 0, -1e-9)), 2);
}

TEST(Box3, DefaultIsEmptyAndExtendGrows) {
  Box3d b;
  EXPECT_TRUE(b.empty());
  b.extend(Vec3d(1, 2, 3)).extend(Vec3d(-1, 5, 0));
  EXPECT_FALSE(b.empty());
  EXPECT_EQ(b.lo, Vec3d(-1, 2, 0));
  EXPECT_EQ(b.hi, Vec3d(1, 5, 3));
  EXPECT_EQ(b.center(), Vec3d(0, 3.5, 1.5));
  EXPECT_TRUE(b.contains(Vec3d(1, 5, 3)));
  EXPECT_FALSE(b.contains(Vec3d(1.0001, 5, 3)));
  EXPECT_TRUE(b.overlaps(Box3d({1, 5, 3}, {2, 6, 4})));
  EXPECT_TRUE(b.intersect(Box3d({2, 2, 2}, {3, 3, 3})).empty());
}

TEST(RayBox, HitsMissesAndInteriorOrigins) {
  const Box3d box({0, 0, 0}, {1, 1, 1});
  auto hit = intersect(Rayd({-1, 0.5, 0.5}, {1, 0, 0}), box);
  EXPECT_DOUBLE_EQ(hit.t0, 1.0);
  EXPECT_DOUBLE_EQ(hit.t1, 2.0);
  EXPECT_TRUE(intersect(Rayd({-1, 2, 0.5}, {1, 0, 0}), box).empty());
  auto inside = intersect(Rayd({0.5, 0.5, 0.5}, {0, 0, -1}), box);
  EXPECT_DOUBLE_EQ(inside.t0, 0.0);
  EXPECT_DOUBLE_EQ(inside.t1, 0.5);
  EXPECT_TRUE(intersect(Rayd({-1, 0.5, 0.5}, {-1, 0, 0}), box).empty());  // pointing away
}

TEST(RayBox, AxisParallelRayOnAFacePlaneIsNotNaN) {
  const Box3d box({0, 0, 0}, {1, 1, 1});
  // Origin exactly on the y = 0 and z = 1 planes, travelling along x: 0 * inf terms appear.
  auto hit = intersect(Rayd({-2, 0, 1}, {1, 0, 0}), box);
  EXPECT_FALSE(hit.empty());
  EXPECT_DOUBLE_EQ(hit.t0, 2.0);
  EXPECT_DOUBLE_EQ(hit.t1, 3.0);
  // Parallel and outside the slab: a miss.
  EXPECT_TRUE(intersect(Rayd({-2, -0.1, 0.5}, {1, 0, 0}), box).empty());
}

TEST(Camera, InBoxMapsNormalisedCoordinatesAndKeepsFlatAxesApart) {
  Camera c;
  c.eye = {0.5, -1.0, 0.5};
  c.target = {0.5, 0.5, 0.5};
  const Camera w = c.in_box(Box3d({0, 0, 0}, {10, 20, 30}));
  EXPECT_EQ(w.eye, Vec3d(5, -20, 15));
  EXPECT_EQ(w.target, Vec3d(5, 10, 15));
  // A slice (zero extent in z) and a single voxel: eye and target must not coincide.
  c.eye = {0.5, 0.5, 2.0};
  const Camera slice = c.in_box(Box3d({0, 0, 4}, {10, 10, 4}));
  EXPECT_EQ(slice.target, Vec3d(5, 5, 4));
  EXPECT_EQ(slice.eye, Vec3d(5, 5, 4 + 1.5 * 10));
  const Camera point = c.in_box(Box3d({1, 1, 1}, {1, 1, 1}));
  EXPECT_GT(length(point.eye - point.target), 1.0);
}

}  // namespace
}  // namespace brickyard

namespace brickyard {
namespace {

TEST(ImageRays, PixelOfInvertsRayAndDirectionsMatchRay) {
  Camera cam;
  cam.eye = {2.0, -1.5, 1.2};
  cam.target = {0.4, 0.6, 0.5};
  cam.up = {0, 0, 1};
  cam.fov_degrees = 37;
  const ImageRays rays(cam, 96, 64);
  for (double px : {0.25, 10.5, 47.0, 95.75})
    for (double py : {0.5, 31.25, 63.5}) {
      const Rayd r = rays.ray(px, py);
      double qx = 0, qy = 0;
      ASSERT_TRUE(rays.pixel_of(r.org + r.dir * 3.7, qx, qy));
      EXPECT_NEAR(qx, px, 1e-9);
      EXPECT_NEAR(qy, py, 1e-9);
      EXPECT_FALSE(rays.pixel_of(r.org - r.dir * 0.5, qx, qy)) << "behind the eye";
    }
  double ex = 0, ey = 0;
  EXPECT_FALSE(rays.pixel_of(cam.eye, ex, ey)) << "the eye itself";
  double dx[12 * 5], dy[12 * 5], dz[12 * 5];
  rays.directions(40, 20, 12, 5, dx, dy, dz);
  for (int j = 0; j < 5; ++j)
    for (int i = 0; i < 12; ++i) {
      const Vec3d d = rays.ray(40 + i + 0.5, 20 + j + 0.5).dir;
      const size_t l = size_t(j * 12 + i);
      EXPECT_NEAR(dx[l], d.x, 1e-14);
      EXPECT_NEAR(dy[l], d.y, 1e-14);
      EXPECT_NEAR(dz[l], d.z, 1e-14);
    }
}

}  // namespace
}  // namespace brickyard
