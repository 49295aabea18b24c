#pragma once
// A minimal tetrahedral dataset and a back end for it, shared by the session tests and the
// test module (tet_probe_module.cpp): enough to open the tetrahedral kind through the same
// path as grids (store -> page cache -> back end), until the mesh importer exists.
//
// The store: `clusters` unit cubes in a row along x, cube i = [i, i+1] x [0,1] x [0,1], each
// split into its 6 Kuhn tetrahedra (one cluster per cube); the scalar at a vertex is its x.
// The back end `tet-probe`: for every pixel, the largest scalar of the clusters whose bounds
// its ray meets, read from the cluster pages through the cache (blocking fetches), drawn as
// grey over the dataset's value range (a MIP over clusters: exact, and easy to check).

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "dataset/tet.h"
#include "renderers/common/pixel.h"
#include "renderers/common/renderer.h"

#ifndef BRICKYARD_TET_FIXTURE_NO_STORE
#include "storage/store.h"
#endif

namespace brickyard::testing {

#ifndef BRICKYARD_TET_FIXTURE_NO_STORE
inline void write_tet_store(const std::string& dir, int clusters) {
  static constexpr std::array<std::array<uint32_t, 4>, 6> kKuhn = {
      {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}}};
  Manifest m;
  m.kind = DataKind::tetrahedral;
  m.source = R"({"kind": "test", "clusters": )" + std::to_string(clusters) + "}";
  m.min_value = 0;
  m.max_value = clusters;
  m.mesh.bounds = Box3d(Vec3d(0.0), Vec3d(clusters, 1, 1));
  m.mesh.clusters = uint64_t(clusters);
  m.mesh.tets = 6 * uint64_t(clusters);
  m.mesh.vertices = 8 * uint64_t(clusters);
  m.mesh.page_bytes = TetClusterPage::bytes(8, 6);
  lmdb::EnvOptions env;
  env.map_size = uint64_t(16) << 20;
  StoreWriter writer(dir, m, env);
  std::vector<TetCluster> table;
  for (int c = 0; c < clusters; ++c) {
    std::vector<float> positions, values;
    for (uint32_t v = 0; v < 8; ++v) {
      const float x = float(c) + float(v & 1), y = float((v >> 1) & 1), z = float((v >> 2) & 1);
      positions.insert(positions.end(), {x, y, z});
      values.push_back(x);
    }
    std::vector<uint32_t> corners;
    for (auto t : kKuhn) {  // positively oriented, as stores keep them
      auto at = [&](uint32_t v) { return Vec3d(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]); };
      if (dot(cross(at(t[1]) - at(t[0]), at(t[2]) - at(t[0])), at(t[3]) - at(t[0])) < 0) std::swap(t[2], t[3]);
      corners.insert(corners.end(), t.begin(), t.end());
    }
    writer.put_cluster(uint64_t(c), TetClusterPage::encode(positions, values, corners));
    TetCluster e;
    e.lo[0] = float(c), e.hi[0] = float(c + 1), e.hi[1] = 1, e.hi[2] = 1;
    e.min = float(c), e.max = float(c + 1);
    e.tets = 6, e.vertices = 8;
    table.push_back(e);
  }
  writer.finish(m, table);
}
#endif

class TetProbe final : public Renderer {
 public:
  explicit TetProbe(const RenderContext& ctx) : ctx_(ctx), tets_(ctx.tets()) {}

  void render_tile(const FrameSetup& s, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    const ImageRays rays(s.camera, s.width, s.height);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) {
        const Rayd ray = rays.ray(x + 0.5, y + 0.5);
        ++counters.rays;
        float best = -std::numeric_limits<float>::infinity();
        double nearest = std::numeric_limits<double>::infinity();
        const auto clusters = tets_.clusters();
        for (size_t c = 0; c < clusters.size(); ++c) {
          const Interval<double> span = intersect(ray, clusters[c].bounds());
          if (span.empty() || span.t1 < 0) continue;
          const PageHandle page = ctx_.pages().fetch({RecordKind::tet_cluster, c});
          ++counters.bricks;
          const TetClusterPage p = TetClusterPage::view({page.bytes(), tets_.page_bytes()});
          for (uint32_t v = 0; v < p.vertex_count; ++v) best = std::max(best, p.values[v]);
          nearest = std::min(nearest, std::max(span.t0, 0.0));
        }
        PixelResult r;
        if (std::isfinite(best)) {
          mip_color(ctx_, best, r);
          r.depth = nearest;
        }
        write_pixel(out, x, y, r);
      }
  }

 private:
  const RenderContext& ctx_;
  const TetView& tets_;
};

inline BackendEntry tet_probe_backend() {
  BackendEntry e;
  e.info.name = "tet-probe";
  e.info.description = "test back end: the largest scalar of the clusters a ray's box test meets, through the cache";
  e.info.kinds = {DataKind::tetrahedral};
  e.info.modes = {RenderMode::mip};
  e.create = [](const RenderContext& ctx, const BackendParams&) -> std::unique_ptr<Renderer> {
    return std::make_unique<TetProbe>(ctx);
  };
  return e;
}

}  // namespace brickyard::testing
