#pragma once
/// @file renderer.h
/// @brief tet_bvh: coherent ray tracing of tetrahedral isosurfaces (Wald, Friedrich, Knoll and
/// Hansen) on brickyard's cache.
///
/// - A top-level BVH over the cluster table (bounds and the frame's time step's value range)
///   ties the clusters together; a cluster's own 4D BVH (bvh.h) is built the first time its
///   page is resident, and kept beside the cache within a memory budget. When the time step
///   changes the top BVH is refitted, and each cluster's BVH is refitted when a packet next
///   reaches it (the clusters are the subtrees, refitted in parallel by the tiles), or one BVH
///   per step is kept (bvh_per_step=1).
/// - Packets of packet x packet rays (16 x 16, a tile, by default; 1: single rays) traverse
///   both: the implicit test first (a node's value range against every isovalue at once), the
///   first active ray's box test speculatively, then the packet's frustum by interval
///   arithmetic, then the rays after the first active one until one hits.
/// - In a leaf each tet's own range is tested, then its isopolygon extracted by the 16-case
///   marching-tets table and tested against the packet: the four corner rays cull a packet
///   that misses it whole (full miss) or find one that needs no edge test (full hit); else
///   each ray's edge tests. Edge planes are computed from the polygon's vertices in canonical
///   order, and the polygon's vertices from their tet edges' ends in canonical order, so
///   neighbouring polygons share their edges to the bit and no ray slips between them.
/// - Clusters are asked for through the cache only when a packet reaches them (bounds met,
///   an isovalue in range); a frame draws what is resident and converges as clusters arrive;
///   exact=1 renders the rest of the frame again once they have (passes).
///
/// Files: bvh.{h,cpp} (the BVH), packets.cpp (traversal, isopolygons), shade.cpp (layers,
/// shadows, shading), tet_bvh.cpp (parameters, the cluster cache, frames, registration).

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "renderers/common/params.h"
#include "renderers/common/pixel.h"
#include "renderers/common/render.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"
#include "dataset/tet_bvh.h"

namespace brickyard::tet_bvh {

struct Params {
  int packet{};
  bool sah{};
  int leaf_size{};
  bool exact{};
  int max_passes{};
  int layers{};
  double layer_opacity{};
  double bvh_cache_mib{};
  bool bvh_per_step{};
  bool stored_bvh{};
  bool corner_culling{};
};
const ParamTable<Params>& params_table();

/// Per-frame figures, summed over tiles (the paper's Table 4 and the cache's side).
struct Counters {
  std::atomic<uint64_t> packet_box_tests{0}, ray_box_tests{0}, isorange_tests{0}, extractions{0}, ray_polygon_tests{0},
      full_miss_rays{0}, full_hit_rays{0}, footprint_culled_rays{0}, footprint_culled_box_rays{0}, clusters_touched{0},
      clusters_missing{0}, bvh_builds{0}, bvh_build_ns{0}, bvh_refits{0}, bvh_refit_ns{0}, bvh_loads{0}, bvh_load_ns{0};
  void reset();
};

/// The largest packet: a tile.
inline constexpr int kMaxLanes = 256;

class TetBvhRenderer;

/// A packet of rays sharing an origin (the eye, or a point light for shadow rays), or single
/// rays each with its own (packet of one).
struct Packet {
  int lanes = 0;
  Vec3d origin;              ///< shared origin
  double dx[kMaxLanes], dy[kMaxLanes], dz[kMaxLanes];
  double ix[kMaxLanes], iy[kMaxLanes], iz[kMaxLanes];  ///< 1 / direction, set by prepare()
  double tmin[kMaxLanes], tmax[kMaxLanes];
  double hit_t[kMaxLanes];
  double t_miss[kMaxLanes];  ///< where the ray first entered a cluster that was not resident
  int hit_surface[kMaxLanes];
  double gx[kMaxLanes], gy[kMaxLanes], gz[kMaxLanes];  ///< gradient of the tet hit
  bool active[kMaxLanes];
  bool any_hit = false;      ///< shadow rays: a lane stops at its first hit
  int corners[4] = {-1, -1, -1, -1};  ///< lanes of the packet's corner rays (-1: no corner culling)
  // Primary packets: lane l is the ray through pixel (x0 + l % w, y0 + l / w) of `image`, so
  // the lanes that can see a box or a polygon are the pixels its projection covers.
  const ImageRays* image = nullptr;
  int x0 = 0, y0 = 0, w = 0;
  // Frustum: the direction's bounds over the active lanes.
  double dlo[3], dhi[3];
  double t_lo = 0, t_hi = 0;  ///< bounds of tmin and of min(tmax, hit_t) over the active lanes

  Vec3d dir(int l) const { return {dx[l], dy[l], dz[l]}; }
  void prepare();  ///< computes the inverse directions, and the frustum from the active lanes
  double limit(int l) const { return std::min(tmax[l], hit_t[l]); }
};

class TetBvhRenderer final : public Renderer {
 public:
  TetBvhRenderer(const RenderContext& ctx, const Params& p);

  void begin_frame(const FrameSetup& setup) override;
  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override;
  void end_frame(const FrameSetup& setup, const FrameBuffers& out) override;
  bool another_pass() override;
  bool converged() const override { return last_missing_ == 0 || stalled_frames_ >= 3; }
  void set_complete_frames(bool complete) override { complete_frames_ = complete; }
  void add_statistics(FrameStats& stats) const override;

  /// Traces a packet through every cluster it reaches (packets.cpp); returns how many of
  /// those were not resident (asked for, and skipped).
  uint64_t trace(Packet& p, RayCounters& counters) const;
  /// The tile being rendered (for exact passes' requests), per thread.
  static thread_local uint32_t current_tile;

 private:
  struct CachedBvh {
    std::shared_ptr<const ClusterBvh> bvh;
    uint64_t last_frame = 0;
  };
  /// The cluster's BVH for the frame's step: cached, refitted from another step's, or built.
  std::shared_ptr<const ClusterBvh> cluster_bvh(uint64_t cluster, const TetClusterPage& page) const;
  /// The frame's time step: the clusters' value ranges for it, the top BVH refitted to them.
  void set_step(uint32_t step);
  void note_missing(uint32_t cluster, float priority, uint32_t tile) const;
  void trace_cluster(Packet& p, const TetClusterPage& page, const ClusterBvh& bvh, int first, RayCounters& counters) const;
  void leaf(Packet& p, const TetClusterPage& page, const ClusterBvh& bvh, const BvhNode& node, int first) const;
  /// Traces a packet's layers, shades and writes the pixels it finished (shade.cpp); false
  /// when some lane met a missing cluster.
  bool shade_packet(const FrameSetup& setup, Packet& p, const int* px, const int* py, FrameBuffers& out,
                    RayCounters& counters) const;
  /// Whether lane l's hit is in shadow (`certain`: no missing cluster could hide an occluder).
  void shadows(const Packet& p, const bool* lit, bool* shadowed, bool* certain, RayCounters& counters) const;
  bool render_packet(const FrameSetup& setup, const ImageRays& rays, int x0, int y0, int x1, int y1, FrameBuffers& out,
                     RayCounters& counters) const;

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  const TetView& tets_;
  Params p_;
  ShadingModel shading_;
  uint32_t step_ = 0;
  std::vector<double> iso_;
  float iso_lo_ = 0, iso_hi_ = 0;
  Box3d clip_;
  BoxBvh top_;
  std::vector<Bounds4> cluster_bounds_;
  size_t bvh_budget_ = 0;

  mutable std::mutex cache_mutex_;
  mutable std::unordered_map<uint64_t, CachedBvh> bvhs_;
  mutable size_t bvh_bytes_ = 0;
  mutable Counters counters_;

  uint64_t frame_ = 0;
  int passes_ = 0;
  bool complete_frames_ = false, frame_exact_ = false;
  uint64_t last_missing_ = 0, last_pass_missing_ = 0;
  int stalled_frames_ = 0;
  std::vector<uint8_t> tile_done_;  // exact passes: tiles that needed nothing missing
  int tiles_x_ = 0;
  // Written by the tiles, each its own entries: whether a tile met a missing cluster, and per
  // pixel whether it is finished and from where an exact pass resumes its ray.
  mutable std::vector<uint8_t> tile_missed_, pixel_done_;
  mutable std::vector<double> resume_t_;
  int state_width_ = 0;  ///< the image width pixel_done_ and resume_t_ are laid out for
  /// Where pixel (x, y)'s state lies: tile by tile, so that a packet's is contiguous.
  size_t pixel_slot(int x, int y) const {
    const size_t tile = size_t(y / kTileSize) * size_t(tiles_x_) + size_t(x / kTileSize);
    return tile * size_t(kTileSize * kTileSize) + size_t(y % kTileSize) * kTileSize + size_t(x % kTileSize);
  }
  mutable std::atomic<uint64_t> unfinished_{0};
  // Exact frames: the clusters a pass found missing, with the highest priority asked, and
  // the first tile (in tile order) that missed each.
  struct Missing {
    float priority = 0;
    uint32_t tile = UINT32_MAX;
  };
  mutable std::mutex missing_mutex_;
  mutable std::unordered_map<uint32_t, Missing> missing_;
  // Exact frames whose pass made no progress (an L1 smaller than what the unfinished tiles
  // need together) render one tile at a time until it is done: this one.
  uint32_t focus_tile_ = UINT32_MAX;
  uint64_t previous_unfinished_ = 0;
};

}  // namespace brickyard::tet_bvh
