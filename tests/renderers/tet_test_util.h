#pragma once
// Helpers shared by the tetrahedral back ends' tests: jittered lattice meshes with known
// fields, stores made from them, scenes over them, and the pinhole count of an image.

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "fields/random.h"
#include "preprocess/mesh_data.h"
#include "preprocess/tet_builder.h"
#include "renderers/common/scene.h"
#include "session/render_session.h"

namespace brickyard::testing {

/// A jittered grid of n^3 cubes on [0, 1]^3, 6 Kuhn tets each, with positions on a 1/4096
/// lattice so that a linear field with dyadic coefficients is exact in float at every vertex.
inline TetMesh lattice_mesh(int n, double jitter, const std::function<double(const Vec3d&)>& f, int steps = 1,
                     const std::function<bool(int, int, int)>& keep_cube = {}) {
  TetMesh m;
  SplitMix64 rng(7);
  auto index = [&](int i, int j, int k) { return uint32_t((k * (n + 1) + j) * (n + 1) + i); };
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        const int g[3] = {i, j, k};
        for (int a = 0; a < 3; ++a) {
          const double u = rng.uniform(-1, 1);
          const bool face = g[a] == 0 || g[a] == n;
          const double x = (g[a] + (face ? 0 : jitter * u)) / n;
          m.positions.push_back(float(std::round(x * 4096) / 4096));
        }
      }
  m.scalars.resize(size_t(steps));
  for (int s = 0; s < steps; ++s)
    for (size_t v = 0; v < m.vertex_count(); ++v) {
      const Vec3d p(m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]);
      m.scalars[size_t(s)].push_back(float(f(p - Vec3d(0.125 * s, 0, 0))));
    }
  static constexpr int kKuhn[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (const auto& t : kKuhn) {
          if (keep_cube && !keep_cube(i, j, k)) break;
          uint32_t q[4];
          for (int c = 0; c < 4; ++c) q[c] = index(i + (t[c] & 1), j + (t[c] >> 1 & 1), k + (t[c] >> 2 & 1));
          auto at = [&](uint32_t v) { return Vec3d(m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]); };
          if (tet_volume6(at(q[0]), at(q[1]), at(q[2]), at(q[3])) < 0) std::swap(q[2], q[3]);
          m.tets.insert(m.tets.end(), q, q + 4);
        }
  m.array_name = "f";
  for (int s = 0; s < steps; ++s) m.step_names.push_back("f_" + std::to_string(s));
  return m;
}

inline void build(TetMesh mesh, const std::string& dir, uint32_t cluster_tets, bool store_bvh = false) {
  auto source = partition_mesh(std::move(mesh), cluster_tets, "test mesh", R"({"kind": "test"})", 0);
  TetBuildOptions o;
  o.cluster_tets = cluster_tets;
  o.store_bvh = store_bvh;
  build_tet_store(*source, dir, o);
}

inline Scene tet_scene(const std::string& store, const std::string& body, int size = 64,
                       const std::string& backend = "reference") {
  const std::string camera = body.find("\"camera\"") == std::string::npos
                                 ? R"(, "camera": {"eye": [1.9, -1.1, 1.5], "target": [0.5, 0.5, 0.5], "fov_degrees": 35})"
                                 : "";
  return parse_scene(R"({"dataset": ")" + store + R"(", "backend": ")" + backend + R"(", "image": {"width": )" +
                         std::to_string(size) + R"(, "height": )" + std::to_string(size) + "}, " + body + camera + "}",
                     "");
}

inline FrameBuffers render(const Scene& scene, FrameStats* stats = nullptr) {
  RenderSession session(scene);
  FrameBuffers fb;
  const FrameStats s = session.render(0, fb, {.depth = true, .normals = true});
  if (stats) *stats = s;
  return fb;
}

/// Pixels that miss while all four neighbours hit: holes in a surface that covers them.
inline int pinholes(const FrameBuffers& fb) {
  int holes = 0;
  for (int y = 1; y + 1 < fb.height(); ++y)
    for (int x = 1; x + 1 < fb.width(); ++x)
      holes += !std::isfinite(fb.depth(x, y)) && std::isfinite(fb.depth(x - 1, y)) && std::isfinite(fb.depth(x + 1, y)) &&
               std::isfinite(fb.depth(x, y - 1)) && std::isfinite(fb.depth(x, y + 1));
  return holes;
}

}  // namespace brickyard::testing
