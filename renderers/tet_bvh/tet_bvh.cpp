// tet_bvh's parameters, its cluster BVH cache, frames and passes, and its registration; the
// parts are listed in renderer.h.

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "core/error.h"
#include "core/timing.h"
#include "renderers/common/render.h"
#include "renderers/tet_bvh/renderer.h"

namespace brickyard {
namespace tet_bvh {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}

const ParamTable<Params>& params_table() {
  static const ParamTable<Params> table{
      {"packet", &Params::packet, 16, 1, 16, "packets of packet x packet rays traverse together (2, 4, 8 or 16); 1: single rays"},
      {"sah", &Params::sah, 0, 0, 1, "1: cluster BVHs built by the surface-area heuristic; 0: by the spatial median (BIH-style)"},
      {"leaf_size", &Params::leaf_size, 12, 1, 64, "the most tets a BVH leaf holds"},
      {"exact", &Params::exact, 0, 0, 1,
       "1: a frame waits for the clusters it needs (passes that resume each ray where it met a missing one); 0: it draws "
       "what is resident and converges over frames"},
      {"max_passes", &Params::max_passes, 256, 1, 100000, "exact frames: passes at most"},
      {"layers", &Params::layers, 1, 1, 16, "transparent depth peeling: surface layers composited along each ray; 1: opaque"},
      {"layer_opacity", &Params::layer_opacity, 0.5, 0.01, 1.0, "layers > 1: the opacity of each layer"},
      {"bvh_cache", &Params::bvh_cache_mib, 0, 0, 1 << 20,
       "MiB of cluster BVHs kept beside the cache (the least recently used are dropped, and rebuilt when needed); 0: "
       "one and a half times the L1 budget, room for the BVHs of every cluster L1 holds"},
      {"stored_bvh", &Params::stored_bvh, 1, 0, 1,
       "1: a cluster's BVH stored by the importer (import --bvh) is read instead of built, when it was built as sah and "
       "leaf_size say; 0: always built when the cluster arrives"},
      {"bvh_per_step", &Params::bvh_per_step, 0, 0, 1,
       "time-varying meshes: 1: a cluster BVH built for each time step drawn (kept while the BVH cache holds them); 0: one "
       "BVH per cluster, refitted when the step changes (moved vertices, new values)"},
      {"corner_culling", &Params::corner_culling, 1, 0, 1,
       "1: a packet's four corner rays cull an isopolygon all its rays miss, and spare the edge tests of one they all hit; "
       "0: every ray's edge tests"},
  };
  return table;
}

void Counters::reset() {
  for (auto* c : {&packet_box_tests, &ray_box_tests, &isorange_tests, &extractions, &ray_polygon_tests, &full_miss_rays,
                  &full_hit_rays, &footprint_culled_rays, &footprint_culled_box_rays, &clusters_touched, &clusters_missing,
                  &bvh_builds, &bvh_build_ns, &bvh_refits, &bvh_refit_ns, &bvh_loads, &bvh_load_ns})
    c->store(0, std::memory_order_relaxed);
}

TetBvhRenderer::TetBvhRenderer(const RenderContext& ctx, const Params& p)
    : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), tets_(ctx.tets()), p_(p), shading_(scene_.shading, geo_) {
  for (const Isosurface& s : scene_.isosurfaces) iso_.push_back(s.value);
  clip_ = Box3d(geo_.to_world(geo_.voxel_clip.lo), geo_.to_world(geo_.voxel_clip.hi));
  // A BVH takes about as many bytes as its cluster's page (40-byte nodes, a slot and a range
  // per tet): evicting the BVH of a cluster still in L1 would rebuild it every frame.
  const size_t l1_bytes = ctx_.pages().pool_slots(RecordKind::tet_cluster) * tets_.page_bytes();
  bvh_budget_ = p_.bvh_cache_mib > 0 ? size_t(p_.bvh_cache_mib * double(1 << 20)) : l1_bytes + l1_bytes / 2;
}

void TetBvhRenderer::set_step(uint32_t step) {
  // The top BVH's topology comes from the clusters' boxes, which cover every step; a new step
  // changes only the value ranges, so a refit gives what a rebuild would.
  const auto clusters = tets_.clusters();
  const bool first = cluster_bounds_.empty() && !clusters.empty();
  cluster_bounds_.resize(clusters.size());
  for (size_t c = 0; c < clusters.size(); ++c) {
    Bounds4& b = cluster_bounds_[c];
    const TetStepRange r = tets_.range(c, int(step));
    for (int a = 0; a < 3; ++a) b.lo[a] = clusters[c].lo[a], b.hi[a] = clusters[c].hi[a];
    b.lo[3] = r.min, b.hi[3] = r.max;
  }
  if (first) {
    top_ = build_bvh(cluster_bounds_, BuildMethod::bih, 1);
  } else {
    std::vector<Bounds4> slots(top_.order.size());
    for (size_t s = 0; s < slots.size(); ++s) slots[s] = cluster_bounds_[top_.order[s]];
    refit_bvh(top_, slots.data());
  }
  step_ = step;
}

std::shared_ptr<const ClusterBvh> TetBvhRenderer::cluster_bvh(uint64_t cluster, const TetClusterPage& page) const {
  // Per-step BVHs are cached by (cluster, step); refitted ones by cluster, for the step they
  // were last refitted to.
  const uint64_t key = p_.bvh_per_step ? cluster * uint64_t(tets_.time_steps()) + step_ : cluster;
  std::shared_ptr<const ClusterBvh> stale;
  {
    std::lock_guard lock(cache_mutex_);
    if (auto it = bvhs_.find(key); it != bvhs_.end()) {
      it->second.last_frame = frame_;
      if (it->second.bvh->step == step_) return it->second.bvh;
      stale = it->second.bvh;
    }
  }
  // Built or refitted outside the lock: two tiles may do the same cluster at once; the second
  // copy is dropped.
  Stopwatch watch;
  std::shared_ptr<const ClusterBvh> built;
  if (stale) {
    if (std::optional<ClusterBvh> refitted = stale->refit(page, step_)) {
      built = std::make_shared<const ClusterBvh>(std::move(*refitted));
      counters_.bvh_refits.fetch_add(1, std::memory_order_relaxed);
      counters_.bvh_refit_ns.fetch_add(uint64_t(watch.nanoseconds()), std::memory_order_relaxed);
    }
  }
  const BuildMethod method = p_.sah ? BuildMethod::sah : BuildMethod::bih;
  if (!built && p_.stored_bvh) {
    // A BVH the importer stored (step 0's, if it was built as this frame would build it): read
    // instead of built, and refitted for another step unless each step gets its own.
    std::optional<ClusterBvh> stored;
    try {
      stored = ClusterBvh::stored(page, method, uint32_t(p_.leaf_size));
    } catch (Error& e) {
      throw e.with_file(ctx_.dataset().name).with_key(fmt::format("cluster {}", cluster));
    }
    if (stored && step_ != 0) stored = p_.bvh_per_step ? std::nullopt : stored->refit(page, step_);
    if (stored) {
      built = std::make_shared<const ClusterBvh>(std::move(*stored));
      counters_.bvh_loads.fetch_add(1, std::memory_order_relaxed);
      counters_.bvh_load_ns.fetch_add(uint64_t(watch.nanoseconds()), std::memory_order_relaxed);
    }
  }
  if (!built) {
    built = std::make_shared<const ClusterBvh>(ClusterBvh::build(page, step_, method, uint32_t(p_.leaf_size)));
    counters_.bvh_builds.fetch_add(1, std::memory_order_relaxed);
    counters_.bvh_build_ns.fetch_add(uint64_t(watch.nanoseconds()), std::memory_order_relaxed);
  }
  std::lock_guard lock(cache_mutex_);
  auto [it, added] = bvhs_.try_emplace(key, CachedBvh{built, frame_});
  if (!added) {
    if (it->second.bvh->step == step_) return it->second.bvh;
    bvh_bytes_ -= it->second.bvh->bytes();
    it->second.bvh = built;
  }
  bvh_bytes_ += built->bytes();
  while (bvh_bytes_ > bvh_budget_ && bvhs_.size() > 1) {
    auto oldest = bvhs_.end();
    for (auto e = bvhs_.begin(); e != bvhs_.end(); ++e)
      if (e->first != key && (oldest == bvhs_.end() || e->second.last_frame < oldest->second.last_frame)) oldest = e;
    bvh_bytes_ -= oldest->second.bvh->bytes();
    bvhs_.erase(oldest);  // a tile still tracing it keeps its copy alive
  }
  return built;
}

void TetBvhRenderer::note_missing(uint32_t cluster, float priority, uint32_t tile) const {
  std::lock_guard lock(missing_mutex_);
  Missing& m = missing_[cluster];
  m.priority = std::max(m.priority, priority);
  m.tile = std::min(m.tile, tile);
}

void TetBvhRenderer::begin_frame(const FrameSetup& setup) {
  ++frame_;
  counters_.reset();
  if (cluster_bounds_.empty() || uint32_t(setup.time_step) != step_) set_step(uint32_t(setup.time_step));
  frame_exact_ = p_.exact || complete_frames_;
  passes_ = 0;
  tiles_x_ = (setup.width + kTileSize - 1) / kTileSize;
  const size_t tiles = size_t(tiles_x_) * size_t((setup.height + kTileSize - 1) / kTileSize);
  tile_done_.assign(tiles, 0);
  tile_missed_.assign(tiles, 0);
  // Tile-major per-pixel state, written by every pixel in the first pass (so never cleared);
  // the slots of edge tiles past the image stay done.
  const size_t slots = tiles * size_t(kTileSize * kTileSize);
  if (pixel_done_.size() != slots || state_width_ != setup.width)  // a new layout: slots past the image done
    pixel_done_.assign(slots, 1), resume_t_.assign(slots, -1.0), state_width_ = setup.width;
  unfinished_.store(0, std::memory_order_relaxed);
  missing_.clear();
  focus_tile_ = UINT32_MAX;
  previous_unfinished_ = UINT64_MAX;
}

void TetBvhRenderer::render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const {
  const size_t index = size_t(tile.y0 / kTileSize) * size_t(tiles_x_) + size_t(tile.x0 / kTileSize);
  if (passes_ > 0 && (tile_done_[index] || (focus_tile_ != UINT32_MAX && index != focus_tile_))) return;
  current_tile = uint32_t(index);
  const ImageRays rays(setup.camera, setup.width, setup.height);
  const int n = p_.packet;
  bool missed = false;
  for (int y = tile.y0; y < tile.y1; y += n)
    for (int x = tile.x0; x < tile.x1; x += n)
      missed |= !render_packet(setup, rays, x, y, std::min(x + n, tile.x1), std::min(y + n, tile.y1), out, counters);
  tile_missed_[index] = missed;
}

void TetBvhRenderer::end_frame(const FrameSetup& setup, const FrameBuffers& out) {
  (void)setup, (void)out;
  ++passes_;
}

bool TetBvhRenderer::another_pass() {
  // Approximate frames count the rays that met a missing cluster; exact ones, the pixels not
  // drawn yet.
  uint64_t unfinished = unfinished_.exchange(0, std::memory_order_relaxed);
  if (frame_exact_) unfinished = uint64_t(std::count(pixel_done_.begin(), pixel_done_.end(), uint8_t(0)));
  const bool again = frame_exact_ && unfinished > 0 && passes_ < p_.max_passes;
  if (!again) {
    stalled_frames_ = unfinished > 0 && unfinished == last_missing_ ? stalled_frames_ + 1 : 0;
    last_missing_ = unfinished;
    return false;
  }
  if (focus_tile_ != UINT32_MAX) {
    if (!tile_missed_[focus_tile_]) focus_tile_ = UINT32_MAX;  // done: every unfinished tile again
  } else if (unfinished >= previous_unfinished_) {
    for (size_t t = 0; t < tile_missed_.size() && focus_tile_ == UINT32_MAX; ++t)
      if (!tile_done_[t] && tile_missed_[t]) focus_tile_ = uint32_t(t);
  }
  previous_unfinished_ = unfinished;
  // The clusters this pass missed arrive, no more than L1 holds beside the pages the next
  // pass pins (one a thread), the first tiles' first and, within a tile, the nearest first:
  // an L1 smaller than the frame's clusters then finishes tiles one after the other instead
  // of evicting what one tile needs for another's. The tiles that needed nothing missing are
  // done.
  struct Wanted {
    uint32_t tile;
    float priority;
    uint32_t cluster;
  };
  std::vector<Wanted> wanted;
  {
    std::lock_guard lock(missing_mutex_);
    for (const auto& [cluster, m] : missing_) wanted.push_back({m.tile, m.priority, cluster});
    missing_.clear();
  }
  std::sort(wanted.begin(), wanted.end(), [](const Wanted& a, const Wanted& b) {
    return a.tile != b.tile ? a.tile < b.tile : a.priority > b.priority;
  });
  const size_t slots = ctx_.pages().pool_slots(RecordKind::tet_cluster);
  const size_t pinned = size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
  const size_t keep = slots > pinned + 1 ? slots - pinned : 1;
  if (wanted.size() > keep) wanted.resize(keep);
  for (const Wanted& w : wanted) ctx_.pages().request({RecordKind::tet_cluster, w.cluster}, w.priority);
  ctx_.pages().wait_idle();
  for (size_t t = 0; t < tile_done_.size(); ++t) tile_done_[t] = tile_done_[t] || !tile_missed_[t];
  return true;
}

void TetBvhRenderer::add_statistics(FrameStats& stats) const {
  size_t cached = 0;
  {
    std::lock_guard lock(cache_mutex_);
    cached = bvhs_.size();
  }
  auto v = [](const std::atomic<uint64_t>& a) { return double(a.load(std::memory_order_relaxed)); };
  stats.backend = {{"passes", double(passes_)},
                   {"packet_box_tests", v(counters_.packet_box_tests)},
                   {"ray_box_tests", v(counters_.ray_box_tests)},
                   {"isorange_tests", v(counters_.isorange_tests)},
                   {"isopolygon_extractions", v(counters_.extractions)},
                   {"ray_isopolygon_tests", v(counters_.ray_polygon_tests)},
                   {"full_miss_rays_culled", v(counters_.full_miss_rays)},
                   {"full_hit_rays", v(counters_.full_hit_rays)},
                   {"footprint_culled_rays", v(counters_.footprint_culled_rays)},
                   {"footprint_culled_box_rays", v(counters_.footprint_culled_box_rays)},
                   {"clusters_touched", v(counters_.clusters_touched)},
                   {"clusters_missing", v(counters_.clusters_missing)},
                   {"bvh_builds", v(counters_.bvh_builds)},
                   {"bvh_build_ms", v(counters_.bvh_build_ns) * 1e-6},
                   {"bvh_loads", v(counters_.bvh_loads)},
                   {"bvh_load_ms", v(counters_.bvh_load_ns) * 1e-6},
                   {"bvh_refits", v(counters_.bvh_refits)},
                   {"bvh_refit_ms", v(counters_.bvh_refit_ns) * 1e-6},
                   {"time_step", double(step_)},
                   {"bvh_cached", double(cached)},
                   {"bvh_bytes", double(bvh_bytes_)},
                   {"unfinished_rays", double(last_missing_)}};
}

bool TetBvhRenderer::render_packet(const FrameSetup& setup, const ImageRays& rays, int x0, int y0, int x1, int y1,
                                   FrameBuffers& out, RayCounters& counters) const {
  Packet p;
  const int w = x1 - x0;
  p.lanes = w * (y1 - y0);
  p.origin = setup.camera.eye;
  p.image = &rays, p.x0 = x0, p.y0 = y0, p.w = w;
  rays.directions(x0, y0, w, y1 - y0, p.dx, p.dy, p.dz);
  // The clip box's span per ray, as intersect() computes it, over whole arrays.
  double t0[kMaxLanes], t1[kMaxLanes];
  for (int l = 0; l < p.lanes; ++l) t0[l] = 0, t1[l] = kInf;
  const double* dirs[3] = {p.dx, p.dy, p.dz};
  for (int a = 0; a < 3; ++a) {
    const double lo = clip_.lo[a] - p.origin[a], hi = clip_.hi[a] - p.origin[a];
    const double* d = dirs[a];
    for (int l = 0; l < p.lanes; ++l) {
      const double inv = 1.0 / d[l];
      double tn = lo * inv, tf = hi * inv;
      if (tn > tf) std::swap(tn, tf);
      if (tn > t0[l]) t0[l] = tn;  // NaN (a parallel ray in the slab's plane) leaves it unchanged
      if (tf < t1[l]) t1[l] = tf;
    }
  }
  int px[kMaxLanes], py[kMaxLanes];
  bool any = false;
  const bool first_pass = passes_ == 0;  // nothing done or resumed yet: no state to read
  for (int l = 0; l < p.lanes; ++l) {
    px[l] = x0 + l % w, py[l] = y0 + l / w;
    const size_t pix = pixel_slot(px[l], py[l]);
    const bool done = !first_pass && pixel_done_[pix];
    p.active[l] = !done && t0[l] <= t1[l] && std::isfinite(t1[l]);
    p.tmin[l] = !first_pass && resume_t_[pix] >= 0 ? resume_t_[pix] : t0[l];
    p.tmax[l] = t1[l];
    if (!done) ++counters.rays;
    if (!done && !p.active[l]) {  // outside the volume: background, done
      PixelResult bg;
      bg.color = scene_.background;
      write_pixel(out, px[l], py[l], bg);
      pixel_done_[pix] = 1;
    }
    any = any || p.active[l];
  }
  if (!any) return true;
  if (p.lanes >= 4) p.corners[0] = 0, p.corners[1] = w - 1, p.corners[2] = p.lanes - w, p.corners[3] = p.lanes - 1;
  return shade_packet(setup, p, px, py, out, counters);
}

}  // namespace tet_bvh

BackendEntry tet_bvh_backend() {
  BackendEntry e;
  e.info.name = "tet_bvh";
  e.info.description = "Wald et al.: isosurfaces of tetrahedral meshes by packets through an implicit 4D min/max BVH "
                       "per cluster, isopolygons extracted on the fly; out of core, converging as clusters arrive";
  e.info.kinds = {DataKind::tetrahedral};
  e.info.records = {RecordKind::tet_cluster};
  e.info.modes = {RenderMode::iso};
  e.info.shadows = true;
  e.info.params = tet_bvh::params_table().declarations();
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const tet_bvh::Params tp = tet_bvh::params_table().bind(p);
    if (tp.packet & (tp.packet - 1))
      throw Error(Errc::invalid_argument, fmt::format("packet {} is not 1, 2, 4, 8 or 16", tp.packet)).with_field("packet");
    return std::make_unique<tet_bvh::TetBvhRenderer>(ctx, tp);
  };
  return e;
}

}  // namespace brickyard
