// A gigavoxels ray's march from node to node (tracer.h): per pixel, from the volume's entry
// point, a kd-restart descent at every new position to the node whose voxels match the ray's
// footprint there, resumed from the deepest node of the last descent that still contains it;
// the node's use and the ray's one request recorded for the loader; then the node integrated
// whole (a constant) or marched by the iso or DVR step loop, and the pixel finished.

#include <algorithm>
#include <cmath>

#include "renderers/gigavoxels/tracer.h"

namespace brickyard::gigavoxels {

template <typename Voxel>
void GigaVoxelsRenderer<Voxel>::render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const {
  Tracer<Voxel> t(*this, setup, counters);
  for (int y = tile.y0; y < tile.y1; ++y)
    for (int x = tile.x0; x < tile.x1; ++x) {
      RayState& s = states_[size_t(y) * size_t(setup.width) + size_t(x)];
      if (s.status == RayState::done) continue;
      t.pixel(x, y, s, out);
    }
  samples_in_runs_.fetch_add(t.samples_in_runs, std::memory_order_relaxed);
  leaps_chained_.fetch_add(t.leaps_chained, std::memory_order_relaxed);
}

/// A pixel: its ray marched where it meets the volume, written once the ray is done.
template <typename Voxel>
void Tracer<Voxel>::pixel(int x, int y, RayState& s, FrameBuffers& out) {
  ++counters.rays;
  const PrimaryRay ray = primary_ray(rays, r.geo_, x, y);
  RayRecorder rec = r.uses_->recorder(x, y);
  PixelResult px;
  px.color = r.scene_.background;
  if (ray.hits()) {
    if (s.status == RayState::fresh) {
      s.t = s.t_sample = ray.span.t0;
      // A procedural volume is empty outside its box: entering a solid region is a surface.
      if (r.outside_value_) s.start_segment(*r.outside_value_, s.t);
    }
    march(ray, s, rec, px);
  } else {
    s.status = RayState::done;
  }
  rec.finish();
  if (s.status == RayState::done) write_pixel(out, x, y, px);
}

/// The ray from where it is (s: its state, kept when exact mode interrupts it) to its end: a
/// descent at each new position, then the node it stops at, integrated whole or marched.
template <typename Voxel>
void Tracer<Voxel>::march(const PrimaryRay& ray, RayState& s, RayRecorder& rec, PixelResult& px) {
  const bool iso = r.scene_.mode == RenderMode::iso;
  for (int a = 0; a < 3; ++a) {
    eye[a] = (ray.org[a] + r.unit_offset_) / r.extent_, dir[a] = ray.dir[a] / r.extent_;
    inv_dir[a] = 1.0 / dir[a];
  }
  scale_eye();
  if (light_fixed) {
    double light_distance;
    ray_light = r.shading_.to_light_along(ray.world, 1.0, light_distance);  // the same at any t > 0
    ray_half = ShadingModel::half_vector(-ray.world.dir, ray_light);
    // normal_of() of a zero gradient: facing the ray
    if (gradients) ray_flat = r.shading_.lighting_with_half(facing_normal(Vec3d(0.0), ray.world.dir), ray_light, ray_half, false);
  }
  const double unit_per_t = length(ray.dir) / r.extent_;  // unit-cube length per unit t
  const double stop = r.scene_.quality.termination_opacity;
  // Descents and samples advance apart: a step may reach past the next node, which is still
  // entered (searched, its exit sampled), or a thin node would hide what is in it.
  double t_at = s.t, t = s.t_sample;
  IsoTrace it;
  bool requested = false;
  int exit_axis = -1;
  aim_path_along_ray();
  while (t_at < ray.span.t1) {
    // DVR integrates between samples whatever lies between them: a node a step passes
    // whole adds nothing, so it descends where the next sample is; or, when that is past
    // the ray's exit, just before the exit, whose node closes the last part-step.
    if (!iso) {
      const bool close_at_exit = t >= ray.span.t1 && s.have_prev && s.prev_t < ray.span.t1;
      t_at = std::max(t_at, close_at_exit ? std::nextafter(ray.span.t1, -kInf) : t);
    }
    Levels lv;
    uint32_t want = 0;
    const PathNode& p = descend(t_at, lv, want);
    const uint32_t address = p.address;
    const Node node = p.node;
    const NodeFrame& frame = p.frame;
    const double scale = p.scale;
    if (!node.constant() && !node.has_brick() && !r.damaged(p.depth, p.c)) want = kWantsBrick;
    // The node's exit along the ray, in the node's frame.
    double t_exit = ray.span.t1;
    const int entry_axis = exit_axis;
    for (int a = 0; a < 3; ++a) {
      if (frame.dir[a] == 0) continue;
      const double ta = ((frame.dir[a] > 0 ? 1.0 : 0.0) - frame.eye[a]) * frame.inv_dir[a];
      if (ta < t_exit) t_exit = ta, exit_axis = a;
    }
    const double t_face = std::min(std::max(t_exit, t_at), ray.span.t1);
    // A hair past the exit, so the next descent lands in the next node.
    const double node_t = 1.0 / scale / unit_per_t;
    t_exit = std::max(t_exit, t_at) + 1e-7 * node_t;
    rec.used(address);
    if (want && !requested) {
      rec.request(address | want);
      requested = true;
      if (r.allow_interrupt_) {
        s.t = t_at, s.t_sample = t;
        s.status = RayState::interrupted;
        return;
      }
    }
    const double t_end = std::min(t_exit, ray.span.t1);
    if (node.constant()) {
      const float v = node.value();
      if (std::isnan(v)) s.have_prev = false;  // a region this scene cannot see
      else if (iso ? iso_constant(v, it, s, t_at, t_face, entry_axis) : dvr_constant(v, s, px, frame, t_at, t_end, unit_per_t, stop, ray))
        break;
      t = t_at = t_exit;
      continue;
    }
    if (lv.count == 0) {  // nothing resident yet, not even the root's brick
      s.have_prev = false;
      t = t_at = t_exit;
      continue;
    }
    ++counters.bricks;
    // March the node with a step from the footprint (never finer than the finest level met).
    const PathNode& fine = *lv.b[lv.count - 1];
    const double fine_voxel = 1.0 / (double(r.m_) * fine.scale);
    // Where the footprint stays finer than the finest level met up to the node's exit (it
    // only grows along the ray), every step has that level alone and the same base length.
    const bool finest_only = footprint(t_end) <= fine_voxel;
    t = std::max(t, t_at);
    const bool finished = iso           ? march_iso(lv, s, it, t, t_end, t_face, unit_per_t, finest_only)
                          : finest_only ? march_dvr<true>(lv, s, t, t_end, t_face, unit_per_t, stop, ray, px)
                                        : march_dvr<false>(lv, s, t, t_end, t_face, unit_per_t, stop, ray, px);
    if (finished) break;
    t_at = t_exit;
  }
  s.status = RayState::done;
  if (!iso) finish_dvr(s, px, stop);
  else if (it.hit_t < kInf) finish_iso(ray, it.hit_t, px);
}

/// kd-restart: the descent from the root to the node at t_at whose voxels match the footprint
/// there. The nodes it passes through are the last descent's as far as they still contain t_at
/// (and are no coarser than the footprint asks), so it resumes from the deepest of those; the
/// path and the levels collected (lv) are the same as from the root. want: kWantsSubdivision
/// where the node should be finer and can be.
template <typename Voxel>
auto Tracer<Voxel>::descend(double t_at, Levels& lv, uint32_t& want) -> const PathNode& {
  const int n = r.n_;
  const double entry_fp = footprint(t_at);
  int restart = 0;
  for (int i = path_size - 1; i > 0; --i)
    if (path[i].contains(t_at)) {
      restart = i;
      break;
    }
  // The footprint grows along the ray: an ancestor may now be fine enough (the test is
  // monotone in depth, so the deepest says whether any does).
  if (restart > 0 && entry_fp * double(r.m_) * path[restart - 1].scale >= 1)
    for (int i = 0; i < restart; ++i)
      if (entry_fp * double(r.m_) * path[i].scale >= 1) {
        restart = i;
        break;
      }
  // The restart node was entered by an earlier descent (its brick and levels are set), or
  // this is the tile's first: the root.
  PathNode* p = &path[restart];
  if (path_size == 0) {
    p->address = 0;
    p->node = r.tree_.node(0);
    p->c[0] = p->c[1] = p->c[2] = 0;
    p->depth = 0;
    p->scale = 1;
    p->frame = node_frame(0, p->c);
    enter(*p, lv);
  } else {
    lv = p->levels;
  }
  int depth = restart;
  for (;;) {
    if (p->node.constant()) break;
    if (entry_fp * double(r.m_) * p->scale >= 1) break;  // its voxels cover at most lod_ratio pixels
    if (!p->node.has_children()) {
      if (!p->node.max_refined()) want = kWantsSubdivision;
      break;
    }
    PathNode& child = path[depth + 1];
    int index = 0, stride = 1;
    for (int a = 0; a < 3; ++a, stride *= n) {
      const int64_t ci = child_index((p->frame.eye[a] + p->frame.dir[a] * t_at) * n, n);
      child.c[a] = p->c[a] * n + ci;
      index += int(ci) * stride;
    }
    child.address = r.tree_.child_address(p->node, index);
    child.node = r.tree_.node(child.address);
    child.scale = p->scale * n;
    child.depth = ++depth;
    child.frame = node_frame(depth, child.c);
    p = &child;
    enter(*p, lv);
  }
  path_size = depth + 1;
  return *p;
}

/// The frame of node c at a depth. The eye's node coordinates e N^depth - c are computed
/// exactly before one rounding: e times the double-double N^depth by an error-free product
/// (fma), and the integer part subtracted in integers where doubles no longer hold c.
template <typename Voxel>
auto Tracer<Voxel>::node_frame(int depth, const int64_t c[3]) const -> NodeFrame {
  const ScaledEye& e = scaled_eye[size_t(depth)];
  NodeFrame f;
  if (e.small) {  // the common case, without a test per axis
    for (int a = 0; a < 3; ++a) f.eye[a] = (e.hi[a] - double(c[a])) + e.lo[a];
    aim(f, depth);
    return f;
  }
  for (int a = 0; a < 3; ++a) {
    const double hi = e.hi[a];
    double whole;
    if (std::abs(hi) < 0x1p53) whole = hi - double(c[a]);  // exact: both are multiples of ulp(hi)
    else if (std::abs(hi) < 0x1p62) whole = double(int64_t(hi) - c[a]);  // hi is an integer here
    else whole = hi - double(c[a]);  // an eye this far outside never descends this deep
    f.eye[a] = whole + e.lo[a];
  }
  aim(f, depth);
  return f;
}

template <typename Voxel>
void Tracer<Voxel>::scale_eye() {
  if (eye[0] == scaled_eye_of[0] && eye[1] == scaled_eye_of[1] && eye[2] == scaled_eye_of[2]) return;
  for (size_t d = 0; d < scaled_eye.size(); ++d) {
    const Scale& s = r.scales_[d];
    for (int a = 0; a < 3; ++a) {
      const double hi = eye[a] * s.hi;
      scaled_eye[d].hi[a] = hi, scaled_eye[d].lo[a] = std::fma(eye[a], s.hi, -hi) + eye[a] * s.lo;
    }
    const double* hi = scaled_eye[d].hi;
    scaled_eye[d].small = std::abs(hi[0]) < 0x1p53 && std::abs(hi[1]) < 0x1p53 && std::abs(hi[2]) < 0x1p53;
  }
  std::copy_n(eye, 3, scaled_eye_of);
}

/// The ray's direction in the frame of a node at a depth.
template <typename Voxel>
void Tracer<Voxel>::aim(NodeFrame& f, int depth) const {
  const double s = r.scales_[size_t(depth)].hi, inv_s = r.inv_scales_[size_t(depth)];
  for (int a = 0; a < 3; ++a) f.dir[a] = dir[a] * s, f.inv_dir[a] = inv_dir[a] * inv_s;
}

/// A node the descent passes: its brick, if any, joins the levels collected.
template <typename Voxel>
void Tracer<Voxel>::enter(PathNode& q, Levels& lv) {
  ++counters.nodes;
  q.brick = nullptr;
  if (q.node.has_brick()) {
    q.brick = r.brick(q.node.brick()), q.group_distances = r.group_distances(q.node.brick());
    const int64_t e = r.m_ + 2;
    for (int a = 0; a < 3; ++a) {
      int64_t lo = 0, hi = e - 1;  // the sponge's: the whole brick
      if (size_t(q.depth) < r.level_dims_.size()) {
        const int64_t base = q.c[a] * r.m_ - 1;  // level voxel p is at brick coordinate p - base
        lo = std::clamp<int64_t>(-base, 0, e - 1), hi = std::clamp<int64_t>(r.level_dims_[size_t(q.depth)][a] - 1 - base, lo, e - 1);
      }
      q.inside_lo[a] = float(lo), q.inside_hi[a] = float(hi);
      q.cell_hi[a] = int32_t(std::min(std::max(hi - 1, lo), e - 2));
    }
    q.differences = r.search_hidden_crossings_ ? &r.brick_differences_of(q.node.brick()) : nullptr;
    lv.push(q);
  }
  q.levels = lv;
}

/// The rays of a tile leave one eye in nearby directions, so each starts from the last
/// ray's descent: the nodes are this ray's too as far as they contain its start, and the
/// eye's part of their frames does not depend on the direction, so only the direction's
/// part is redone. Deep in a zoom, a descent from the root would be most of the tree.
template <typename Voxel>
void Tracer<Voxel>::aim_path_along_ray() {
  for (int d = 0; d < path_size; ++d) aim(path[size_t(d)].frame, d);
}

#define BRICKYARD_GIGAVOXELS_DESCENT(V) \
  template void GigaVoxelsRenderer<V>::render_tile(const FrameSetup&, const Tile&, FrameBuffers&, RayCounters&) const;
BRICKYARD_GIGAVOXELS_FOR_VOXELS(BRICKYARD_GIGAVOXELS_DESCENT)
#undef BRICKYARD_GIGAVOXELS_DESCENT

}  // namespace brickyard::gigavoxels
