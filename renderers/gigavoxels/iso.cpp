// Surfaces (tracer.h): a gigavoxels iso ray's step loop through the node its descent stopped
// at, leaping clear cell groups, bracketing a crossing between two samples or searching a step
// for a pair of crossings its samples may hide (hidden_crossings), then the hit refined by
// bisection and shaded.

#include <algorithm>
#include <cmath>
#include <optional>

#include "renderers/common/cubic.h"
#include "renderers/gigavoxels/tracer.h"

namespace brickyard::gigavoxels {

/// A constant node on an iso ray: a sample of known value all along it. Returns whether the
/// surface is at its face (the value equals an isovalue, or steps across one there).
template <typename Voxel>
bool Tracer<Voxel>::iso_constant(float v, IsoTrace& trace, RayState& s, double t_at, double t_face, int entry_axis) {
  double& hit_t = trace.hit_t;
  for (size_t k = 0; k < r.scene_.isosurfaces.size(); ++k)
    if (v == r.scene_.isosurfaces[k].value) hit_t = std::min(hit_t, t_at), hit_surface = int(k);
  const int crossed = hit_t == kInf && s.have_prev ? first_crossed(s.prev_value, v) : -1;
  if (crossed >= 0) hit_t = t_at, hit_surface = crossed;
  if (hit_t < kInf) {
    hit_levels.count = 0;  // a face: its normal is the axis the ray entered through
    face_axis = entry_axis;
    return true;
  }
  s.start_segment(v, t_face);
  trace.prev_node = kNoAddress;
  return false;
}

/// Iso through the node the descent stopped at, from t to its exit t_end (t_face: the exit
/// within the ray), sampling the levels lv collected: march()'s loop for iso. finest_only: the
/// footprint stays finer than the finest level met up to t_end (one level, one base step).
/// Returns whether the ray is finished (trace.hit_t: where it hit).
template <typename Voxel>
bool Tracer<Voxel>::march_iso(const Levels& lv, RayState& s, IsoTrace& trace, double& t_io, double t_end, double t_face,
                              double unit_per_t, bool finest_only) {
  double& hit_t = trace.hit_t;
  uint32_t& prev_node = trace.prev_node;
  CachedBounds& bounds = trace.bounds;
  double& clear_until = trace.clear_until;
  const PathNode& fine = *lv.b[lv.count - 1];
  const double fine_voxel = 1.0 / (double(r.m_) * fine.scale);
  const double finest_dt = r.step_ * fine_voxel / unit_per_t;
  double t = t_io;
  bool finished = false;
  double visible_until = -kInf;  // the cell group of the last look showed something
  // The first crossing the step from the previous sample to t hides (hit_t), if any.
  // The clear groups a leap passed, and those around t when a voxel stands in for its
  // value, are not searched: every value in them is on one side of every isovalue.
  // (Made once per node, not per sample: a closure of this many references made a sample
  // that never called it 5% more instructions.)
  const auto hidden_hit = [&](const Blend& bl, double lam, std::optional<float> value_at_t) {
    if (!r.search_hidden_crossings_ || !s.have_prev || bl.coarse) return false;
    const double from = std::max(s.prev_t, clear_until), to = value_at_t ? t : clear_cube_entry(*bl.finer, t);
    Bracket hidden;
    if (!hidden_crossing(*bl.finer, bounds.of(*bl.finer, *this), prev_node, from, to, s.prev_value, value_at_t, hidden))
      return false;
    hit_t = refine_hit(lv, lam, hidden.t0, hidden.t1, hidden.v0, hidden.v1);
    return true;
  };
  // One more sample at the node's exit, so that a crossing in the last part-step is
  // bracketed even when the next node is empty.
  for (bool last = false; !last;) {
    if (t >= t_end) {
      if (s.have_prev && s.prev_t >= t_face) break;
      t = t_face;
      last = true;
    }
    double lam = fine.depth, dt = finest_dt;
    Blend bl{nullptr, &fine, 1};
    if (!finest_only) {
      const double fp = footprint(t);
      // Finer than the finest level met: that level alone, without a log per sample.
      if (fp > fine_voxel) lam = depth_for(fp);
      dt = r.step_ * std::max(fp, fine_voxel) / unit_per_t;
      bl = blend(lv, lam);
    }
    // A clear cell group (nothing visible in it), and the clear groups around it, are
    // leapt to the first sample position past them, the group's voxel standing in for a
    // sample (DVR: see march_dvr).
    double t_leave = kInf, t_next = 0, t_before = 0;
    float voxel;
    bool leap = false;
    if (r.p_.skip_cells && t >= visible_until) {
      leap = clear(bl, t, true, t_leave, voxel);
      if (!leap) visible_until = t_leave;  // no need to look again before
    }
    if (leap) {  // a clear group's voxel stands in for a sample
      const double steps = leap_steps(t, t_leave, t_face, dt);
      t_next = t + std::max(steps, 1.0) * dt;
      t_before = t_next - dt;  // the last position in the clear groups
      // Every value in the clear groups is on the voxel's side of every isovalue.
      if (s.have_prev && crossing(s.prev_value, voxel)) {
        hit_t = refine_hit(lv, lam, s.prev_t, t, s.prev_value, voxel);
        finished = true;
        break;
      }
      // The step into the clear groups starts in visible ones, where it may graze a surface.
      if (hidden_hit(bl, lam, std::nullopt)) {
        finished = true;
        break;
      }
      s.start_segment(voxel, t_before);
      prev_node = kNoAddress;
      clear_until = std::min(t_leave, t_face);  // the cube may reach far past this node
      t = t_next;
      continue;
    }
    ++counters.samples;
    const float v = sample(bl, t, nullptr);
    // A crossing since the last sample, or, with none before (the ray's first sample in
    // data it can see), a sample on the surface: the ray starts on it.
    if (s.have_prev ? crossing(s.prev_value, v) : crossing(v, v)) {
      hit_t = s.have_prev ? refine_hit(lv, lam, s.prev_t, t, s.prev_value, v) : refine_hit(lv, lam, t, t, v, v);
      finished = true;
      break;
    }
    if (hidden_hit(bl, lam, v)) {
      finished = true;
      break;
    }
    s.prev_value = v, s.prev_t = t, s.have_prev = true;
    prev_node = bl.coarse ? kNoAddress : bl.finer->address;
    t += dt;
  }
  t_io = t;
  return finished;
}

/// The first crossing hidden between the samples v0 at t0 and v1 at t1 of brick b's node.
/// v0 may be something else's (prev_node: another node's brick, a clear group's voxel), and
/// t0 in nodes the step went past: then only the part of the step in b's node is searched,
/// from this brick's own value where the ray enters it. Without v1 (t1 where the clear
/// groups a voxel stands in for begin), this brick's value there ends the step.
template <typename Voxel>
bool Tracer<Voxel>::hidden_crossing(const PathNode& b, const FieldBounds& f, uint32_t prev_node, double t0, double t1, float v0,
                                    std::optional<float> v1, Bracket& out) {
  const bool own_v0 = prev_node == b.address;
  if (!(t0 < t1)) return false;
  if (own_v0 && v1) return search_halves(b, f, t0, t1, v0, *v1, r.search_halvings_, out);
  if (!own_v0) t0 = std::max(t0, node_entry(b.frame));
  if (!(t0 < t1)) return false;
  if (!own_v0 && !v1) {  // between clear groups (or from another node into them): neither end known
    counters.samples += 2;
    v0 = sample_brick(b, t0, nullptr), v1 = sample_brick(b, t1, nullptr);
    if (crossing(v0, *v1)) return out = {t0, t1, v0, *v1}, true;
    return search_halves(b, f, t0, t1, v0, *v1, r.search_halvings_, out);
  }
  // With one end known, f must still get from an isovalue to it within the step.
  const double known = own_v0 ? v0 : *v1;
  bool reachable = false;
  for (const auto& surface : r.scene_.isosurfaces) reachable |= std::abs(known - surface.value) <= f.slope * (t1 - t0);
  if (!reachable) return false;
  ++counters.samples;
  if (own_v0) v1 = sample_brick(b, t1, nullptr);
  else v0 = sample_brick(b, t0, nullptr);
  if (crossing(v0, *v1)) return out = {t0, t1, v0, *v1}, true;
  return search_halves(b, f, t0, t1, v0, *v1, r.search_halvings_, out);
}

/// Whether f can cross an isovalue twice between the values v0 and v1, dt apart, both on
/// the same side of every isovalue.
template <typename Voxel>
bool Tracer<Voxel>::may_hide(const FieldBounds& f, double dt, float v0, float v1) const {
  for (const auto& surface : r.scene_.isosurfaces) {
    const double g0 = std::abs(double(v0) - surface.value), g1 = std::abs(double(v1) - surface.value);
    if (g0 + g1 <= f.slope * dt && std::min(g0, g1) <= f.stray(dt)) return true;
  }
  return false;
}

/// Halves the step from v0 at t0 to v1 at t1 while f may hide a crossing pair in it, at most
/// `halvings` times: the first crossing found, bracketed.
template <typename Voxel>
bool Tracer<Voxel>::search_halves(const PathNode& b, const FieldBounds& f, double t0, double t1, float v0, float v1, int halvings,
                                  Bracket& out) {
  if (halvings == 0 || !may_hide(f, t1 - t0, v0, v1)) return false;
  const double tm = 0.5 * (t0 + t1);
  ++counters.samples;
  const float vm = sample_brick(b, tm, nullptr);
  if (crossing(v0, vm)) return out = {t0, tm, v0, vm}, true;
  if (search_halves(b, f, t0, tm, v0, vm, halvings - 1, out)) return true;
  if (crossing(vm, v1)) return out = {tm, t1, vm, v1}, true;
  return search_halves(b, f, tm, t1, vm, v1, halvings - 1, out);
}

/// The first surface crossed between the samples v0 at t0 and v1 at t1 (a crossing bracketed),
/// sampled at footprint depth lambda in the levels lv; it sets what finish_iso shades.
template <typename Voxel>
double Tracer<Voxel>::refine_hit(const Levels& lv, double lambda, double t0, double t1, float v0, float v1) {
  // Bisected down to 2^-refine voxels of the level sampled, whatever the bracket's length.
  const NodeFrame& frame = blend(lv, lambda).finer->frame;
  const double voxels = (t1 - t0) * double(r.m_) * length(Vec3d(frame.dir[0], frame.dir[1], frame.dir[2]));
  const int steps = voxels > 0 ? int(std::clamp(double(r.p_.refine) + std::ceil(std::log2(voxels)), 0.0, 60.0)) : 0;
  // The first surface crossed between the two samples (one is, by the caller's test: at t1 at
  // the latest, where the bisection of a surface met only there returns).
  double best = t1;
  bool found = false;
  for (const auto& surface : r.scene_.isosurfaces) {
    const double g0 = v0 - surface.value, g1 = v1 - surface.value;
    if (!((g0 < 0) != (g1 < 0) || g1 == 0)) continue;
    const double iso = surface.value;
    CrossingBracket bracket;
    const double th = bisect_crossing(
        [&](double m) {
          ++counters.samples;
          return double(sample(lv, lambda, m, nullptr)) - iso;
        },
        t0, t1, g0, g1, steps, &bracket);
    if (!found || th < best) best = th, hit_surface = int(&surface - r.scene_.isosurfaces.data()), hit_bracket = bracket, found = true;
  }
  hit_levels = lv;
  hit_lambda = lambda;
  return best;
}

/// The pixel of a ray that hit at hit_t: its surface's colour, shaded with its normal.
template <typename Voxel>
void Tracer<Voxel>::finish_iso(const PrimaryRay& ray, double hit_t, PixelResult& px) {
  px.depth = hit_t;
  px.alpha = 1;
  const int surface = std::max(0, hit_surface);
  px.color = r.scene_.isosurfaces[size_t(surface)].color;
  if (!gradients) return;
  Vec3d g(0.0);
  if (hit_levels.count > 0) {
    g = crossing_gradient(
        [&](double u) {
          Vec3d gu;
          sample(hit_levels, hit_lambda, u, &gu);
          return gu;
        },
        hit_t, hit_bracket, ray.dir);
  } else if (face_axis >= 0) {
    g[face_axis] = ray.dir[face_axis] > 0 ? 1.0 : -1.0;  // the value rises into the region entered
  }
  // Unit-cube gradient to world: unit = voxel / extent, voxel = world / spacing.
  ++counters.gradients;
  const Vec3d n = facing_normal(g / (r.geo_.spacing * r.extent_), ray.world.dir);
  if (setup.outputs.normals) px.normal = n;
  if (!r.shading_.lit()) return;
  double light_distance;
  const Vec3d l = r.shading_.to_light_along(ray.world, hit_t, light_distance);
  px.color = r.shading_.shade(px.color, n, -ray.world.dir, l, false);
}

#define BRICKYARD_GIGAVOXELS_ISO(V)                                                                                       \
  template bool Tracer<V>::iso_constant(float, IsoTrace&, RayState&, double, double, int);                                \
  template bool Tracer<V>::march_iso(const Levels&, RayState&, IsoTrace&, double&, double, double, double, bool);          \
  template void Tracer<V>::finish_iso(const PrimaryRay&, double, PixelResult&);
BRICKYARD_GIGAVOXELS_FOR_VOXELS(BRICKYARD_GIGAVOXELS_ISO)
#undef BRICKYARD_GIGAVOXELS_ISO

}  // namespace brickyard::gigavoxels
