// Stiff and extreme cases over every registered back end (the shared suite: shared_suite.h):
// inputs real data has that once gave a silently wrong image (exit 0, no warning, far from the
// reference): masks and constant regions under lit DVR, opaque data touching the volume's
// faces, isovalues just off a plateau, very anisotropic grids at their default level of
// detail, values near the limits of f32; and cameras on faces, along axes and grazing
// surfaces. Each case states the error against the reference every back end must stay under
// (a back end's own tolerance where its design makes it coarser); where a case is ill-posed
// (an isovalue equal to a plateau's value) only what is defined is checked: a sane frame and
// its coverage.

#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "array_scene.h"
#include "renderers/common/metrics.h"
#include "shared_suite.h"
#include "test_util.h"
#include "tet_test_util.h"

namespace brickyard {
namespace {

using testing::backends_for;
using testing::build_array;
using testing::expect_sane;
using testing::look;
using testing::make_scene;
using testing::render_world;
using testing::Rendered;

/// A back end's frame and the reference's of one scene and world camera, and the error between.
struct Compared {
  Rendered test, truth;
  ImageError e;
};

Compared against_reference(const Scene& scene, const Camera& camera) {
  Compared c;
  c.test = render_world(scene, camera);
  Scene ref = scene;
  ref.backend = "reference";
  ref.backend_params.clear();
  c.truth = render_world(ref, camera);
  c.e = compare_frames(c.test.fb, c.truth.fb, 1.0);  // unit spacing: world units are voxels
  return c;
}

/// A 0/1 mask of a ball: the segmentation a user renders as is. Its inside is flat (no
/// gradient), and whole bricks of it are constant.
std::vector<float> ball_mask(int n, double radius) {
  std::vector<float> v;
  const double c = 0.5 * (n - 1);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) v.push_back(std::hypot(x - c, y - c, z - c) <= radius ? 1.0f : 0.0f);
  return v;
}

/// f = scale (x + 2y + 3z) on n^3 voxels: a gradient of (1, 2, 3) scale everywhere, its faces
/// included.
std::vector<float> linear_ramp(int n, double scale = 1.0) {
  std::vector<float> v;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) v.push_back(float(scale * (x + 2 * y + 3 * z)));
  return v;
}

class Stiff : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    mask_ = build_array(*dir_, "mask", {24, 24, 24}, ball_mask(24, 8.5));
  }
  static void TearDownTestSuite() { delete dir_; }
  static testing::TempDir* dir_;
  static std::string mask_;
};
testing::TempDir* Stiff::dir_ = nullptr;
std::string Stiff::mask_;

const Camera kOblique = look({-14, -20, 30}, {11.5, 11.5, 11.5}, {0, 0, 1}, 40);

TEST_F(Stiff, LitDvrOfAMaskShadesItsFlatInsideAsFacingTheEye) {
  // The mask's inside has no gradient: the reference shades it as a surface facing the ray
  // (facing_normal), so under a headlight it is fully lit. gigavoxels once left such samples
  // to the ambient term alone: almost black (RMSE 0.53-0.75 against 0.01 elsewhere).
  // A step field (z >= 12 is 1) and a volume constant at 1 too: all flat where visible.
  std::vector<float> step(24 * 24 * 24), constant(24 * 24 * 24, 1.0f);
  for (size_t i = 0; i < step.size(); ++i) step[i] = i / (24 * 24) >= 12 ? 1.0f : 0.0f;
  const std::vector<std::pair<std::string, std::string>> stores = {
      {"mask", mask_}, {"step", build_array(*dir_, "step", {24, 24, 24}, step)}, {"constant", build_array(*dir_, "constant", {24, 24, 24}, constant)}};
  for (const auto& [name, store] : stores)
    for (const std::string& backend : backends_for(RenderMode::dvr)) {
      if (backend == "reference") continue;
      Scene s = make_scene(store, backend, RenderMode::dvr, 33);
      s.shading.light = LightKind::headlight;
      s.transfer_function = TransferFunction({{0.0, Vec3f(0.2f, 0.3f, 0.9f), 0.0f}, {1.0, Vec3f(0.9f, 0.6f, 0.2f), 0.12f}});
      const Compared c = against_reference(s, kOblique);
      const std::string what = backend + " " + name;
      EXPECT_GT(expect_sane(c.test.fb, what), 200) << what;
      EXPECT_LT(c.e.rmse, 0.02) << what << " " << c.e.to_json();
    }
}

TEST_F(Stiff, LitDvrEnteringThroughAFaceIsShadedFromTheData) {
  // f = x + 2y + 3z, visible everywhere: its gradient is (1, 2, 3) at every point, the faces
  // included, so every back end must shade with it where rays enter through a face into
  // visible opacity. gobbetti once took the gradient at a face from a cell reaching into the
  // apron (a copy of the face): salt and pepper, 51 degrees of normal error. At the finest
  // level a midpoint sample never lies on the face; at a coarser one the half finest voxel
  // outside its first voxel centre does (here at lod_ratio 4). The coarse
  // levels of a linear field are linear (32 = 2^5: every coarse voxel averages whole blocks).
  const int n = 32;
  const std::string store = build_array(*dir_, "linear", {n, n, n}, linear_ramp(n));
  for (const std::string& backend : backends_for(RenderMode::dvr)) {
    if (backend == "reference") continue;
    for (double lod_ratio : {0.01, 4.0})
    for (const Camera& cam : {look({-20, -15, 48}, {15.5, 15.5, 15.5}, {0, 0, 1}, 45), look({15.5, 15.5, 64}, {15.5, 15.5, 0}, {0, 1, 0}, 40),
                              look({-32, 15, 15}, {15.5, 15.5, 15.5}, {0, 0, 1}, 50)}) {
      Scene s = make_scene(store, backend, RenderMode::dvr, 33);
      s.quality.lod_ratio = lod_ratio;
      s.shading.light = LightKind::headlight;
      s.transfer_function = TransferFunction({{0.0, Vec3f(0.9f, 0.2f, 0.1f), 0.3f}, {186.0, Vec3f(0.1f, 0.8f, 0.9f), 0.6f}});
      const Compared c = against_reference(s, cam);
      const std::string what = backend + " lod_ratio " + std::to_string(lod_ratio) + " eye " + std::to_string(cam.eye.x) + " " + std::to_string(cam.eye.z);
      EXPECT_GT(expect_sane(c.test.fb, what), 300) << what;
      EXPECT_LT(c.e.rmse, 0.01) << what << " " << c.e.to_json();
      EXPECT_GT(c.e.normal_pixels, 300u) << what;
      EXPECT_LT(c.e.normal_p99_deg, 1.0) << what << " " << c.e.to_json();
    }
  }
}

TEST_F(Stiff, AnIsovalueJustOffAPlateauIsShadedFromItsRisingSide) {
  // The mask at isovalue 1e-4: the crossing lies a ten-thousandth of a cell into the cell that
  // rises from the plateau at 0, and a refined hit may land across the kink, on the plateau
  // side, where the gradient vanishes (43 degrees of normal error, RMSE 0.15). At 1 - 1e-4
  // the kink is on the far side, the plateau at 1.
  // The marchers (a half-voxel step) miss slivers of the blocky surface at 1 - 1e-4 that the
  // back ends solving cells exactly see: their tolerances are wider.
  struct Tolerance {
    double rmse, coverage, normal_deg;
  };
  const Tolerance marcher{0.03, 0.01, 2.5}, exact{0.012, 0.003, 0.5};
  for (double iso : {1e-4, 1 - 1e-4, 0.5})
    for (const std::string& backend : backends_for(RenderMode::iso)) {
      if (backend == "reference") continue;
      const Tolerance tol = backend == "raymarch" || backend == "gobbetti" ? marcher : exact;
      Scene s = make_scene(mask_, backend, RenderMode::iso, 41);
      s.shading.light = LightKind::headlight;
      s.isosurfaces = {Isosurface{iso}};
      const Compared c = against_reference(s, kOblique);
      const std::string what = backend + " iso " + std::to_string(iso);
      EXPECT_GT(expect_sane(c.test.fb, what), 300) << what;
      EXPECT_LT(c.e.coverage_mismatch_fraction, tol.coverage) << what << " " << c.e.to_json();
      EXPECT_LT(c.e.normal_mean_deg, tol.normal_deg) << what << " " << c.e.to_json();
      EXPECT_LT(c.e.rmse, tol.rmse) << what << " " << c.e.to_json();
    }
}

TEST_F(Stiff, AnIsovalueEqualToAPlateauIsIllPosedAndOnlyItsCoverageIsChecked) {
  // At isovalue 1 the surface is the whole inside of the mask (every point of it is on the
  // surface) and at 0 the whole outside: no normal is defined there, and where a marcher
  // reports the surface depends on where it samples. What is defined: a sane frame, and at 1
  // the mask's silhouette (the rays that reach the plateau) within a pixel's margin.
  for (double iso : {1.0, 0.0})
    for (const std::string& backend : backends_for(RenderMode::iso)) {
      Scene s = make_scene(mask_, backend, RenderMode::iso, 41);
      s.shading.light = LightKind::headlight;
      s.isosurfaces = {Isosurface{iso}};
      const Compared c = against_reference(s, kOblique);
      const std::string what = backend + " iso " + std::to_string(iso);
      const int covered = expect_sane(c.test.fb, what);
      EXPECT_GT(covered, 300) << what;
      if (iso == 1.0) {
        EXPECT_LT(c.e.coverage_mismatch_fraction, 0.03) << what << " " << c.e.to_json();
      }
    }
}

TEST_F(Stiff, TransferFunctionsOverDenormalAndHugeRangesKeepTheirShape) {
  // f = s (x + 2y + 3z) with s = 1e-42 (every value denormal) and 2.5e36 (up to 2.9e38, near the
  // largest float), a transfer function over the whole range: the image is the one of s = 1.
  // A table over 1e-40 once had a scale past the largest float and collapsed to its first
  // entry (RMSE 0.069).
  const int n = 20;
  for (double scale : {1e-42, 2.5e36}) {
    const std::vector<float> v = linear_ramp(n, scale);
    const std::string store = build_array(*dir_, "scaled" + std::to_string(scale), {n, n, n}, v);
    const double hi = double(v.back());
    for (const std::string& backend : backends_for(RenderMode::dvr)) {
      if (backend == "reference") continue;
      Scene s = make_scene(store, backend, RenderMode::dvr, 33);
      s.transfer_function = TransferFunction({{0.0, Vec3f(0.9f, 0.2f, 0.1f), 0.0f}, {hi, Vec3f(0.1f, 0.8f, 0.9f), 0.5f}});
      const Compared c = against_reference(s, look({-12, -9, 30}, {9.5, 9.5, 9.5}, {0, 0, 1}, 45));
      const std::string what = backend + " scale " + std::to_string(scale);
      EXPECT_GT(expect_sane(c.test.fb, what), 300) << what;
      EXPECT_LT(c.e.rmse, 0.01) << what << " " << c.e.to_json();
    }
  }
}

/// The back ends' tolerances where they take the volume as a marcher does (a half-voxel step,
/// raymarch and gobbetti), or solve or integrate it more exactly (the rest). gigavoxels lights
/// a DVR segment from its ends: inside a visible plateau, where segments join flat samples and
/// sloped ones, its error is first order in its step (0.0150, 0.0075, 0.0039 at steps 0.5,
/// 0.25, 0.125 with the eye in the plateau), where the other views stay under 0.009.
double view_tolerance(const std::string& backend, RenderMode mode) {
  const bool marcher = backend == "raymarch" || backend == "gobbetti";
  if (mode == RenderMode::iso) return marcher ? 0.03 : 0.015;
  return marcher || backend == "gigavoxels" ? 0.02 : 0.015;
}

TEST_F(Stiff, DegenerateViewpointsMatchTheReference) {
  // A ball's distance field, 1 past radius 12 (the cube's corners: constant bricks, a plateau),
  // on 25^3 and on 25x25x7 voxels 4 apart in z (the same ball in world space): an isosurface
  // at 0.6 and a lit transfer function over [0.3, 1]. Cameras on a face looking in, in a face's
  // plane looking along it, along exact axes (with the up vector reversed, so that the ray
  // directions' zero components are -0.0) and diagonals, inside the empty part of the volume,
  // inside the surface and inside the plateau, and one whose central ray grazes the
  // isosurface's silhouette. Every frame sane, and its error under the back end's tolerance.
  const auto ball = [](const Vec3s& dims, const Vec3d& spacing) {
    std::vector<float> v;
    for (int64_t z = 0; z < dims.z; ++z)
      for (int64_t y = 0; y < dims.y; ++y)
        for (int64_t x = 0; x < dims.x; ++x) {
          const Vec3d p = Vec3d(double(x), double(y), double(z)) * spacing - Vec3d(12.0);
          v.push_back(float(std::min(length(p) / 12, 1.0)));
        }
    return v;
  };
  const std::vector<std::pair<std::string, std::string>> stores = {
      {"ball", build_array(*dir_, "ball", {25, 25, 25}, ball({25, 25, 25}, Vec3d(1.0)))},
      {"ball anisotropic", build_array(*dir_, "ball-aniso", {25, 25, 7}, ball({25, 25, 7}, {1, 1, 4}), 8, {1, 1, 4})}};
  struct View {
    const char* what;
    Camera camera;
  };
  const std::vector<View> views = {
      {"on the top face, looking in", look({12, 12, 24}, {12, 12, 0}, {0, 1, 0}, 60)},
      {"in the top face's plane, looking along it", look({-10, 12, 24}, {30, 12, 24}, {0, 0, 1}, 60)},
      {"along -y, up reversed", look({12, 45, 12}, {12, 0, 12}, {0, 0, -1}, 40)},
      {"along +x through the centre", look({-30, 12, 12}, {12, 12, 12}, {0, 0, 1}, 40)},
      {"along the diagonal", look({-10, -10, -10}, {12, 12, 12}, {0, 0, 1}, 45)},
      {"inside the empty part", look({12, 12, 20.5}, {12, 12, 0}, {0, 1, 0}, 70)},
      {"inside the surface", look({12.3, 11.8, 12.4}, {24, 24, 24}, {0, 0, 1}, 70)},
      {"inside the plateau, a corner", look({1, 1, 1}, {12, 12, 12}, {0, 0, 1}, 60)},
      {"grazing the silhouette", look({19.2, -40, 12}, {19.2, 12, 12}, {0, 0, 1}, 6)}};
  for (const auto& [name, store] : stores)
    for (RenderMode mode : {RenderMode::iso, RenderMode::dvr})
      for (const std::string& backend : backends_for(mode)) {
        if (backend == "reference") continue;
        for (const View& v : views) {
          Scene s = make_scene(store, backend, mode, 33);
          s.shading.light = LightKind::headlight;
          s.isosurfaces = {Isosurface{0.6}};
          s.transfer_function = TransferFunction({{0.3, Vec3f(0.9f, 0.5f, 0.1f), 0.0f}, {1.0, Vec3f(0.2f, 0.6f, 1.0f), 0.15f}});
          const Compared c = against_reference(s, v.camera);
          const std::string what = backend + " " + std::string(to_string(mode)) + " " + name + ", " + v.what;
          expect_sane(c.test.fb, what);
          EXPECT_LT(c.e.rmse, view_tolerance(backend, mode)) << what << " " << c.e.to_json();
        }
      }
}

TEST_F(Stiff, TetrahedralMeshesFromDegenerateViewpointsMatchTheReference) {
  // An unjittered lattice of Kuhn tets on [0, 1]^3 (faces on the axis planes and diagonals,
  // so axis-aligned rays run along edges and through vertices) with f = min(x + y + z, 1.5)
  // and f * 1e30: values at the vertices multiples of 1/6, and a plateau at 1.5 near the far
  // corner. Isovalues equal to vertex values (0.5), just below the plateau (1.5 - 1e-4), and a
  // generic one (0.8); cameras along an axis through vertices, on a boundary face looking in,
  // inside the mesh, in the plateau, along the diagonal, grazing. Every tetrahedral back end
  // against the tet reference. The isovalue of the plateau itself is ill-posed: a sane frame.
  for (const double scale : {1.0, 1e30}) {
    const std::string store = dir_->file("tets" + std::to_string(int(std::log10(scale))) + ".store");
    testing::build(testing::lattice_mesh(6, 0.0, [&](const Vec3d& p) { return scale * std::min(p.x + p.y + p.z, 1.5); }), store, 64);
    // Which rays lie in the mesh's face planes: through the central row and column of an
    // image looking along an axis through the lattice's planes. A hit there lies on a face
    // two tets share, and where the field kinks (the plateau's edge) the normal is either
    // tet's: only the depth and coverage are defined. A ray in a boundary face only touches
    // the mesh (the central column of the grazing view): it may hit or not.
    struct View {
      const char* what;
      Camera camera;
      bool rays_in_faces = false, touching_column = false;
    };
    const std::vector<View> views = {
        {"along +x through vertices", look({-2, 0.5, 0.5}, {0.5, 0.5, 0.5}, {0, 0, 1}, 40), true},
        {"on the z = 0 face, looking in", look({0.5, 0.5, 0}, {0.5, 0.5, 1}, {0, 1, 0}, 70), true},
        {"inside the mesh", look({0.2, 0.25, 0.3}, {1, 1, 1}, {0, 0, 1}, 70)},
        {"inside the plateau", look({0.95, 0.9, 0.95}, {0, 0, 0}, {0, 0, 1}, 70)},
        {"along the diagonal, up reversed", look({-1, -1, -1}, {0.5, 0.5, 0.5}, {0, 0, -1}, 40), true},
        {"grazing the x = 1 face", look({1, -2, 0.5}, {1, 0.5, 0.5}, {0, 0, 1}, 30), true, true}};
    for (const double iso : {0.5, 1.5 - 1e-4, 0.8, 1.5})
      for (const std::string& backend : backends_for(RenderMode::iso, DataKind::tetrahedral)) {
        if (backend == "reference") continue;
        for (const View& v : views) {
          Scene s = make_scene(store, backend, RenderMode::iso, 33);
          s.shading.light = LightKind::headlight;
          s.isosurfaces = {Isosurface{iso * scale}};
          const Compared c = against_reference(s, v.camera);
          const std::string what = backend + " scale " + std::to_string(scale) + " iso " + std::to_string(iso) + ", " + v.what;
          expect_sane(c.test.fb, what);
          if (iso == 1.5) continue;  // ill-posed: the plateau's every point is on the surface
          EXPECT_LE(c.e.coverage_mismatch, v.touching_column ? 33u : 0u) << what << " " << c.e.to_json();
          EXPECT_LT(c.e.depth_max, 1e-4) << what << " " << c.e.to_json();
          if (!v.rays_in_faces) {
            EXPECT_LT(c.e.rmse, 0.002) << what << " " << c.e.to_json();
          } else if (iso != 1.5 - 1e-4) {  // no kink at the crossings: the normal is defined
            EXPECT_LT(c.e.normal_mean_deg, 0.01) << what << " " << c.e.to_json();
          }
        }
      }
  }
}

TEST_F(Stiff, AStarvedCacheIsRefusedOrSaysTheFrameIsBelowQuality) {
  // An L1 of one brick (8^3 voxels with their apron, 4000 bytes): every back end either
  // refuses it before the first frame, naming cache.l1 and the least it needs, or renders
  // within it a sane frame that matches the reference or says it is below the quality asked.
  // None may render past its budget or draw a coarse image without a word.
  const uint64_t brick = 10 * 10 * 10 * sizeof(float);
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr})
    for (const std::string& backend : backends_for(mode)) {
      Scene s = make_scene(mask_, backend, mode, 33);
      s.cache.l1_bytes = brick;
      s.shading.light = LightKind::headlight;
      s.isosurfaces = {Isosurface{0.5}};
      s.transfer_function = TransferFunction({{0.0, Vec3f(0.2f, 0.3f, 0.9f), 0.0f}, {1.0, Vec3f(0.9f, 0.6f, 0.2f), 0.12f}});
      const std::string what = backend + " " + std::string(to_string(mode));
      try {
        const Compared c = against_reference(s, kOblique);
        expect_sane(c.test.fb, what);
        EXPECT_TRUE(c.e.rmse < 0.02 || !c.test.stats.below_quality.empty()) << what << " " << c.e.to_json();
        const CacheStats& bricks = c.test.cache.kinds.empty() ? c.test.cache : c.test.cache.kinds.at(RecordKind::brick);
        EXPECT_LE(bricks.l1_pool_bytes, brick) << what;
      } catch (const Error& e) {
        EXPECT_EQ(e.field(), "cache.l1") << what << ": " << e.what();
        const std::string message = e.what();  // naming the least it needs
        EXPECT_TRUE(message.find("at least") != std::string::npos || message.find("smaller than one") != std::string::npos)
            << what << ": " << message;
      }
    }
}

TEST_F(Stiff, AStepBetweenValuesNearTheLargestFloatKeepsItsSurface) {
  // -0.6 and +0.6 times the largest float, below and above z = 3.5: the difference of two
  // neighbours overflows single precision. The isosurfaces at 0 and 0.3 FLT_MAX are the planes
  // z = 3.5 and 3.75, with normal z; once they came out flat-shaded, up to 11 voxels deep and
  // with 1% of their coverage wrong in every float back end.
  const double big = 0.6 * double(FLT_MAX);
  std::vector<float> v;
  for (int z = 0; z < 9; ++z)
    for (int y = 0; y < 9; ++y)
      for (int x = 0; x < 9; ++x) v.push_back(float(z < 4 ? -big : big));
  const std::string store = build_array(*dir_, "huge-step", {9, 9, 9}, v);
  const Camera cam = look({-6, -4, 14}, {4, 4, 4}, {0, 0, 1}, 50);
  for (const double iso : {0.0, 0.3 * double(FLT_MAX)})
    for (const std::string& backend : backends_for(RenderMode::iso)) {
      Scene s = make_scene(store, backend, RenderMode::iso, 33);
      s.shading.light = LightKind::headlight;
      s.isosurfaces = {Isosurface{iso}};
      const Rendered r = render_world(s, cam);
      const std::string what = backend + " iso " + std::to_string(iso);
      const double plane = iso == 0 ? 3.5 : 3.75;
      int hits = 0, expected = 0;
      for (int y = 0; y < 33; ++y)
        for (int x = 0; x < 33; ++x) {
          const Rayd ray = cam.ray(x + 0.5, y + 0.5, 33, 33);
          const double t = (plane - ray.org.z) / ray.dir.z;
          const Vec3d p = ray.at(t);
          const bool inside = p.x > 1e-3 && p.x < 8 - 1e-3 && p.y > 1e-3 && p.y < 8 - 1e-3;
          const float depth = r.fb.depth(x, y);
          expected += inside;
          if (!std::isfinite(depth)) {
            EXPECT_FALSE(inside && p.x > 0.1 && p.x < 7.9 && p.y > 0.1 && p.y < 7.9) << what << " pixel " << x << " " << y << " missed";
            continue;
          }
          ++hits;
          EXPECT_NEAR(ray.at(depth).z, plane, 0.02) << what << " pixel " << x << " " << y;
          EXPECT_NEAR(std::fabs(r.fb.normal(x, y).z), 1.0, 1e-3) << what << " pixel " << x << " " << y;
        }
      EXPECT_NEAR(hits, expected, 0.02 * expected) << what;
    }
}

TEST(StiffRays, AxisViewsGiveRaysNoNegativeZeroComponent) {
  // Back ends take a zero direction component as +0.0 (1 / d is +infinity in slab tests and
  // cell walks): no camera looking along an axis, whatever its up vector, gives a ray a -0.0
  // one (the basis' zero terms sum to +0.0), so a -0.0 never reaches them from a scene.
  const Vec3d axes[] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  int zeros = 0;
  for (const Vec3d& d : axes)
    for (const Vec3d& up : axes) {
      if (dot(d, up) != 0) continue;
      const Camera c = look(Vec3d(12.0) - d * 30.0, Vec3d(12.0), up, 40);
      for (int y = 0; y < 33; ++y)
        for (int x = 0; x < 33; ++x) {
          const Rayd r = c.ray(x + 0.5, y + 0.5, 33, 33);
          for (int a = 0; a < 3; ++a)
            if (r.dir[a] == 0) {
              ++zeros;
              EXPECT_FALSE(std::signbit(r.dir[a])) << "dir " << d << " up " << up << " pixel " << x << " " << y;
            }
        }
    }
  EXPECT_GT(zeros, 1000);  // the central rows and columns
}

TEST_F(Stiff, AStepTransferFunctionMatchesTheReference) {
  // Opacity jumping from 0 to 0.5 within 1e-6 of the value range at 0.5 (a threshold, as
  // users draw segmentations), lit and unlit, over the mask (its interpolated edge) and a
  // linear ramp: the marchers' error is their step's, the pre-integrated back end's its
  // table's; none may lose the step's surface.
  const int n = 20;
  const std::vector<float> ramp = linear_ramp(n, 1.0 / 114);
  const std::vector<std::pair<std::string, std::string>> stores = {{"mask", mask_},
                                                                   {"ramp", build_array(*dir_, "ramp01", {n, n, n}, ramp)}};
  for (const auto& [name, store] : stores)
    for (const LightKind light : {LightKind::none, LightKind::headlight})
      for (const std::string& backend : backends_for(RenderMode::dvr)) {
        if (backend == "reference") continue;
        Scene s = make_scene(store, backend, RenderMode::dvr, 33);
        s.shading.light = light;
        s.transfer_function = TransferFunction({{0.0, Vec3f(0.2f, 0.3f, 0.9f), 0.0f}, {0.5, Vec3f(0.2f, 0.3f, 0.9f), 0.0f},
                                                {0.5 + 1e-6, Vec3f(0.9f, 0.6f, 0.2f), 0.5f}, {1.0, Vec3f(0.9f, 0.6f, 0.2f), 0.5f}});
        const Compared c = against_reference(s, name == "mask" ? kOblique : look({-12, -9, 30}, {9.5, 9.5, 9.5}, {0, 0, 1}, 45));
        const std::string what = backend + " " + name + (light == LightKind::none ? " unlit" : " lit");
        EXPECT_GT(expect_sane(c.test.fb, what), 200) << what;
        EXPECT_LT(c.e.rmse, 0.02) << what << " " << c.e.to_json();  // measured 0.0006-0.0152
        EXPECT_LT(c.e.coverage_mismatch_fraction, 0.005) << what << " " << c.e.to_json();
      }
}

}  // namespace
}  // namespace brickyard
