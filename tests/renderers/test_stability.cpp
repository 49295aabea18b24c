// Numerical stability of every registered back end (the shared suite: tests/renderers/
// shared_suite.h) on degenerate input: rays
// parallel to the axes, through cell corners and along cell edges; rays tangent to an
// isosurface; isovalues equal to voxel values and constant cells at the isovalue; cameras
// inside the volume and on its faces; volumes one or two voxels thick; values from 1e-30 to
// 1e30; transfer functions transparent or opaque everywhere. Every frame must be finite
// (no NaN or infinity in colour, normals unit or zero, depth a distance or +infinity), and
// the images must make sense: isosurface depths are checked against the exact crossing of the
// trilinear interpolant, which is known in closed form for the fields used here (sums of
// per-axis functions, so the interpolant is piecewise linear along any ray).
//
// Volumes come from in-memory arrays (ArraySource, array_scene.h) with unit spacing and origin 0, so
// world, voxel and camera coordinates coincide; frames are rendered with world-space cameras
// (RenderSession::render of a FrameSetup), which also reaches volumes whose box is flat
// (normalised camera coordinates cannot place a camera beside a volume of zero extent). Scenes
// ask for the finest level (quality.lod_ratio 0.01): the expectations are those of full
// resolution. The reference must find every crossing exactly; every other back end is held to
// what a marcher with its step is bound to see (SeparableField::marcher_must_hit).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <iostream>
#include <limits>
#include <random>
#include <sstream>
#include <span>
#include <string>
#include <vector>

#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "session/grid_cache.h"
#include "preprocess/volume_source.h"
#include "session/render_session.h"
#include "array_scene.h"
#include "shared_suite.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
using testing::backends_for;
using testing::build_array;
using testing::expect_sane;
using testing::look;
using testing::make_scene;
using testing::render_world;
using testing::Rendered;
constexpr RenderMode kModes[] = {RenderMode::iso, RenderMode::dvr, RenderMode::mip};

/// A field that is a sum of per-axis functions of the lattice index: its trilinear interpolant
/// is the sum of the per-axis linear interpolants, exact and piecewise linear along any ray,
/// with kinks only where the ray crosses an integer plane.
struct SeparableField {
  Vec3s dims;
  std::function<double(int axis, int64_t i)> phi;

  std::vector<float> values() const {
    std::vector<float> v;
    v.reserve(size_t(volume(dims)));
    for (int64_t z = 0; z < dims.z; ++z)
      for (int64_t y = 0; y < dims.y; ++y)
        for (int64_t x = 0; x < dims.x; ++x) v.push_back(float(phi(0, x) + phi(1, y) + phi(2, z)));
    return v;
  }
  /// The interpolant at p (clamped into the volume).
  double at(const Vec3d& p) const {
    double v = 0;
    for (int a = 0; a < 3; ++a) {
      const double x = std::clamp(p[a], 0.0, double(dims[a] - 1));
      const int64_t i = std::min<int64_t>(int64_t(std::floor(x)), std::max<int64_t>(dims[a] - 2, 0));
      const double lo = phi(a, i), hi = dims[a] > 1 ? phi(a, i + 1) : lo;
      v += lo + (hi - lo) * (x - double(i));
    }
    return v;
  }
  /// The largest change of the interpolant over one voxel along any axis, summed over axes.
  double max_slope() const {
    double sum = 0;
    for (int a = 0; a < 3; ++a) {
      double m = 0;
      for (int64_t i = 0; i + 1 < dims[a]; ++i) m = std::max(m, std::fabs(phi(a, i + 1) - phi(a, i)));
      sum += m;
    }
    return sum;
  }
  /// Whether a marcher sampling every `step` must see the first crossing in [t0, t1]: after it,
  /// the interpolant stays on the far side of the isovalue (or on it) for two steps inside
  /// [t0, t1]. Tangent touches, slivers thinner than two steps and crossings within two steps
  /// of the ray's exit are not required.
  bool marcher_must_hit(const Vec3d& o, const Vec3d& d, double t0, double t1, double iso, double tol, double step) const {
    const double t = first_hit(o, d, t0, t1, iso, tol);
    if (!(t + 2 * step <= t1)) return false;
    auto sign = [&](double u) {
      const double v = at(o + d * u) - iso;
      return std::fabs(v) <= tol ? 0 : (v < 0 ? -1 : 1);
    };
    const int before = t > t0 ? sign(t0) : 0;
    for (double k : knots(o, d, t, t + 2 * step)) {
      if (k == t) continue;
      if (before == 0 ? sign(k) != 0 : sign(k) == before) return false;
    }
    return true;
  }
  /// t0, t1 and every crossing of an integer plane between them, sorted.
  std::vector<double> knots(const Vec3d& o, const Vec3d& d, double t0, double t1) const {
    std::vector<double> ts = {t0, t1};
    for (int a = 0; a < 3; ++a) {
      if (d[a] == 0) continue;
      for (int64_t k = 0; k < dims[a]; ++k) {
        const double t = (double(k) - o[a]) / d[a];
        if (t > t0 && t < t1) ts.push_back(t);
      }
    }
    std::sort(ts.begin(), ts.end());
    return ts;
  }
  /// The first t in [t0, t1] where the interpolant equals iso (crossing or touch, |g| <= tol),
  /// or +inf.
  double first_hit(const Vec3d& o, const Vec3d& d, double t0, double t1, double iso, double tol) const {
    if (!(t0 <= t1)) return kInf;
    const std::vector<double> ts = knots(o, d, t0, t1);
    auto g = [&](double t) {
      const double v = at(o + d * t) - iso;
      return std::fabs(v) <= tol ? 0.0 : v;
    };
    double ta = ts[0], ga = g(ta);
    if (ga == 0) return ta;
    for (size_t i = 1; i < ts.size(); ++i) {
      const double tb = ts[i], gb = g(tb);
      if (gb == 0) return tb;
      if ((ga < 0) != (gb < 0)) return ta + (tb - ta) * ga / (ga - gb);
      ta = tb, ga = gb;
    }
    return kInf;
  }
};

/// Compares an iso frame with the exact crossings of a separable field. The reference must
/// agree everywhere: the same pixels hit (touching included), depths within rounding. Raymarch,
/// which samples every `step` voxels, must hit every pixel whose crossing it is bound to sample
/// (SeparableField::marcher_must_hit), within `march_tol` after the exact crossing or the
/// bisection's error before it, and any hit it reports must lie on the surface.
void expect_iso_matches(const Rendered& r, const std::string& backend, const SeparableField& f, double iso,
                        double value_scale, double march_tol, const std::string& what) {
  const bool reference = backend == "reference";
  const double step = 0.5;  // raymarch's default, in voxels (= world units here)
  int mismatch = 0;
  double depth_max = 0;
  for (int y = 0; y < r.fb.height(); ++y)
    for (int x = 0; x < r.fb.width(); ++x) {
      const Rayd ray = r.camera.ray(x + 0.5, y + 0.5, r.fb.width(), r.fb.height());
      Interval<double> span = intersect(ray, r.world);
      span.t0 = std::max(span.t0, 0.0);
      const double t = span.empty() ? kInf : f.first_hit(ray.org, ray.dir, span.t0, span.t1, iso, 1e-12 * value_scale);
      const double depth = r.fb.depth(x, y);
      if (reference) {
        if (std::isfinite(t) != std::isfinite(depth)) {
          ++mismatch;
          ADD_FAILURE() << what << ": pixel " << x << " " << y << " exact " << t << " reference " << depth;
        } else if (std::isfinite(t)) {
          depth_max = std::max(depth_max, std::fabs(depth - t));
        }
        continue;
      }
      const bool must_hit = !span.empty() && f.marcher_must_hit(ray.org, ray.dir, span.t0, span.t1, iso, 1e-12 * value_scale, step);
      if (std::isfinite(depth)) {
        // Any hit lies on the surface, up to the bisection's and float's errors.
        EXPECT_LE(std::fabs(f.at(ray.at(depth)) - iso), f.max_slope() * march_tol + 1e-6 * value_scale)
            << what << ": pixel " << x << " " << y << " depth " << depth << " exact " << t;
        // Six bisection steps leave a bracket step / 2^6 wide around a crossing, and the hit
        // returned lies in it.
        if (std::isfinite(t)) {
          EXPECT_GE(depth, t - step / 64 - 1e-6) << what << ": pixel " << x << " " << y;
        }
        if (must_hit) {
          EXPECT_LE(depth, t + march_tol) << what << ": pixel " << x << " " << y;
        }
      } else if (must_hit) {
        ++mismatch;
        ADD_FAILURE() << what << ": pixel " << x << " " << y << " missed by raymarch; exact " << t;
      }
    }
  if (reference) {
    EXPECT_LT(depth_max, 1e-5 * (1 + length(r.camera.eye))) << what;
  }
  EXPECT_EQ(mismatch, 0) << what;
}

std::string fmt_what(const std::string& backend, RenderMode mode, const Vec3d& eye) {
  std::ostringstream s;
  s << backend << " " << to_string(mode) << " eye " << eye;
  return s.str();
}

/// The central pixel of an odd-sized image looks exactly along target - eye.
int centre(const Scene& s) { return s.width / 2; }

// The octahedron |x - 4| + |y - 4| + |z - 4| on 9^3: trilinear-exact, with kinks on lattice
// planes. Isovalue 2 passes through lattice points (equal to voxel values), 2.5 between them.
SeparableField octahedron() {
  return {{9, 9, 9}, [](int, int64_t i) { return std::fabs(double(i) - 4); }};
}

class Stability : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    octa_ = build_array(*dir_, "octa", {9, 9, 9}, octahedron().values());
  }
  static void TearDownTestSuite() { delete dir_; }
  static testing::TempDir* dir_;
  static std::string octa_;
};
testing::TempDir* Stability::dir_ = nullptr;
std::string Stability::octa_;

TEST_F(Stability, AxisParallelRaysAlongCellEdgesAndThroughCorners) {
  // Cameras on the six axis directions and two diagonals, each looking through lattice points,
  // so the central ray runs along a cell edge (or through cell corners) and its row and column
  // have one zero direction component; odd image sizes put a pixel centre on the axis.
  const SeparableField f = octahedron();
  struct View {
    Vec3d eye, target, up;
  };
  const std::vector<View> views = {
      {{3, 4, 20}, {3, 4, 0}, {0, 1, 0}},  {{3, 4, -12}, {3, 4, 8}, {0, 1, 0}}, {{20, 3, 5}, {0, 3, 5}, {0, 0, 1}},
      {{-12, 4, 4}, {8, 4, 4}, {0, 0, 1}}, {{5, 20, 3}, {5, 0, 3}, {1, 0, 0}},  {{4, -12, 4}, {4, 8, 4}, {0, 0, 1}},
      {{-6, -6, -6}, {4, 4, 4}, {0, 0, 1}}, {{14, -4, 13}, {5, 5, 4}, {0, 0, 1}}};
  for (RenderMode mode : kModes)
    for (const std::string& backend : backends_for(mode))
      for (const View& v : views) {
        Scene s = make_scene(octa_, backend, mode, 15);
        s.isosurfaces = {Isosurface{2.5}};
        s.transfer_function = TransferFunction({{0.0, Vec3f(1.0f), 0.4f}, {3.0, Vec3f(0.5f), 0.05f}, {12, Vec3f(0.0f), 0.0f}});
        const Rendered r = render_world(s, look(v.eye, v.target, v.up));
        const std::string what = fmt_what(backend, mode, v.eye);
        const int covered = expect_sane(r.fb, what);
        EXPECT_GT(covered, 0) << what;
        if (mode != RenderMode::iso) continue;
        for (double iso : {2.5, 2.0}) {
          Scene si = s;
          si.isosurfaces = {Isosurface{iso}};
          const Rendered ri = iso == 2.5 ? r : render_world(si, r.camera);
          expect_sane(ri.fb, what);
          expect_iso_matches(ri, backend, f, iso, 12, 0.05, what + " iso " + std::to_string(iso));
          // The central ray, along a cell edge through cell corners: its exact depth.
          const Rayd ray = r.camera.ray(centre(s) + 0.5, centre(s) + 0.5, s.width, s.height);
          const Interval<double> span = intersect(ray, r.world);
          const double t = f.first_hit(ray.org, ray.dir, std::max(span.t0, 0.0), span.t1, iso, 1e-11);
          ASSERT_TRUE(std::isfinite(t)) << what;
          // (Raymarch cannot see a surface the ray only touches: isovalue 2 touches at lattice points.)
          if (backend == "reference" || f.marcher_must_hit(ray.org, ray.dir, std::max(span.t0, 0.0), span.t1, iso, 1e-11, 0.5)) {
            EXPECT_NEAR(ri.fb.depth(centre(s), centre(s)), t, backend == "reference" ? 1e-5 : 0.05) << what;
          }
        }
      }
}

TEST_F(Stability, RaysTangentToAnIsosurfaceAreFoundByTheReference) {
  // (a) f = z, isovalue 3: rays in the plane z = 3 touch the isosurface all along (the central
  // ray along x, and along the diagonal through cell corners). The reference must report the hit
  // where the ray enters the volume.
  const SeparableField plane{{9, 9, 9}, [](int a, int64_t i) { return a == 2 ? double(i) : 0.0; }};
  const std::string planar = build_array(*dir_, "plane", plane.dims, plane.values());
  for (const std::string& backend : backends_for(RenderMode::iso))
    for (const auto& [eye, target] : {std::pair{Vec3d(-5, 4, 3), Vec3d(4, 4, 3)}, std::pair{Vec3d(-4, -3, 3), Vec3d(4, 5, 3)},
                                      std::pair{Vec3d(13, 12, 3), Vec3d(0, -1, 3)}}) {
      Scene s = make_scene(planar, backend, RenderMode::iso, 15);
      s.isosurfaces = {Isosurface{3.0}};
      const Rendered r = render_world(s, look(eye, target));
      const std::string what = fmt_what(backend, RenderMode::iso, eye);
      expect_sane(r.fb, what);
      expect_iso_matches(r, backend, plane, 3.0, 8, 0.5, what);
      const Rayd ray = r.camera.ray(7.5, 7.5, 15, 15);
      const double entry = intersect(ray, r.world).t0;
      const double depth = r.fb.depth(7, 7);
      if (backend == "reference") {
        EXPECT_NEAR(depth, entry, 1e-5) << what;
      } else {
        EXPECT_GE(depth, entry - 1e-5) << what;
        EXPECT_LE(depth, entry + 1.0) << what;
      }
    }

  // (b) A saddle cell, f = 1 - x - y + 2xy on 2x2x2: along the diagonal (t, t, 1/2),
  // f - 1/2 = 2 (t - 1/2)^2 touches zero at the cell's centre. The reference must find it.
  std::vector<float> saddle(8);
  for (int n = 0; n < 8; ++n) {
    const double x = n & 1, y = (n >> 1) & 1;
    saddle[size_t(n)] = float(1 - x - y + 2 * x * y);
  }
  const std::string ds = build_array(*dir_, "saddle", {2, 2, 2}, saddle);
  for (const std::string& backend : backends_for(RenderMode::iso)) {
    Scene s = make_scene(ds, backend, RenderMode::iso, 15);
    s.isosurfaces = {Isosurface{0.5}};
    const Rendered r = render_world(s, look({-1, -1, 0.5}, {1, 1, 0.5}));
    expect_sane(r.fb, backend);
    const double depth = r.fb.depth(7, 7);
    if (backend == "reference") {
      EXPECT_NEAR(depth, 1.5 * std::sqrt(2.0), 1e-6);
    } else if (std::isfinite(depth)) {  // raymarch may step over a tangent touch
      EXPECT_NEAR(depth, 1.5 * std::sqrt(2.0), 0.5);
    }
  }
}

TEST_F(Stability, IsovaluesEqualToVoxelValuesAndConstantCellsAtTheIsovalue) {
  // f = min(z, 8) on 17^3 with 8^3 bricks: every voxel value an integer, and the bricks above
  // z = 8 constant at 8 (stored without payload). Isovalue 8 makes them solid from their first
  // point on; 5 and 3 lie exactly on lattice planes.
  const SeparableField f{{17, 17, 17}, [](int a, int64_t i) { return a == 2 ? double(std::min<int64_t>(i, 8)) : 0.0; }};
  const std::string ds = build_array(*dir_, "plateau", f.dims, f.values());
  {
    Store store(ds);
    const GridLayout& l = store.layout();
    int constant_at_iso = 0;
    for (int64_t i = 0; i < l.brick_count(l.finest()); ++i) {
      const NodeRecord& n = store.nodes().at(l.key_at(l.finest(), i));
      constant_at_iso += n.is_constant() && n.constant == 8.0f;
    }
    EXPECT_GT(constant_at_iso, 4);
  }
  const std::vector<std::pair<Vec3d, Vec3d>> views = {
      {{8.5, 7.5, 30}, {8, 8, 0}}, {{8, 8.5, -14}, {8.5, 8, 16}}, {{30, -6, 20}, {8, 8, 8}}, {{8, 8, 30}, {8, 8, 0}}};
  for (const std::string& backend : backends_for(RenderMode::iso))
    for (double iso : {8.0, 5.0, 3.0})
      for (const auto& [eye, target] : views) {
        Scene s = make_scene(ds, backend, RenderMode::iso, 15);
        s.isosurfaces = {Isosurface{iso}};
        const Rendered r = render_world(s, look(eye, target, {0, 1, 0}));
        const std::string what = fmt_what(backend, RenderMode::iso, eye) + " iso " + std::to_string(iso);
        EXPECT_GT(expect_sane(r.fb, what), 0) << what;
        // Raymarch reports a surface it starts on one sample (half a step) late.
        expect_iso_matches(r, backend, f, iso, 16, 0.5, what);
      }
}

TEST_F(Stability, ASurfaceTheRayStartsOnTakesItsOwnColour) {
  // f = min(z, 8) on 17x17x13: seen from above, every ray enters the plateau at the isovalue 8
  // and starts on that surface (the second of two), not on the first (3, below it). The top
  // bricks (z from 8 to 12) are not constant (their apron reaches z = 7), so the ray's first
  // sample, not a constant node, meets the surface. Unlit, a hit pixel is its surface's colour.
  const SeparableField f{{17, 17, 13}, [](int a, int64_t i) { return a == 2 ? double(std::min<int64_t>(i, 8)) : 0.0; }};
  const std::string ds = build_array(*dir_, "plateau2", f.dims, f.values());
  for (const std::string& backend : backends_for(RenderMode::iso)) {
    Scene s = make_scene(ds, backend, RenderMode::iso, 15);
    s.shading.light = LightKind::none;
    s.isosurfaces = {Isosurface{3.0, Vec3f(1.0f, 0.0f, 0.0f)}, Isosurface{8.0, Vec3f(0.0f, 1.0f, 0.0f)}};
    const Rendered r = render_world(s, look({8, 8, 40}, {8, 8, 0}, {0, 1, 0}, 20));
    // Where the ray enters, or (a marcher's first sample) within one of its steps of it.
    // Back ends that solve each cell exactly (no step) hit where the ray enters.
    const std::map<std::string, double> params = RenderSession(s).params().values();
    const double step = backend == "reference" || !params.count("step") ? 1e-4 : params.at("step");
    int green = 0;
    for (int y = 0; y < 15; ++y)
      for (int x = 0; x < 15; ++x) {
        if (r.fb.color(x, y).a == 0) continue;
        EXPECT_EQ(r.fb.color(x, y), (Rgbaf{0.0f, 1.0f, 0.0f, 1.0f})) << backend << " pixel " << x << " " << y;
        const double entry = intersect(r.camera.ray(x + 0.5, y + 0.5, 15, 15), r.world).t0;
        EXPECT_GE(r.fb.depth(x, y), entry - 1e-4) << backend;
        EXPECT_LE(r.fb.depth(x, y), entry + step + 1e-4) << backend;
        ++green;
      }
    EXPECT_GT(green, 100) << backend;
  }
}

TEST_F(Stability, CamerasInsideTheVolumeAndOnItsFaces) {
  const SeparableField f = octahedron();
  struct View {
    Vec3d eye, target, up;
    const char* what;
  };
  const std::vector<View> views = {
      {{0.5, 0.5, 7.5}, {4, 4, 4}, {0, 0, 1}, "inside the volume, outside the surface"},
      {{4.2, 3.9, 4.1}, {8, 8, 8}, {0, 0, 1}, "inside the surface"},
      {{4, 4, 4}, {0, 4, 4}, {0, 0, 1}, "at a lattice point inside the surface"},
      {{4, 4, 8}, {4, 4, 0}, {0, 1, 0}, "on the top face, looking in"},
      {{0, 3, 5}, {8, 3, 5}, {0, 0, 1}, "on the x = 0 face, looking in"},
      {{4, 0, 1}, {4, 0, 7}, {0, 1, 0}, "on the y = 0 face, looking along it"},
      {{4, 4, 8}, {4, 4, 20}, {0, 1, 0}, "on the top face, looking out"},
      {{0, 0, 0}, {8, 8, 8}, {0, 0, 1}, "on a corner, looking along the diagonal"},
      {{8, 8, 0}, {0, 8, 8}, {1, 0, 0}, "on an edge, looking along a face diagonal"}};
  for (RenderMode mode : kModes)
    for (const std::string& backend : backends_for(mode))
      for (const View& v : views) {
        Scene s = make_scene(octa_, backend, mode, 15);
        s.isosurfaces = {Isosurface{2.5}};
        s.transfer_function = TransferFunction({{0.0, Vec3f(1.0f), 0.4f}, {3.0, Vec3f(0.5f), 0.05f}, {12, Vec3f(0.0f), 0.01f}});
        const Rendered r = render_world(s, look(v.eye, v.target, v.up, 60));
        const std::string what = fmt_what(backend, mode, v.eye) + " " + v.what;
        const int covered = expect_sane(r.fb, what);
        if (std::string(v.what).find("looking out") != std::string::npos) {
          // Every ray meets the volume in one point, the eye: nothing to see in iso or DVR. The
          // reference's MIP takes that point's value (a closed box, as for flat volumes), the
          // same in every pixel; raymarch takes no sample there.
          if (mode != RenderMode::mip || backend == "raymarch") {
            EXPECT_EQ(covered, 0) << what;
          } else {
            for (int i = 1; i < 15 * 15; ++i) EXPECT_EQ(r.fb.color.data()[i], r.fb.color.data()[0]) << what;
          }
          continue;
        }
        if (mode != RenderMode::iso) {
          EXPECT_GT(covered, 0) << what;
        } else {
          expect_iso_matches(r, backend, f, 2.5, 12, 0.05, what);
        }
      }
}

TEST_F(Stability, VolumesOneAndTwoVoxelsThick) {
  struct Tiny {
    Vec3s dims;
    std::vector<float> values;
  };
  const SeparableField slab_x{{1, 8, 8}, [](int a, int64_t i) { return a == 1 ? double(i) : a == 2 ? 2.0 * double(i) : 0.0; }};
  const SeparableField slab_z{{8, 8, 1}, [](int a, int64_t i) { return a == 0 ? double(i) : a == 1 ? -double(i) : 0.0; }};
  const std::vector<Tiny> tiny = {{{1, 1, 1}, {1.0f}},
                                  {{2, 2, 2}, {0.1f, 0.9f, 0.4f, 0.7f, 0.3f, 0.2f, 0.8f, 0.6f}},
                                  {{1, 8, 8}, slab_x.values()},
                                  {{8, 8, 1}, slab_z.values()},
                                  {{2, 1, 2}, {0.0f, 1.0f, 0.5f, 0.25f}}};
  for (const Tiny& t : tiny) {
    const std::string name = std::to_string(t.dims.x) + "x" + std::to_string(t.dims.y) + "x" + std::to_string(t.dims.z);
    const std::string ds = build_array(*dir_, name, t.dims, t.values);
    const Vec3d hi = Vec3d(t.dims - Vec3s(1)), mid = hi * 0.5;
    const float lo_v = *std::min_element(t.values.begin(), t.values.end()), hi_v = *std::max_element(t.values.begin(), t.values.end());
    // Oblique views, views along each axis through the volume's middle, and the first voxel.
    const std::vector<Camera> cams = {look(mid + Vec3d(7, -5, 6), mid, {0, 0, 1}, 60), look(mid + Vec3d(-3, 4, -9), mid, {0, 0, 1}, 60),
                                      look(mid + Vec3d(10, 0, 0), mid, {0, 0, 1}, 60), look(mid + Vec3d(0, 10, 0), mid, {0, 0, 1}, 60),
                                      look(mid + Vec3d(0, 0, 10), mid, {0, 1, 0}, 60), look({-3, 0, 0}, {0, 0, 0}, {0, 0, 1}, 10)};
    for (RenderMode mode : kModes)
      for (const std::string& backend : backends_for(mode))
        for (const Camera& cam : cams) {
          Scene s = make_scene(ds, backend, mode, 15);
          s.isosurfaces = {Isosurface{0.5 * (double(lo_v) + double(hi_v))}, Isosurface{double(hi_v)}};
          s.transfer_function = TransferFunction({{double(lo_v) - 1, Vec3f(1.0f, 0.0f, 0.0f), 0.2f}, {double(hi_v) + 1, Vec3f(0.0f, 0.0f, 1.0f), 0.9f}});
          const Rendered r = render_world(s, cam);
          expect_sane(r.fb, name + " " + fmt_what(backend, mode, cam.eye));
          // A flat volume seen in MIP by the reference shows its slice: the interpolated value
          // where each ray crosses the plane (grey scaled over the value range).
          if (mode != RenderMode::mip || std::string(backend) != "reference" || !(t.dims.x == 1 && t.dims.y == 8)) continue;
          Scene plain = s;
          plain.transfer_function = TransferFunction();
          const Rendered m = render_world(plain, cam);
          int checked = 0;
          for (int y = 0; y < 15; ++y)
            for (int x = 0; x < 15; ++x) {
              const Rayd ray = cam.ray(x + 0.5, y + 0.5, 15, 15);
              if (ray.dir.x == 0) continue;
              const double tc = -ray.org.x / ray.dir.x;
              const Vec3d p = ray.at(tc);
              if (tc < 0 || p.y < 1e-9 || p.y > 7 - 1e-9 || p.z < 1e-9 || p.z > 7 - 1e-9) continue;
              const double expected = (slab_x.at(p) - lo_v) / (hi_v - lo_v);
              EXPECT_NEAR(m.fb.color(x, y).r, expected, 1e-5) << name << " pixel " << x << " " << y;
              ++checked;
            }
          if (cam.eye.x != mid.x) {
            EXPECT_GT(checked, 0);
          }
        }
  }
}

TEST_F(Stability, NormalisedCamerasOnVolumesOfZeroExtent) {
  // Through RenderSession, camera positions are normalised to the volume's box. A 1x1x1 volume
  // has a box of zero extent, so eye and target collapse onto the voxel; so do those of a camera
  // looking straight down z at an 8x8x1 slice. Such frames must still be finite.
  const std::string one = build_array(*dir_, "one", {1, 1, 1}, {2.0f});
  const SeparableField slice{{8, 8, 1}, [](int a, int64_t i) { return a == 0 ? double(i) : a == 1 ? -double(i) : 0.0; }};
  const std::string flat = build_array(*dir_, "slice", slice.dims, slice.values());
  for (const std::string& ds : {one, flat})
    for (RenderMode mode : kModes)
      for (const std::string& backend : backends_for(mode)) {
        Scene s = make_scene(ds, backend, mode, 9);
        s.camera.keyframes = {look({0.5, 0.5, 2.0}, {0.5, 0.5, 0.5}, {0, 1, 0})};
        s.isosurfaces = {Isosurface{2.0}};
        s.transfer_function = TransferFunction({{-8.0, Vec3f(1.0f), 0.5f}, {8.0, Vec3f(1.0f), 0.5f}});
        RenderSession session(s);
        FrameBuffers fb;
        session.render(0, fb, FrameOutputs{.depth = true, .normals = true});
        expect_sane(fb, ds + " " + fmt_what(backend, mode, session.camera(0).eye));
      }
}

TEST_F(Stability, RaysWithoutADirectionSeeNothing) {
  // A camera whose eye and target coincide gives rays of direction (0, 0, 0): every pixel is
  // the background, in every mode (the reference once evaluated its DVR step count from the
  // resulting infinite span, a float-to-integer conversion of +inf).
  for (RenderMode mode : kModes)
    for (const std::string& backend : backends_for(mode)) {
      Scene s = make_scene(octa_, backend, mode, 9);
      s.isosurfaces = {Isosurface{2.5}};
      s.transfer_function = TransferFunction({{0.0, Vec3f(1.0f), 0.5f}, {12.0, Vec3f(1.0f), 0.5f}});
      for (const Vec3d& at : {Vec3d(4, 4, 4), Vec3d(0, 0, 0), Vec3d(3, 4, 8)}) {
        Camera cam = look(at, at);
        const Rendered r = render_world(s, cam);
        ASSERT_EQ(cam.ray(4.5, 4.5, 9, 9).dir, Vec3d(0.0));
        const std::string what = fmt_what(backend, mode, at);
        EXPECT_EQ(expect_sane(r.fb, what), 0) << what;
        for (int i = 0; i < 81; ++i) EXPECT_EQ(r.fb.color.data()[i], (Rgbaf{0.1f, 0.2f, 0.3f, 0.0f})) << what;
      }
    }
}

TEST_F(Stability, HugeAndTinyValues) {
  // (a) The ramp f = s (z - 4) for s from 1e-30 to 1e30: the isosurface f = s / 2 is the plane
  // z = 4.5 whatever the scale.
  for (double scale : {1e29, -1e29, 1e-30, -1e-30, 1e30}) {
    const SeparableField f{{9, 9, 9}, [scale](int a, int64_t i) { return a == 2 ? scale * (double(i) - 4) : 0.0; }};
    const std::string ds = build_array(*dir_, "ramp" + std::to_string(scale), f.dims, f.values());
    for (const std::string& backend : backends_for(RenderMode::iso)) {
      Scene s = make_scene(ds, backend, RenderMode::iso, 15);
      s.isosurfaces = {Isosurface{0.5 * scale}};
      const Rendered r = render_world(s, look({-5, 3, 14}, {4, 4, 4}, {0, 0, 1}, 50));
      const std::string what = fmt_what(backend, RenderMode::iso, Vec3d(scale));
      EXPECT_GT(expect_sane(r.fb, what), 30) << what;
      expect_iso_matches(r, backend, f, 0.5 * scale, 4 * std::fabs(scale), 0.05, what);
    }
  }
  // (b) Magnitudes from 1e-30 to 1e30 and both signs side by side, in every mode.
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> exponent(-30, 30);
  std::vector<float> v(9 * 9 * 9);
  for (size_t i = 0; i < v.size(); ++i) v[i] = float((i % 2 ? -1.0 : 1.0) * std::pow(10.0, exponent(rng)));
  const std::string ds = build_array(*dir_, "magnitudes", {9, 9, 9}, v);
  for (RenderMode mode : kModes)
    for (const std::string& backend : backends_for(mode)) {
      Scene s = make_scene(ds, backend, mode, 21);
      s.isosurfaces = {Isosurface{0.0}, Isosurface{1e20}};
      s.transfer_function = TransferFunction({{-1e30, Vec3f(1.0f, 0.0f, 0.0f), 0.3f},
                                              {-1e-30, Vec3f(0.0f, 1.0f, 0.0f), 0.05f},
                                              {1e-30, Vec3f(0.0f, 1.0f, 1.0f), 0.05f},
                                              {1e30, Vec3f(0.0f, 0.0f, 1.0f), 0.8f}});
      for (const Camera& cam : {look({-5, 3, 14}, {4, 4, 4}, {0, 0, 1}, 50), look({4, 4, 20}, {4, 4, 0}, {0, 1, 0}, 40)}) {
        const Rendered r = render_world(s, cam);
        const std::string what = fmt_what(backend, mode, cam.eye) + " magnitudes";
        EXPECT_GT(expect_sane(r.fb, what), 30) << what;
      }
    }
}

TEST_F(Stability, TransparentTransferFunctionShowsTheBackgroundAndFetchesNothing) {
  for (const std::string& backend : backends_for(RenderMode::dvr))
    for (const TransferFunction& tf : {TransferFunction({{0.0, Vec3f(1.0f), 0.0f}, {12.0, Vec3f(1.0f), 0.0f}}),
                                       TransferFunction({{-100.0, Vec3f(1.0f), 0.0f}, {2.0, Vec3f(0.5f), 0.0f}, {100.0, Vec3f(0.0f), 0.0f}}),
                                       TransferFunction()}) {
      Scene s = make_scene(octa_, backend, RenderMode::dvr, 17);
      s.transfer_function = tf;
      const Rendered r = render_world(s, look({-6, -5, 12}, {4, 4, 4}, {0, 0, 1}, 60));
      const std::string what = backend + " " + std::to_string(tf.points().size()) + " points";
      for (int y = 0; y < 17; ++y)
        for (int x = 0; x < 17; ++x) {
          EXPECT_EQ(r.fb.color(x, y), (Rgbaf{0.1f, 0.2f, 0.3f, 0.0f})) << what;
          EXPECT_EQ(r.fb.depth(x, y), std::numeric_limits<float>::infinity()) << what;
          EXPECT_EQ(r.fb.normal(x, y), Vec3f(0.0f)) << what;
        }
      EXPECT_EQ(r.cache.l1.misses, 0u) << what;
      EXPECT_EQ(r.cache.stalls, 0u) << what;
      EXPECT_EQ(r.cache.l3_bytes_read, 0u) << what;
      EXPECT_EQ(r.stats.stalls, 0u) << what;
      EXPECT_EQ(r.stats.counters.misses, 0u) << what;
      EXPECT_EQ(r.stats.counters.samples, 0u) << what;
    }
}

TEST_F(Stability, OpaqueTransferFunctionStopsAtTheFirstSample) {
  // f = x + 2y + 3z (values 0 to 48) with opacity 1 everywhere and colour proportional to the
  // value: each pixel shows the field where the ray enters, fully opaque. The midpoint samplers
  // (the reference, raymarch) show exactly their first sample's value, at t0 + dt/2. The others
  // take the volume from its entry in their own way (gobbetti samples from t0, gigavoxels
  // integrates pre-integrated segments from t0): each must show a value the field takes within
  // one of its steps of the entry, at a depth within that step.
  const SeparableField f{{9, 9, 9}, [](int a, int64_t i) { return double(a + 1) * double(i); }};
  const std::string ds = build_array(*dir_, "linear", f.dims, f.values());
  for (const std::string& backend : backends_for(RenderMode::dvr)) {
    const bool midpoint = backend == "reference" || backend == "raymarch";
    Scene s = make_scene(ds, backend, RenderMode::dvr, 17);
    s.shading.light = LightKind::none;
    s.transfer_function = TransferFunction({{0.0, Vec3f(0.0f), 1.0f}, {48.0, Vec3f(1.0f, 0.5f, 0.25f), 1.0f}});
    const double step = RenderSession(s).params()["step"];  // the back end's default step, in voxels
    for (const Camera& cam : {look({-6, -5, 12}, {4, 4, 4}, {0, 0, 1}, 60), look({4, 4, 4}, {9, 0, 1}, {0, 0, 1}, 60),
                              look({4, 3, 20}, {4, 3, 0}, {0, 1, 0}, 40)}) {
      const Rendered r = render_world(s, cam);
      const std::string what = fmt_what(backend, RenderMode::dvr, cam.eye);
      EXPECT_GT(expect_sane(r.fb, what), 50) << what;
      int checked = 0;
      for (int y = 0; y < 17; ++y)
        for (int x = 0; x < 17; ++x) {
          const Rayd ray = cam.ray(x + 0.5, y + 0.5, 17, 17);
          Interval<double> span = intersect(ray, r.world);
          span.t0 = std::max(span.t0, 0.0);
          if (span.empty() || span.t1 - span.t0 < step + 1e-9) continue;
          const Rgbaf c = r.fb.color(x, y);
          const double tol = backend == "reference" ? 1e-5 : 1e-4;
          EXPECT_NEAR(c.a, 1.0f, 1e-6) << what;
          if (midpoint) {
            const double t = span.t0 + 0.5 * step;
            const double value = f.at(ray.at(t));
            EXPECT_NEAR(r.fb.depth(x, y), t, tol * (1 + t)) << what;
            EXPECT_NEAR(c.r, value / 48, tol) << what << " pixel " << x << " " << y;
            EXPECT_NEAR(c.g, 0.5 * value / 48, tol) << what;
            EXPECT_NEAR(c.b, 0.25 * value / 48, tol) << what;
          } else {
            const double v0 = f.at(ray.at(span.t0)), v1 = f.at(ray.at(span.t0 + step));
            EXPECT_GE(r.fb.depth(x, y), span.t0 - tol) << what;
            EXPECT_LE(r.fb.depth(x, y), span.t0 + step + tol) << what;
            EXPECT_GE(c.r, std::min(v0, v1) / 48 - tol) << what << " pixel " << x << " " << y;
            EXPECT_LE(c.r, std::max(v0, v1) / 48 + tol) << what << " pixel " << x << " " << y;
            EXPECT_NEAR(c.g, 0.5 * c.r, tol) << what;
            EXPECT_NEAR(c.b, 0.25 * c.r, tol) << what;
          }
          ++checked;
        }
      EXPECT_GT(checked, 50) << what;
    }
  }
}
}  // namespace
}  // namespace brickyard
