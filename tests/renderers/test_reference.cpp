// The reference renderer's numerical core and its accuracy against closed forms.
//
// 1. grid_walk.h (the 3D DDA) against brute-force cell enumeration; trilinear interpolation
//    (cell_accessor.h) against its definition, and in float against double. The trilinear
//    cubic along a ray and its first root (cubic.h) are tested in test_cubic.cpp.
// 2. The reference isosurface of a sphere signed-distance field against the closed-form
//    ray-sphere intersection, in grid mode and in analytic mode, with the error bound the
//    trilinear interpolant of a sampled SDF obeys (see SphereBound below); grid against analytic
//    images through compare_frames; normals against the exact sphere normal.
// 3. Images independent of the thread count, for the reference and raymarch.

#include <gtest/gtest.h>


#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>
#include <limits>
#include <optional>
#include <random>
#include <vector>

#include "cache/brick_cache.h"
#include "session/grid_cache.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/grid_walk.h"
#include "renderers/common/metrics.h"
#include "session/render_session.h"
#include "renderers/common/shading.h"
#include "test_util.h"

namespace brickyard {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// --- cell_accessor.h: trilinear interpolation ----------------------------------------

TEST(Trilinear, IsTheCornerWeightedSumAndItsGradientTheSumsDerivative) {
  // The definition: each corner weighted by the product over the axes of u (upper corner) or
  // 1 - u (lower), and the gradient that sum's derivative, one axis's factor replaced by +1 or
  // -1. trilinear() interpolates along the axes in turn instead; trilinear_gradient() takes
  // face differences.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> unit(0.0, 1.0), value(-1.0, 1.0);
  for (int trial = 0; trial < 2000; ++trial) {
    double c[8], u[3];
    for (double& v : c) v = value(rng);
    for (double& x : u) x = trial % 5 == 0 ? double(trial / 5 % 2) : unit(rng);  // faces too
    double want = 0, want_g[3] = {0, 0, 0};
    for (int n = 0; n < 8; ++n) {
      double w[3], dw[3];
      for (int a = 0; a < 3; ++a) {
        const bool upper = (n >> a) & 1;
        w[a] = upper ? u[a] : 1 - u[a];
        dw[a] = upper ? 1 : -1;
      }
      want += c[n] * w[0] * w[1] * w[2];
      want_g[0] += c[n] * dw[0] * w[1] * w[2];
      want_g[1] += c[n] * w[0] * dw[1] * w[2];
      want_g[2] += c[n] * w[0] * w[1] * dw[2];
    }
    ASSERT_NEAR(trilinear(c, u[0], u[1], u[2]), want, 1e-14) << "trial " << trial;
    const Vec3d g = trilinear_gradient(c, u[0], u[1], u[2]);
    for (int a = 0; a < 3; ++a) {
      ASSERT_NEAR(g[a], want_g[a], 1e-14) << "trial " << trial << " axis " << a;
    }
  }
}

TEST(Trilinear, WithGradientIsTrilinearAndItsGradientInFloatOnLargeValues) {
  // In float on u16-sized values with small differences between corners (a nearly flat cell
  // far from zero): every gradient component of the fused form stays within float rounding of
  // the cell's variation, as the separate form's does, against a double truth; the value
  // within float rounding of its size.
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> unit(0.0, 1.0), delta(-4.0, 4.0);
  double worst = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    const double base = 60000 * unit(rng);
    float c[8];
    double cd[8];
    for (int n = 0; n < 8; ++n) c[n] = float(base + (trial % 5 == 0 ? 0.0 : delta(rng))), cd[n] = double(c[n]);
    const float ux = float(unit(rng)), uy = float(unit(rng)), uz = float(unit(rng));
    Vec3f g;
    const float v = trilinear_with_gradient(c, ux, uy, uz, g);
    const double want = trilinear(cd, double(ux), double(uy), double(uz));
    const Vec3d want_g = trilinear_gradient(cd, double(ux), double(uy), double(uz));
    const Vec3f sep_g = trilinear_gradient(c, ux, uy, uz);
    double spread = 0;
    for (int n = 0; n < 8; ++n) spread = std::max(spread, std::fabs(cd[n] - cd[0]));
    ASSERT_NEAR(v, want, 4 * 0x1p-24 * (std::fabs(want) + spread)) << "trial " << trial;
    for (int a = 0; a < 3; ++a) {
      const double err = std::fabs(double(g[a]) - want_g[a]);
      ASSERT_LE(err, 1e-5 * (spread + 1e-30)) << "trial " << trial << " axis " << a << ": " << g[a] << " against " << want_g[a];
      ASSERT_LE(std::fabs(double(sep_g[a]) - want_g[a]), 1e-5 * (spread + 1e-30)) << "trial " << trial << " axis " << a;
      worst = std::max(worst, err / (spread + 1e-30));
    }
  }
  std::cout << "[ measured ] trilinear_with_gradient: worst gradient error / cell spread " << worst << "\n";
}

TEST(TrilinearSampler, LastSampleGradientIsTheGradientOfSampleWithGradient) {
  // raymarch's DVR with gradients takes a sample's gradient from the cell its value was just
  // read from (last_sample_gradient): what sample(p, gradient) gives, across brick faces, at the
  // volume's faces and outside it (clamped), in float and in double. Within 8 units of rounding
  // of the largest value (u16: 65535), not bit for bit: the compiler may contract the two call
  // sites' products into FMAs differently (it did, in double). The gradients are far larger
  // than that, and another sample's gradient is far off.
  testing::TempDir dir;
  BuildOptions o;
  o.brick_size = 8;
  auto src = make_field_source(make_field("fbm"), {21, 18, 17}, ValueType::u16);
  build_store(*src, dir.file("fbm"), o);
  Store store(dir.file("fbm"));
  CacheConfig config;
  config.l1_slots = 64;
  config.l2_bytes = 64 * store.format().bytes();
  GridCache cache_pages(store, config);
  BrickCache& cache = cache_pages.bricks();
  RayCounters counters;
  const int finest = store.layout().finest();
  TrilinearSampler<uint16_t, float> f(cache, counters, finest), f_with(cache, counters, finest);
  TrilinearSampler<uint16_t, double> d(cache, counters, finest), d_with(cache, counters, finest);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> pos(-1.5, 22.0);
  const double float_tolerance = 8 * 0x1p-24 * 65535, double_tolerance = 8 * 0x1p-53 * 65535;
  int large = 0, told_apart = 0;
  Vec3f previous(0.0f);
  for (int n = 0; n < 4000; ++n) {
    const Vec3d p(pos(rng), pos(rng) * 18 / 22, n % 7 == 0 ? 16.0 : pos(rng) * 17 / 22);
    Vec3f gf;
    const float vf = f_with.sample(Vec3f(p), gf);
    ASSERT_NEAR(f.sample(Vec3f(p)), vf, float_tolerance);
    const Vec3f lf = f.last_sample_gradient();
    Vec3d gd;
    d_with.sample(p, gd);
    d.sample(p);
    const Vec3d ld = d.last_sample_gradient();
    for (int a = 0; a < 3; ++a) {
      ASSERT_NEAR(lf[a], gf[a], float_tolerance) << "float, sample " << n << " axis " << a;
      ASSERT_NEAR(ld[a], gd[a], double_tolerance) << "double, sample " << n << " axis " << a;
    }
    large += length(Vec3d(gf)) > 100 * float_tolerance;
    told_apart += length(Vec3d(gf - previous)) > 100 * float_tolerance;
    previous = gf;
  }
  // Not vacuous: the gradients dwarf the tolerance, and the last sample's differs from the one before.
  EXPECT_GT(large, 3000);
  EXPECT_GT(told_apart, 3000);
}

// --- grid_walk.h -----------------------------------------------------------------------

struct Visit {
  int64_t cell[3];
  double ta, tb;
};

std::vector<Visit> walk(const Vec3d& o, const Vec3d& d, double t0, double t1, const Vec3s& n) {
  std::vector<Visit> out;
  walk_cells(o, d, t0, t1, n, [&](const int64_t c[3], double ta, double tb) {
    out.push_back({{c[0], c[1], c[2]}, ta, tb});
    return true;
  });
  return out;
}

/// Brute force: split [t0, t1] at every crossing of an integer plane and take the cell of each
/// piece's midpoint. Returns the pieces longer than `min_length` (in t) with their cells.
std::vector<Visit> brute_force_cells(const Vec3d& o, const Vec3d& d, double t0, double t1, const Vec3s& n, double min_length) {
  std::vector<double> ts = {t0, t1};
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) continue;
    for (int64_t k = 0; k <= n[a]; ++k) {
      const double t = (double(k) - o[a]) / d[a];
      if (t > t0 && t < t1) ts.push_back(t);
    }
  }
  std::sort(ts.begin(), ts.end());
  std::vector<Visit> out;
  for (size_t i = 0; i + 1 < ts.size(); ++i) {
    if (ts[i + 1] - ts[i] <= min_length) continue;
    const Vec3d m = o + d * (0.5 * (ts[i] + ts[i + 1]));
    Visit v{{0, 0, 0}, ts[i], ts[i + 1]};
    for (int a = 0; a < 3; ++a) v.cell[a] = std::clamp<int64_t>(int64_t(std::floor(m[a])), 0, n[a] - 1);
    out.push_back(v);
  }
  return out;
}

/// Checks one ray: the visits tile [t0, t1] in increasing t, every visited cell contains the
/// part of the ray it was visited for (zero-length visits: the point lies on the cell), and the
/// cells the ray crosses over a positive length are all visited, in order.
void check_walk(const Vec3d& o, const Vec3d& d, const Vec3s& n, const std::string& what) {
  const Interval<double> span = intersect(Rayd(o, d), Box3d(Vec3d(0.0), Vec3d(n)));
  if (span.empty()) return;
  const double t0 = std::max(span.t0, 0.0), t1 = span.t1;
  if (!(t0 <= t1)) return;
  SCOPED_TRACE(::testing::Message() << what << " o " << o << " d " << d << " n " << n << " t " << t0 << ".." << t1);
  const std::vector<Visit> visits = walk(o, d, t0, t1, n);
  ASSERT_FALSE(visits.empty());
  const double tol = 1e-9 * (1 + std::fabs(t0) + std::fabs(t1));
  EXPECT_EQ(visits.front().ta, t0);
  EXPECT_NEAR(visits.back().tb, t1, tol);
  for (size_t i = 0; i < visits.size(); ++i) {
    const Visit& v = visits[i];
    ASSERT_LE(v.ta, v.tb) << i;
    if (i > 0) {
      ASSERT_EQ(v.ta, visits[i - 1].tb) << i;
    }
    for (int a = 0; a < 3; ++a) {
      ASSERT_GE(v.cell[a], 0);
      ASSERT_LT(v.cell[a], n[a]);
    }
    // The visited piece lies in the cell (closed, with a rounding margin in space).
    for (double t : {v.ta, 0.5 * (v.ta + v.tb), v.tb}) {
      const Vec3d p = o + d * t;
      for (int a = 0; a < 3; ++a) {
        const double margin = 1e-9 * (1 + std::fabs(o[a]) + std::fabs(d[a] * t));
        ASSERT_GE(p[a], double(v.cell[a]) - margin) << "visit " << i << " axis " << a << " t " << t;
        ASSERT_LE(p[a], double(v.cell[a] + 1) + margin) << "visit " << i << " axis " << a << " t " << t;
      }
    }
  }
  // Every cell crossed over a positive length (beyond rounding) is visited, in order.
  const std::vector<Visit> expected = brute_force_cells(o, d, t0, t1, n, tol);
  std::vector<const Visit*> long_visits;
  for (const Visit& v : visits)
    if (v.tb - v.ta > tol) long_visits.push_back(&v);
  ASSERT_EQ(long_visits.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i)
    for (int a = 0; a < 3; ++a) ASSERT_EQ(long_visits[i]->cell[a], expected[i].cell[a]) << "crossing " << i;
}

TEST(GridWalk, MatchesBruteForceOnRandomRays) {
  std::mt19937_64 rng(3);
  std::uniform_int_distribution<int> size(1, 12);
  std::uniform_real_distribution<double> unit(0.0, 1.0), dir(-1.0, 1.0);
  for (int trial = 0; trial < 3000; ++trial) {
    const Vec3s n(size(rng), size(rng), size(rng));
    const Vec3d target(unit(rng) * double(n.x), unit(rng) * double(n.y), unit(rng) * double(n.z));
    Vec3d o;
    if (trial % 2) o = target + normalize(Vec3d(dir(rng), dir(rng), dir(rng))) * 30.0;  // outside
    else o = target;                                                                  // inside
    const Vec3d d = normalize(trial % 2 ? target - o : Vec3d(dir(rng), dir(rng), dir(rng)));
    ASSERT_NO_FATAL_FAILURE(check_walk(o, d, n, "random"));
  }
}

TEST(GridWalk, AxisParallelRaysAlongEdgesAndThroughCorners) {
  const Vec3s n(5, 4, 6);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int axis = 0; axis < 3; ++axis)
    for (double sign : {1.0, -1.0})
      for (int kind = 0; kind < 4; ++kind)
        for (int trial = 0; trial < 20; ++trial) {
          Vec3d d(0.0);
          d[axis] = sign;
          if (kind == 3) d[(axis + 1) % 3] = -0.0;  // negative zero components
          Vec3d o;
          for (int a = 0; a < 3; ++a) {
            const double extent = double(n[a]);
            // kind 0: anywhere; 1: on integer planes (along cell faces and edges);
            // 2: on the volume's faces; 3: cell-corner lines with -0 components.
            if (kind == 0) o[a] = unit(rng) * extent;
            else if (kind == 2) o[a] = trial % 2 ? 0.0 : extent;
            else o[a] = std::floor(unit(rng) * (extent + 1));
          }
          o[axis] = sign > 0 ? -2.0 : double(n[axis]) + 2;
          ASSERT_NO_FATAL_FAILURE(check_walk(o, d, n, "axis-parallel"));
        }
}

TEST(GridWalk, DiagonalRaysThroughCellCorners) {
  // Rays through lattice points along (±1, ±1, ±1), (1, 1, 0) and (1, 2, 0): they pass
  // exactly through cell corners and along cell edges; ties between axes must not skip cells.
  const Vec3s n(8, 8, 8);
  const std::vector<Vec3d> dirs = {{1, 1, 1}, {-1, 1, 1}, {1, -1, -1}, {-1, -1, -1}, {1, 1, 0},
                                   {1, 0, -1}, {1, 2, 0}, {2, 1, 1}, {0, -1, 1}, {3, 1, 2}};
  for (const Vec3d& raw : dirs)
    for (int start = 0; start <= 8; ++start) {
      const Vec3d d = normalize(raw);
      const Vec3d p(double(start), double(8 - start) * 0.5, 4.0);  // a lattice or half-lattice point
      ASSERT_NO_FATAL_FAILURE(check_walk(p - d * 20.0, d, n, "diagonal"));
      ASSERT_NO_FATAL_FAILURE(check_walk(p, d, n, "diagonal from inside"));
      // The unnormalised direction keeps the components exactly equal.
      ASSERT_NO_FATAL_FAILURE(check_walk(p - raw * 20.0, raw, n, "diagonal, exact direction"));
    }
}

TEST(GridWalk, SubIntervalsAndEarlyStop) {
  const Vec3s n(10, 10, 10);
  const Vec3d o(-1, 2.5, 3.25), d(1, 0.1, 0.05);
  // [t0, t1] inside the grid: the walk starts in the cell holding o + d t0 and stops at t1.
  const auto v = walk(o, d, 3.5, 7.25, n);
  ASSERT_FALSE(v.empty());
  EXPECT_EQ(v.front().cell[0], 2);
  EXPECT_EQ(v.front().ta, 3.5);
  EXPECT_EQ(v.back().tb, 7.25);
  EXPECT_EQ(v.back().cell[0], 6);
  // Stopping early.
  int calls = 0;
  walk_cells(o, d, 1.0, 11.0, n, [&](const int64_t*, double, double) { return ++calls < 3; });
  EXPECT_EQ(calls, 3);
  // An empty interval visits nothing; a point visits one cell with ta = tb.
  EXPECT_TRUE(walk(o, d, 5.0, 4.0, n).empty());
  EXPECT_TRUE(walk(o, d, std::nan(""), 4.0, n).empty());
  const auto point = walk(o, d, 4.0, 4.0, n);
  ASSERT_EQ(point.size(), 1u);
  EXPECT_EQ(point[0].ta, point[0].tb);
}

// --- the sphere: closed form against the reference ----------------------------------------

struct SphereSpec {
  double radius, cx, cy, cz;
};

/// First intersection t > 0 of the ray o + t d (|d| = 1) with the sphere, or +inf.
double ray_sphere(const Vec3d& o, const Vec3d& d, const SphereSpec& s) {
  const Vec3d oc = o - Vec3d(s.cx, s.cy, s.cz);
  const double b = dot(oc, d), c = dot(oc, oc) - s.radius * s.radius;
  const double disc = b * b - c;
  if (disc < 0) return kInf;
  // Cancellation-free: q is the far root (for rays from outside, b < 0), c / q the near one.
  const double q = -b + std::sqrt(disc);
  const double near = c / q;
  return near > 0 ? near : (q > 0 ? q : kInf);
}

RenderSession::Options analytic_mode() {
  RenderSession::Options o;
  o.params["analytic"] = 1.0;
  return o;
}

Scene sphere_scene(const std::string& dataset, const std::string& backend, const Camera& cam, int size) {
  Scene s;
  s.dataset = dataset;
  s.backend = backend;
  s.camera.keyframes = {cam};
  s.camera.frames = 1;
  s.width = s.height = s.camera.width = s.camera.height = size;
  s.mode = RenderMode::iso;
  s.isosurfaces = {Isosurface{0.0, Vec3f(0.8f, 0.7f, 0.6f)}};
  s.cache.l1_bytes = uint64_t(32) << 20;
  s.cache.l2_bytes = uint64_t(32) << 20;
  return s;
}

/// A sphere SDF store, f32 at the finest level, bricks of 8.
void build_sphere(const std::string& dir, const SphereSpec& s, int64_t n) {
  BuildOptions o;
  o.brick_size = 8;
  auto src = make_field_source(make_field("sphere", {{"radius", s.radius}, {"cx", s.cx}, {"cy", s.cy}, {"cz", s.cz}}),
                               {n, n, n}, ValueType::f32);
  build_store(*src, dir, o);
}

/// Per-pixel comparison of a reference frame with the closed form. The trilinear interpolant I
/// of a sampled SDF f obeys f <= I <= f + h^2 / (4 r) (f is convex, so I >= f by Jensen; the
/// quadratic error term is (h^2 / 2) sum_a H_aa u_a (1 - u_a) <= h^2 trace(H) / 8, with
/// trace(H) = 2 / r), so the grid surface lies inside the sphere by at most h^2 / (4R) world
/// units: 1 / (4 R_vox) voxels along the normal, that over cos(theta) along the ray. Its
/// gradient is off by at most H_aa h / 2 per component, an angle of at most 1 / (sqrt(2) R_vox).
struct SphereErrors {
  double depth_max = 0, depth_min_signed = kInf, depth_mean = 0;  // voxels, grid - exact
  double bound_ratio_max = 0;  // largest error over its per-pixel bound
  double normal_max_deg = 0, normal_mean_deg = 0;
  int pixels = 0, misses = 0, extra_hits = 0;
};

SphereErrors measure_sphere(RenderSession& session, const FrameBuffers& fb, const SphereSpec& s, double margin,
                            double min_cos) {
  const Camera cam = session.camera(0);
  const VolumeGeometry& geo = session.context().geometry();
  const double h = geo.voxel_size;
  const double r_vox = s.radius / h;
  const Vec3d c(s.cx, s.cy, s.cz);
  const Box3d inner(geo.world.lo + Vec3d(margin), geo.world.hi - Vec3d(margin));
  SphereErrors e;
  double depth_sum = 0, normal_sum = 0;
  for (int y = 0; y < fb.height(); ++y)
    for (int x = 0; x < fb.width(); ++x) {
      const Rayd ray = cam.ray(x + 0.5, y + 0.5, fb.width(), fb.height());
      const double t = ray_sphere(ray.org, ray.dir, s);
      const float depth = fb.depth(x, y);
      if (t == kInf || !inner.contains(ray.at(t))) {
        // No hit well inside the volume: the reference may hit only near the volume's faces.
        if (std::isfinite(depth) && inner.contains(ray.at(depth)) && t == kInf) ++e.extra_hits;
        continue;
      }
      const Vec3d n = normalize(ray.at(t) - c);
      const double cos_theta = std::fabs(dot(n, ray.dir));
      if (cos_theta < min_cos) continue;
      if (!std::isfinite(depth)) {
        ++e.misses;
        continue;
      }
      ++e.pixels;
      const double err = (double(depth) - t) / h;
      e.depth_max = std::max(e.depth_max, std::fabs(err));
      e.depth_min_signed = std::min(e.depth_min_signed, err);
      depth_sum += std::fabs(err);
      // The bound at the smallest distance from the centre a cell near the surface reaches
      // (R less a cell diagonal), plus float depth rounding (a few ulps of the distance).
      const double bound = 1.0 / (4 * (r_vox - std::sqrt(3.0)) * cos_theta) + 1e-6 * t / h;
      e.bound_ratio_max = std::max(e.bound_ratio_max, std::fabs(err) / bound);
      const Vec3d got(fb.normal(x, y));
      const double angle = std::acos(std::clamp(dot(normalize(got), n), -1.0, 1.0)) * 180 / kPi;
      e.normal_max_deg = std::max(e.normal_max_deg, angle);
      normal_sum += angle;
    }
  if (e.pixels) e.depth_mean = depth_sum / e.pixels, e.normal_mean_deg = normal_sum / e.pixels;
  return e;
}

/// A cap of a large sphere (R = 16 world units, 512 voxels) across a 33^3 grid (h = 1/32):
/// the interpolation error bound 1/(4 R_vox) = 4.9e-4 voxel is below the 1e-3 voxel target. A
/// whole sphere would need R_vox >= 250, a 512^3 grid (512 MiB of f32), for the same bound.
class SphereReference : public ::testing::Test {
 protected:
  static constexpr SphereSpec kCap{16.0, 0.45, 0.55, 0.5 - 16.0};
  static constexpr int64_t kCapN = 33;
  static constexpr SphereSpec kBall{0.35, 0.5, 0.5, 0.5};
  static constexpr int64_t kBallN = 65;

  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    build_sphere(dir_->file("cap"), kCap, kCapN);
    build_sphere(dir_->file("ball"), kBall, kBallN);
  }
  static void TearDownTestSuite() { delete dir_; }

  static Camera cap_camera() {
    Camera cam;
    cam.eye = Vec3d(0.52, 0.47, 1.7);
    cam.target = Vec3d(0.5, 0.5, 0.45);
    cam.up = Vec3d(0, 1, 0);
    cam.fov_degrees = 40;
    return cam;
  }
  static Camera ball_camera() {
    Camera cam;
    cam.eye = Vec3d(1.5, -0.8, 1.1);
    cam.target = Vec3d(0.5, 0.5, 0.5);
    cam.fov_degrees = 30;
    return cam;
  }
  static testing::TempDir* dir_;
};
testing::TempDir* SphereReference::dir_ = nullptr;

TEST_F(SphereReference, GridIsosurfaceOfALargeSphereIsWithin1e3VoxelOfTheClosedForm) {
  RenderSession session(sphere_scene(dir_->file("cap"), "reference", cap_camera(), 64));
  FrameBuffers fb;
  session.render(0, fb, FrameOutputs{.depth = true, .normals = true});
  const double h = session.context().geometry().voxel_size;
  ASSERT_DOUBLE_EQ(h, 1.0 / 32);
  const SphereErrors e = measure_sphere(session, fb, kCap, h, 0.0);
  const double bound = 1.0 / (4 * kCap.radius / h);
  std::cout << "[ measured ] sphere cap R = 16 (" << kCap.radius / h << " voxels), grid " << kCapN
            << "^3 f32, h = 1/32: depth error vs closed form max " << e.depth_max << " voxel, mean " << e.depth_mean
            << ", most negative " << e.depth_min_signed << " (bound 1/(4 R_vox) = " << bound << " / cos); normal max "
            << e.normal_max_deg << " deg, mean " << e.normal_mean_deg << " deg (bound "
            << 180 / kPi / (std::sqrt(2.0) * kCap.radius / h) << "); pixels " << e.pixels << "\n";
  EXPECT_GT(e.pixels, 2500);
  EXPECT_EQ(e.misses, 0);
  EXPECT_EQ(e.extra_hits, 0);
  EXPECT_LT(e.depth_max, 1e-3);
  EXPECT_LE(e.bound_ratio_max, 1.0);
  EXPECT_GT(e.depth_min_signed, -1e-5);  // the grid surface never lies outside the sphere
  EXPECT_LT(e.normal_max_deg, 180 / kPi / (std::sqrt(2.0) * (kCap.radius / h - std::sqrt(3.0))) + 1e-3);
}

TEST_F(SphereReference, GridIsosurfaceOfASmallSphereObeysTheInterpolationBound) {
  // R = 0.35 on 65^3: R_vox = 22.4, bound 1/(4 R_vox) = 0.011 voxel / cos(theta). Rays more
  // grazing than 60 degrees from the normal are left out (the bound grows as 1/cos).
  RenderSession session(sphere_scene(dir_->file("ball"), "reference", ball_camera(), 64));
  FrameBuffers fb;
  session.render(0, fb, FrameOutputs{.depth = true, .normals = true});
  const double h = session.context().geometry().voxel_size;
  const SphereErrors e = measure_sphere(session, fb, kBall, 0.0, 0.5);
  std::cout << "[ measured ] sphere R = 0.35 (" << kBall.radius / h << " voxels), grid " << kBallN
            << "^3 f32: depth error max " << e.depth_max << " voxel (bound ratio " << e.bound_ratio_max << "), mean "
            << e.depth_mean << "; normal max " << e.normal_max_deg << " deg, mean " << e.normal_mean_deg
            << " deg; pixels " << e.pixels << "\n";
  EXPECT_GT(e.pixels, 1000);
  EXPECT_EQ(e.misses, 0);
  EXPECT_LE(e.bound_ratio_max, 1.0);
  EXPECT_GT(e.depth_min_signed, -1e-5);
  EXPECT_GT(e.depth_max, 0.5 / (4 * kBall.radius / h));  // the error has the predicted size, not less
  EXPECT_LT(e.normal_max_deg, 180 / kPi / (std::sqrt(2.0) * (kBall.radius / h - std::sqrt(3.0))) + 1e-3);
}

TEST_F(SphereReference, AnalyticModeMatchesTheClosedFormTightly) {
  for (const char* name : {"cap", "ball"}) {
    const bool cap = std::string(name) == "cap";
    const SphereSpec s = cap ? kCap : kBall;
    RenderSession session(sphere_scene(dir_->file(name), "reference", cap ? cap_camera() : ball_camera(), 48),
                          analytic_mode());
    FrameBuffers fb;
    session.render(0, fb, FrameOutputs{.depth = true, .normals = true});
    const double h = session.context().geometry().voxel_size;
    const SphereErrors e = measure_sphere(session, fb, s, cap ? h : 0.0, cap ? 0.0 : 0.2);
    std::cout << "[ measured ] analytic reference, " << name << ": depth error max " << e.depth_max
              << " voxel, normal max " << e.normal_max_deg << " deg, pixels " << e.pixels << "\n";
    EXPECT_GT(e.pixels, 800) << name;
    EXPECT_EQ(e.misses, 0) << name;
    EXPECT_LT(e.depth_max, 1e-4) << name;
    EXPECT_LT(e.normal_max_deg, 1e-3) << name;
  }
}

TEST_F(SphereReference, GridAndAnalyticImagesAgree) {
  // The same view in grid and analytic mode, lit by the headlight, compared with compare_frames.
  // Tolerances: for the cap, depth within the interpolation bound (< 1e-3 voxel) everywhere both
  // hit, normals within 0.1 degree, coverage identical, colour RMSE below 1e-3; for the small
  // sphere the bound is 0.011 voxel / cos(theta), large at the silhouette: depth mean < 0.03
  // voxel and p99 < 0.25 voxel, normals within 2 degrees (p99), at most 0.5% of the pixels
  // differing in coverage, colour RMSE below 0.01.
  struct Case {
    const char* name;
    Camera cam;
    double depth_mean, depth_p99, normal_p99, coverage, rmse;
  };
  for (const Case& c : {Case{"cap", cap_camera(), 1e-3, 1e-3, 0.1, 0.0, 1e-3},
                        Case{"ball", ball_camera(), 0.03, 0.25, 2.0, 0.005, 0.01}}) {
    const Scene scene = sphere_scene(dir_->file(c.name), "reference", c.cam, 64);
    FrameBuffers grid, analytic;
    RenderSession g(scene);
    g.render(0, grid, FrameOutputs{.depth = true, .normals = true});
    RenderSession a(scene, analytic_mode());
    a.render(0, analytic, FrameOutputs{.depth = true, .normals = true});
    const ImageError e = compare_frames(grid, analytic, g.context().geometry().voxel_size);
    std::cout << "[ measured ] grid vs analytic reference, " << c.name << ": " << e.to_json() << "\n";
    EXPECT_GT(e.depth_pixels, 1000u) << c.name;
    EXPECT_LT(e.depth_mean, c.depth_mean) << c.name;
    if (std::string(c.name) == "cap") {
      EXPECT_LT(e.depth_max, 1e-3);
    }
    EXPECT_LT(e.depth_p99, c.depth_p99) << c.name;
    EXPECT_LT(e.normal_p99_deg, c.normal_p99) << c.name;
    EXPECT_LE(e.coverage_mismatch_fraction, c.coverage) << c.name;
    EXPECT_LT(e.rmse, c.rmse) << c.name;
    EXPECT_EQ(e.nonfinite_color_pixels, 0u) << c.name;
  }
}

// --- thread-count independence ---------------------------------------------------------


TEST(ShadingModel, LightingIsAveragedBeforeItIsApplied) {
  // apply() is affine in the lighting, so the mean of two points'
  // lighting, applied, is the mean of their shaded colours (below the clamp at 1), which is
  // how a ray segment is shaded from both its ends. Shadowed: the ambient term alone.
  Shading sh;
  const VolumeGeometry geo;
  const ShadingModel m(sh, geo);
  std::mt19937 rng(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<float> unit(0.0f, 0.5f);
  const auto direction = [&] { return normalize(Vec3d(normal(rng), normal(rng), normal(rng))); };
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3d n0 = direction(), n1 = direction(), view = direction(), light = trial % 2 ? view : direction();
    const Vec3f base(unit(rng), unit(rng), unit(rng));
    const ShadingModel::Lighting l0 = m.lighting(n0, view, light, false), l1 = m.lighting(n1, view, light, false);
    const Vec3f s0 = m.shade(base, n0, view, light, false), s1 = m.shade(base, n1, view, light, false);
    const Vec3f mean = m.apply(base, l0.mix(l1, 0.5f));
    for (int c = 0; c < 3; ++c) {
      ASSERT_NEAR(mean[c], 0.5f * (s0[c] + s1[c]), 1e-6f) << trial;
      ASSERT_FLOAT_EQ(m.shade(base, n0, view, light, true)[c], base[c] * sh.ambient) << trial;
    }
  }
}

TEST(ShadingModel, LightingOfAGradientIsTheLightingOfItsUnitNormalEitherWay) {
  // gigavoxels lights a sample from its gradient without forming the unit normal: |n.l| and
  // |n.h| do not depend on the normal's length, once divided out, nor on which way it faces.
  Shading sh;
  sh.light = LightKind::headlight;
  sh.shininess = 24;
  const VolumeGeometry geo;
  const ShadingModel model(sh, geo);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> coord(-1.0, 1.0), scale(-30.0, 30.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const Vec3d g = Vec3d(coord(rng), coord(rng), coord(rng)) * std::exp2(scale(rng));
    const Vec3d light = normalize(Vec3d(coord(rng), coord(rng), coord(rng)) + Vec3d(0, 0, 2));
    const Vec3d half = ShadingModel::half_vector(normalize(Vec3d(coord(rng), coord(rng), 1.5)), light);
    const double inv = 1 / length(g);
    for (const double side : {1.0, -1.0}) {
      const ShadingModel::Lighting want = model.lighting_with_half(g * (side * inv), light, half, false);
      const ShadingModel::Lighting got = model.lighting_of_gradient(g * side, inv, light, half);
      ASSERT_NEAR(got.diffuse, want.diffuse, 1e-6f) << "trial " << trial;
      ASSERT_NEAR(got.specular, want.specular, 1e-6f) << "trial " << trial;
    }
  }
}

TEST(ShadingModel, TheLightIsFixedAlongARayExactlyWhenItsDirectionIsTheSameAtEveryDistance) {
  // A back end computes the light's direction and half vector once per ray only where
  // light_fixed_along_rays() says every t > 0 gives the same direction.
  VolumeGeometry geo;
  geo.world = Box3d(Vec3d(0.0), Vec3d(2.0));
  const Rayd ray(Vec3d(0.3, -2.0, 0.7), normalize(Vec3d(0.2, 1.0, -0.1)));
  for (LightKind kind : {LightKind::headlight, LightKind::directional, LightKind::point}) {
    Shading sh;
    sh.light = kind;
    sh.light_direction = Vec3d(1, 0.3, -0.5);
    sh.light_position = Vec3d(0.9, 0.4, 0.2);
    const ShadingModel m(sh, geo);
    double distance;
    const Vec3d first = m.to_light_along(ray, 0.25, distance);
    bool same = true;
    for (double t : {0.5, 1.0, 3.0, 40.0}) {
      const Vec3d l = m.to_light_along(ray, t, distance);
      same &= l.x == first.x && l.y == first.y && l.z == first.z;
    }
    EXPECT_EQ(m.light_fixed_along_rays(), same) << int(kind);
    const Vec3d n = normalize(Vec3d(0.3, -0.8, 0.5)), view = -ray.dir;
    const ShadingModel::Lighting a = m.lighting(n, view, first, false);
    const ShadingModel::Lighting b = m.lighting_with_half(n, first, ShadingModel::half_vector(view, first), false);
    EXPECT_EQ(a.diffuse, b.diffuse);
    EXPECT_EQ(a.specular, b.specular);
  }
}

}  // namespace
}  // namespace brickyard
