// The tetrahedral reference against closed forms: a linear field's isosurface is an exact
// plane on any mesh; a closed surface has no pinholes where rays run through shared vertices,
// edges and faces; hexahedra split into tets leave no cracks; clusters change nothing; time
// steps select their scalars; DVR and MIP match their integrals; only the clusters that can
// contribute are read.

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "fields/random.h"
#include "preprocess/mesh_data.h"
#include "preprocess/tet_builder.h"
#include "renderers/common/tet_geometry.h"
#include "renderers/common/scene.h"
#include "session/render_session.h"
#include "storage/store.h"
#include "renderers/tet_test_util.h"
#include "test_util.h"

namespace brickyard {
namespace {

using testing::build;
using testing::lattice_mesh;
using testing::pinholes;
using testing::render;
using testing::tet_scene;

TEST(TetGeometry, TwoTetsSharingAFaceAgreeOnTheRaysCrossingToTheLastBit) {
  // Random pairs of tets on either side of a random shared face (vertices given in different
  // orders), rays aimed at random points of the face: one tet's exit is the other's entry,
  // exactly, so no ray slips between them and none is counted twice.
  SplitMix64 rng(3);
  auto point = [&] { return Vec3d(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)) * 1e3 + Vec3d(1e4, -3e3, 7e2); };
  const double f[4] = {0, 1, 2, 3};
  int tested = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    const Vec3d a = point(), b = point(), c = point();
    const Vec3d n = normalize(cross(b - a, c - a));
    const Vec3d centre = (a + b + c) / 3.0;
    const Vec3d above = centre + n * rng.uniform(50, 500) + Vec3d(rng.uniform(-200, 200), rng.uniform(-200, 200), 0);
    const Vec3d below = centre - n * rng.uniform(50, 500) + Vec3d(0, rng.uniform(-200, 200), rng.uniform(-200, 200));
    if (!(dot(above - centre, n) > 1 && dot(below - centre, n) < -1)) continue;
    const Vec3d first[4] = {a, b, c, above}, second[4] = {c, below, a, b};  // the face in another order
    const TetGeometry t1(first, f), t2(second, f);
    // A point inside the face, and a ray through it from above to below.
    double u = rng.uniform(0.01, 0.98), v = rng.uniform(0.01, 0.98);
    if (u + v > 0.99) u = 0.99 - u, v = 0.99 - v;
    const Vec3d on_face = a + (b - a) * u + (c - a) * v;
    const Vec3d eye = on_face + (n * 3e3 + Vec3d(rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3)));
    const Vec3d d = normalize(on_face - eye);
    if (dot(d, n) > -0.05) continue;
    const Interval<double> s1 = t1.span(eye, d, 0, 1e9), s2 = t2.span(eye, d, 0, 1e9);
    if (!(s1.t0 <= s1.t1) || !(s2.t0 <= s2.t1)) continue;  // missed past a rim: not through the face
    EXPECT_EQ(s1.t1, s2.t0) << trial;
    ++tested;
  }
  EXPECT_GT(tested, 5000);
}

class TetReference : public ::testing::Test {
 protected:
  testing::TempDir dir_;
};

TEST_F(TetReference, ALinearFieldsIsosurfaceIsAnExactPlane) {
  const Vec3d a(1, 0.5, 0.25);
  build(lattice_mesh(6, 0.2, [&](const Vec3d& p) { return dot(a, p); }), dir_.file("linear.store"), 64);
  for (const char* camera : {R"({"eye": [1.9, -0.8, 1.6], "target": [0.5, 0.5, 0.5], "fov_degrees": 35})",
                             R"({"eye": [-0.7, 1.8, -0.9], "target": [0.45, 0.5, 0.55], "fov_degrees": 30})"}) {
    const Scene scene = tet_scene(dir_.file("linear.store"),
                                  std::string(R"("mode": "iso", "isosurfaces": [{"value": 0.9}], "camera": )") + camera);
    RenderSession session(scene);
    FrameBuffers fb;
    session.render(0, fb, {.depth = true, .normals = true});
    const ImageRays rays(session.camera(0), fb.width(), fb.height());
    int hits = 0;
    double worst = 0, worst_normal = 0;
    for (int y = 0; y < fb.height(); ++y)
      for (int x = 0; x < fb.width(); ++x) {
        if (!std::isfinite(fb.depth(x, y))) continue;
        ++hits;
        // Depth is stored in float: take the exact crossing along the same ray instead and
        // compare the distance between them with float's resolution.
        const Rayd r = rays.ray(x + 0.5, y + 0.5);
        const double t_exact = (0.9 - dot(a, r.org)) / dot(a, r.dir);
        worst = std::max(worst, std::abs(double(fb.depth(x, y)) - t_exact) / std::max(1.0, t_exact));
        const Vec3d n = Vec3d(fb.normal(x, y));
        worst_normal = std::max(worst_normal, 1 - std::abs(dot(n, normalize(a))));
      }
    EXPECT_GT(hits, fb.width() * fb.height() / 4) << camera;
    EXPECT_LT(worst, 2e-7) << camera;  // float depth; the crossing itself is exact (below)
    EXPECT_LT(worst_normal, 1e-6) << camera;
  }
}

TEST_F(TetReference, ALinearFieldsCrossingLiesOnThePlaneWithin1e9OfTheCell) {
  // Depth is stored in float: eyes 1e-3 from the plane, inside the mesh, make float's
  // rounding of the depth (6e-11) small against the bound, 1e-9 of a cell (2.5e-10 here).
  const Vec3d a(1, 0.5, 0.25);
  build(lattice_mesh(4, 0.2, [&](const Vec3d& p) { return dot(a, p); }), dir_.file("linear.store"), 64);
  const Scene scene = tet_scene(dir_.file("linear.store"), R"("mode": "iso", "isosurfaces": [{"value": 0.7}])", 1);
  RenderSession session(scene);
  SplitMix64 rng(11);
  int tested = 0;
  for (int trial = 0; trial < 1500; ++trial) {
    // A point of the plane inside the box, and a ray reaching it from 1e-3 away.
    Vec3d q(rng.uniform(0.05, 0.95), rng.uniform(0.05, 0.95), 0);
    q.z = (0.7 - a.x * q.x - a.y * q.y) / a.z;
    if (!(q.z > 0.05 && q.z < 0.95)) continue;
    const Vec3d d = normalize(Vec3d(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)));
    if (std::abs(dot(d, normalize(a))) < 0.2) continue;  // grazing: the crossing is ill-conditioned
    FrameSetup setup = session.setup(0, {.depth = true});
    setup.camera = Camera{q - d * 1e-3, q, std::abs(d.z) < 0.9 ? Vec3d(0, 0, 1) : Vec3d(1, 0, 0), 1e-3};
    setup.width = setup.height = 1;
    FrameBuffers fb;
    session.render(setup, fb);
    const Rayd r = ImageRays(setup.camera, 1, 1).ray(0.5, 0.5);
    const double t_exact = (0.7 - dot(a, r.org)) / dot(a, r.dir);
    ASSERT_TRUE(std::isfinite(fb.depth(0, 0))) << trial;
    EXPECT_NEAR(double(fb.depth(0, 0)), t_exact, 1e-9 * 0.25) << trial;
    ++tested;
  }
  EXPECT_GT(tested, 250);
}

TEST_F(TetReference, RaysThroughSharedVerticesEdgesAndFacesFindEveryCrossing) {
  // No jitter: the centre row and column of an axis-aligned view lie in planes of shared
  // faces, the centre pixel's ray runs along shared edges through shared vertices, and the
  // Kuhn diagonals put more rays through edges; a closed sphere must show no hole.
  build(lattice_mesh(8, 0.0, [](const Vec3d& p) { return length(p - Vec3d(0.5)); }), dir_.file("sphere.store"), 96);
  for (const char* camera : {R"({"eye": [0.5, 0.5, -2], "target": [0.5, 0.5, 0.5], "up": [0, 1, 0], "fov_degrees": 30})",
                             R"({"eye": [-2, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30})",
                             R"({"eye": [2.5, 2.5, 2.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 25})"}) {
    const FrameBuffers fb = render(tet_scene(dir_.file("sphere.store"),
                                             std::string(R"("mode": "iso", "isosurfaces": [{"value": 0.3}], "camera": )") + camera,
                                             129));
    EXPECT_EQ(pinholes(fb), 0) << camera;
    EXPECT_TRUE(std::isfinite(fb.depth(64, 64))) << camera;
    for (int i = 40; i <= 88; ++i) {
      EXPECT_TRUE(std::isfinite(fb.depth(i, 64))) << camera << " row pixel " << i;
      EXPECT_TRUE(std::isfinite(fb.depth(64, i))) << camera << " column pixel " << i;
    }
  }
}

TEST_F(TetReference, RaysLeavingAConcaveMeshFindItAgain) {
  // f = x on a 6^3 lattice without the cubes 2 <= i < 4 above the bottom layer: a ray along +x
  // at mid height leaves the mesh at x = 1/3 and enters it again at x = 2/3, before the
  // isosurface x = 0.8. Unused vertices are dropped by the store's clusters.
  build(lattice_mesh(6, 0.0, [](const Vec3d& p) { return p.x; }, 1, [](int i, int, int k) { return k == 0 || i < 2 || i >= 4; }),
        dir_.file("notch.store"), 64);
  const FrameBuffers fb = render(tet_scene(dir_.file("notch.store"),
                                           R"("mode": "iso", "isosurfaces": [{"value": 0.8}], "camera": {"eye": [-1, 0.5, 0.6],
                                              "target": [0.5, 0.5, 0.6], "up": [0, 0, 1], "fov_degrees": 10})",
                                           33));
  EXPECT_NEAR(fb.depth(16, 16), 1.8, 1e-6);
  // And the gap is empty: an isosurface in it is never hit where the mesh is missing.
  const FrameBuffers gap = render(tet_scene(dir_.file("notch.store"),
                                            R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "camera": {"eye": [-1, 0.5, 0.6],
                                               "target": [0.5, 0.5, 0.6], "up": [0, 0, 1], "fov_degrees": 10})",
                                            33));
  EXPECT_FALSE(std::isfinite(gap.depth(16, 16)));
}

TEST_F(TetReference, ASurfaceBetweenAnotherAndThePointLightIsInShadow) {
  // f = x with isosurfaces x = 0.3 and x = 0.7, the light on the axis beyond x = 0.7, the eye
  // before x = 0.3: the surface seen, x = 0.3, gets ambient light only when shadows are on.
  build(lattice_mesh(4, 0.1, [](const Vec3d& p) { return p.x; }), dir_.file("planes.store"), 64);
  auto centre = [&](bool shadows) {
    const std::string body = std::string(R"("mode": "iso", "isosurfaces": [{"value": 0.3, "color": [1, 1, 1]}, {"value": 0.7}],
        "camera": {"eye": [-1, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 10},
        "shading": {"light": "point", "light_position": [3, 0.5, 0.5], "specular": 0, "shadows": )") +
                             (shadows ? "true" : "false") + "}";
    return render(tet_scene(dir_.file("planes.store"), body, 17)).color(8, 8);
  };
  const Rgbaf lit = centre(false), shadowed = centre(true);
  EXPECT_NEAR(shadowed.r, 0.15f, 1e-6f);  // ambient
  EXPECT_NEAR(lit.r, 0.15f + 0.75f, 1e-3f);  // ambient + diffuse, the light head on
}

TEST_F(TetReference, HexahedraSplitIntoTetsShowNoCrackFromAnySide) {
  // Jittered hexahedra with their vertex numbering rotated from cell to cell, so that a rule
  // depending on a cell's own numbering would split shared faces differently.
  MeshData d;
  d.source = "hexes";
  const int n = 5;
  SplitMix64 rng(5);
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        const int g[3] = {i, j, k};
        for (int a = 0; a < 3; ++a) d.points.push_back((g[a] + (g[a] == 0 || g[a] == n ? 0 : 0.2 * rng.uniform(-1, 1))) / n);
      }
  PointArray f{"r", {}};
  for (size_t v = 0; v < d.point_count(); ++v)
    f.values.push_back(length(Vec3d(d.points[3 * v], d.points[3 * v + 1], d.points[3 * v + 2]) - Vec3d(0.5)));
  d.arrays.push_back(f);
  auto id = [&](int i, int j, int k) { return int64_t((k * (n + 1) + j) * (n + 1) + i); };
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        int64_t c[8] = {id(i, j, k),         id(i + 1, j, k),         id(i + 1, j + 1, k),     id(i, j + 1, k),
                        id(i, j, k + 1),     id(i + 1, j, k + 1),     id(i + 1, j + 1, k + 1), id(i, j + 1, k + 1)};
        const int r = (i + 2 * j + 3 * k) % 4;  // rotate bottom and top quads alike
        int64_t q[8];
        for (int v = 0; v < 4; ++v) q[v] = c[(v + r) % 4], q[4 + v] = c[4 + (v + r) % 4];
        d.add_cell(MeshCellType::hexahedron, {q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7]});
      }
  TetMesh mesh = tetrahedralize(std::move(d), {});
  EXPECT_EQ(mesh.report.split.at("hexahedron"), uint64_t(n * n * n));
  EXPECT_EQ(mesh.tet_count(), uint64_t(12 * n * n * n));
  EXPECT_EQ(mesh.report.centre_points, uint64_t(n * n * n));
  build(std::move(mesh), dir_.file("hex.store"), 128);
  const char* cameras[] = {R"({"eye": [0.5, 0.5, -2], "target": [0.5, 0.5, 0.5], "up": [0, 1, 0], "fov_degrees": 30})",
                           R"({"eye": [0.5, 0.5, 3], "target": [0.5, 0.5, 0.5], "up": [0, 1, 0], "fov_degrees": 30})",
                           R"({"eye": [-2, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30})",
                           R"({"eye": [3, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30})",
                           R"({"eye": [0.5, -2, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30})",
                           R"({"eye": [0.5, 3, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30})"};
  for (const char* camera : cameras) {
    const FrameBuffers fb = render(tet_scene(dir_.file("hex.store"),
                                             std::string(R"("mode": "iso", "isosurfaces": [{"value": 0.35}], "camera": )") + camera,
                                             97));
    EXPECT_EQ(pinholes(fb), 0) << camera;
    EXPECT_TRUE(std::isfinite(fb.depth(48, 48))) << camera;
  }
}

TEST_F(TetReference, ClustersRenderIdenticallyToOneCluster) {
  auto f = [](const Vec3d& p) { return std::sin(6 * p.x) * std::cos(5 * p.y) + p.z; };
  build(lattice_mesh(6, 0.15, f), dir_.file("one.store"), 6 * 6 * 6 * 6);
  build(lattice_mesh(6, 0.15, f), dir_.file("many.store"), 64);
  for (const char* mode : {R"("mode": "iso", "isosurfaces": [{"value": 0.5}, {"value": 0.9, "color": [1, 0, 0]}],
                              "shading": {"light": "point", "light_position": [1.5, -0.5, 2], "shadows": true})",
                           R"("mode": "dvr", "transfer_function": {"points": [{"value": 0, "opacity": 0},
                              {"value": 1, "color": [1, 0.5, 0], "opacity": 0.4}, {"value": 1.8, "opacity": 0.9}]})",
                           R"("mode": "mip")"}) {
    const FrameBuffers one = render(tet_scene(dir_.file("one.store"), mode, 48));
    const FrameBuffers many = render(tet_scene(dir_.file("many.store"), mode, 48));
    int differ = 0;
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 48; ++x) {
        const Rgbaf a = one.color(x, y), b = many.color(x, y);
        differ += std::abs(a.r - b.r) > 1e-6f || std::abs(a.g - b.g) > 1e-6f || std::abs(a.a - b.a) > 1e-6f;
      }
    EXPECT_EQ(differ, 0) << mode;
  }
}

TEST_F(TetReference, TimeStepsSelectTheirScalars) {
  // f = x moved by 1/8 per step: the isosurface x = 0.4 + s / 8, seen head on along +x.
  build(lattice_mesh(4, 0.1, [](const Vec3d& p) { return p.x; }, 3), dir_.file("steps.store"), 64);
  double depth[3];
  for (int s = 0; s < 3; ++s) {
    const Scene scene = tet_scene(dir_.file("steps.store"),
                                  R"("mode": "iso", "isosurfaces": [{"value": 0.4}], "time_step": )" + std::to_string(s) +
                                      R"(, "camera": {"eye": [-1, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 20})",
                                  33);
    depth[s] = render(scene).depth(16, 16);
  }
  EXPECT_NEAR(depth[0], 1.4, 1e-6);
  EXPECT_NEAR(depth[1] - depth[0], 0.125, 1e-6);
  EXPECT_NEAR(depth[2] - depth[0], 0.25, 1e-6);
  EXPECT_THROW(RenderSession(tet_scene(dir_.file("steps.store"), R"("mode": "mip", "time_step": 3)")), Error);
}

TEST_F(TetReference, MovingVerticesMoveTheSurfaceWithThem) {
  // The mesh of f = x translated by 1/4 along x in step 1 (its values unchanged): the
  // isosurface moves with it.
  TetMesh m = lattice_mesh(4, 0.1, [](const Vec3d& p) { return p.x; }, 2);
  m.scalars[1] = m.scalars[0];
  m.step_positions.push_back(m.positions);
  for (size_t v = 0; v < m.vertex_count(); ++v) m.step_positions[0][3 * v] += 0.25f;
  build(std::move(m), dir_.file("moving.store"), 64);
  EXPECT_TRUE(Store(dir_.file("moving.store")).manifest().mesh.moving);
  double depth[2];
  for (int s = 0; s < 2; ++s)
    depth[s] = render(tet_scene(dir_.file("moving.store"),
                                R"("mode": "iso", "isosurfaces": [{"value": 0.4}], "time_step": )" + std::to_string(s) +
                                    R"(, "camera": {"eye": [-1, 0.5, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 20})",
                                33))
                   .depth(16, 16);
  // The world box spans both steps ([0, 1.25] in x): the camera sits 1 / 0.8 box widths out.
  EXPECT_NEAR(depth[1] - depth[0], 0.25, 1e-6);
}

TEST_F(TetReference, DvrAndMipMatchTheirIntegrals) {
  build(lattice_mesh(4, 0.2, [](const Vec3d& p) { return p.x + 0.5 * p.y; }), dir_.file("ramp.store"), 64);
  // Constant opacity a per unit length u = cbrt(1 / tets): transmittance (1 - a)^(L / u).
  const Scene dvr = tet_scene(dir_.file("ramp.store"),
                              R"("mode": "dvr", "shading": {"light": "none"}, "transfer_function": {"points": [
                                 {"value": -1, "color": [1, 1, 1], "opacity": 0.05}, {"value": 3, "color": [1, 1, 1], "opacity": 0.05}]},
                                 "camera": {"eye": [0.5, 0.5, -2], "target": [0.5, 0.5, 0.5], "up": [0, 1, 0], "fov_degrees": 20})",
                              33);
  const FrameBuffers fb = render(dvr);
  const double unit = std::cbrt(1.0 / (6 * 64));
  EXPECT_NEAR(fb.color(16, 16).a, 1 - std::pow(0.95, 1.0 / unit), 2e-6);
  // MIP along +z through (0.5, 0.5): the ramp is constant along z, 0.75.
  const Scene mip = tet_scene(dir_.file("ramp.store"),
                              R"("mode": "mip", "camera": {"eye": [0.5, 0.5, -2], "target": [0.5, 0.5, 0.5], "up": [0, 1, 0], "fov_degrees": 20})", 33);
  RenderSession session(mip);
  FrameBuffers m;
  session.render(0, m, {.depth = true});
  // Grey over the store's range [0, 1.5].
  EXPECT_NEAR(m.color(16, 16).r, 0.75 / 1.5, 1e-6);
}

TEST_F(TetReference, ReadsOnlyTheClustersThatCanContribute) {
  // Isovalue 0.05 of f = x: only the clusters at the low-x end hold it.
  build(lattice_mesh(8, 0.0, [](const Vec3d& p) { return p.x; }), dir_.file("ramp.store"), 64);
  Store store(dir_.file("ramp.store"));
  uint64_t holding = 0;
  for (const TetCluster& c : store.clusters()) holding += c.min <= 0.05f && c.max >= 0.05f;
  ASSERT_LE(holding, store.clusters().size() / 4);
  RenderSession session(tet_scene(dir_.file("ramp.store"), R"("mode": "iso", "isosurfaces": [{"value": 0.05}])", 64));
  FrameBuffers fb;
  session.render(0, fb, {.depth = true});
  const CacheStats s = session.pages().stats(RecordKind::tet_cluster);
  EXPECT_GT(s.l3.hits, 0u);
  EXPECT_LE(s.l3.hits, holding);
}

}  // namespace
}  // namespace brickyard
