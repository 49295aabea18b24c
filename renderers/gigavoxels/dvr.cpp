// Volume rendering (tracer.h): a gigavoxels DVR ray's step loop through the node its descent
// stopped at (march_dvr), with runs of samples taken side by side at one level (sample_run),
// leaps over clear cell groups and prefetches ahead of its samples; the segments between
// samples pre-integrated, lit by their ends (and the cells between their faces), and
// composited; constant nodes integrated whole.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>

#include "renderers/gigavoxels/corner_lanes.h"
#include "renderers/gigavoxels/tracer.h"

namespace brickyard::gigavoxels {
namespace {

/// DVR at one level: how many sample positions ahead a ray asks for their cells (8 gained
/// nothing over 3).
constexpr int kPrefetchAhead = 3;

/// DVR at one level: from what base step on (`step`, in voxels) a ray asks for the cells of
/// a node's first samples as it enters it (prefetch_entry_samples).
constexpr double kEntryPrefetchStep = 2;
/// How many sample positions from a node's entry that asks for, the exit sample's included.
constexpr int kEntryPrefetches = 5;

}  // namespace

/// DVR through the node the descent stopped at, from t to its exit t_end (t_face: the
/// exit within the ray), sampling the levels lv collected: march()'s loop for DVR, with
/// the ray's state in locals so that a sample's value, segment, lighting and compositing
/// stay in registers (7% less time per lit DVR frame than when it was one loop with iso,
/// 165 -> 154 ms on fBm 256^3 at 256x256, with the same samples and arithmetic).
/// kOneLevel: the footprint stays finer than the finest level met up to t_end, so every
/// sample reads that level alone at one base step, with no footprint, log or blend per
/// sample. Returns whether the ray is finished.
template <typename Voxel>
template <bool kOneLevel>
bool Tracer<Voxel>::march_dvr(const Levels& lv, RayState& ray_state, double& t_io, double t_end, double t_face, double unit_per_t,
                              double stop, const PrimaryRay& ray, PixelResult& px) {
  const bool skip_cells = r.p_.skip_cells;
  const PathNode& fine = *lv.b[lv.count - 1];
  const double fine_voxel = 1.0 / (double(r.m_) * fine.scale);
  const double finest_dt = r.step_ * fine_voxel / unit_per_t;
  // The cell group of the last look showed something: before visible_until (!kOneLevel), or
  // while the sample's group index is visible_group (kOneLevel).
  double t = t_io, visible_until = -kInf;
  double prefetched_until = -kInf;  // kOneLevel: the farthest sample position whose cell was asked for
  int visible_group = -1;
  RayState s = ray_state;  // a copy the compiler keeps in registers
  bool finished = false;
  // Where the previous sample fell among the cells of its brick (prev_lattice), when it
  // was taken here, with a gradient, from that brick alone: a segment within one brick's
  // cells is lit by the faces it crosses. Where two levels blend, the coarser level's
  // gradient jumps at other faces, and the segment takes its ends' mean.
  CellPoint prev_at;
  const PathNode* prev_lattice = nullptr;
  // Difference normals are continuous across cell faces (they jump only at store-brick
  // faces, one in M, as the reference's do): their ends' mean serves.
  const bool face_lighting = r.p_.face_lighting && gradients && r.shading_.lit() && r.scene_.shading.normals == NormalMethod::analytic;
  if constexpr (kOneLevel)
    if (r.step_ >= kEntryPrefetchStep && t < t_end) prefetch_entry_samples(fine, t, finest_dt * s.step_scale, t_end, t_face);
  // One more sample at the node's exit, so that the part-step to it is integrated even
  // when the next node takes no samples (hidden, or past the ray's end: on Marschner-Lobb
  // 64^3 at step 1, leaving that out doubled the error).
  for (bool last = false; !last;) {
    if (t >= t_end) {
      if (!s.have_prev || s.prev_t >= t_face) break;
      t = t_face;
      last = true;
    }
    double dt = finest_dt;
    Blend bl{nullptr, &fine, 1};
    if constexpr (!kOneLevel) {
      const double fp = footprint(t);
      // Finer than the finest level met: that level alone, without a log per sample.
      const double lam = fp > fine_voxel ? depth_for(fp) : double(fine.depth);
      dt = r.step_ * std::max(fp, fine_voxel) / unit_per_t;
      bl = blend(lv, lam);
    }
    dt *= s.step_scale;
    // A clear cell group (nothing visible in it), and the clear groups around it, are
    // leapt to the first sample position past them: at one level, the samples taken are
    // the ones marching every step would take; where the step follows the footprint, later
    // samples move (another sampling, as accurate). A leap of one step is a plain step.
    double t_next = 0, t_leave = kInf;
    bool leap = false;
    // At one level, t's brick coordinates serve both the look and the sample; and the look
    // is skipped while the ray stays in the group the last look found visible, which its
    // index tells more cheaply than where the ray leaves that group.
    double l[3];
    if constexpr (kOneLevel) {
      if (runs && s.have_prev && !last) {
        const Run run = sample_run(fine, s, px, t, dt, t_end, t_face, unit_per_t, stop, visible_group, prev_at,
                                   prev_lattice, face_lighting, ray);
        if (run == Run::finished) {
          finished = true;
          break;
        }
        if (run == Run::exited) break;  // t is past the exit, as after the exit sample below
        if (run == Run::leapt) {  // as a leap below, whose first sample the run took
          if (r.p_.leap_chains) t = chain_leaps(fine, t, dt, finest_dt * s.step_scale, t_end, t_face);
          ++counters.samples;
          prev_lattice = nullptr;
          s.start_segment(sample(bl, t - dt, nullptr), t - dt);
          continue;
        }
        if (run == Run::advanced) continue;
      }
      brick_coordinates(fine, t, l);
      // At one level the step is known, so the next positions are: on a volume larger than
      // the caches a sample's rows often miss, and asking for them a few steps ahead hides
      // part of that: 3-5% of a lit 512x512 DVR frame of fBm 1024^3 u16 at step 1 (medians
      // 1.12-1.18 s -> 1.08-1.13 s, 6 alternations). Fragile: the same prefetches in a
      // counted loop from t, or left out where a leap starts and past the node's exit, lost
      // the gain. The frame is bound by instructions, not memory: a 64x64 crop of it that
      // stays in the caches costs as much per sample.
      prefetched_until = std::max(prefetched_until, t);
      for (int k = 0; k < kPrefetchAhead && prefetched_until < t + kPrefetchAhead * dt; ++k) {
        prefetched_until += dt;
        double ahead[3];
        for (int a = 0; a < 3; ++a) ahead[a] = l[a] + fine.frame.dir[a] * double(r.m_) * (prefetched_until - t);
        prefetch_cell(fine, ahead);
      }
      if (skip_cells) {
        int g[3];
        if (const int i = group_of(l, g); i != visible_group) {
          const uint8_t distance = fine.group_distances[i];
          if (distance == 0) visible_group = i;
          else leap = true, t_leave = cube_crossing(fine, g, distance, true);
        }
      }
    } else if (skip_cells && t >= visible_until) {
      float voxel;  // DVR samples where a leap ends instead
      leap = clear(bl, t, false, t_leave, voxel);
      if (!leap) visible_until = t_leave;  // no need to look again before
    }
    if (leap) {
      const double steps = leap_steps(t, t_leave, t_face, dt);
      leap = steps > 1;
      t_next = t + std::max(steps, 1.0) * dt;
    }
    // A sample at t, unless a leap starts there with no segment open (the clear groups add
    // nothing): then the leap's last value alone starts the next segment.
    if (!leap || s.have_prev) {
      ++counters.samples;
      Vec3d g(0.0);
      CellPoint at;
      const bool one_lattice = face_lighting && !bl.coarse;
      float v;
      if constexpr (kOneLevel) v = sample_brick_at(fine, l, gradients ? &g : nullptr, one_lattice ? &at : nullptr);
      else v = sample(bl, t, gradients ? &g : nullptr, one_lattice ? &at : nullptr);
      bool lit_here = false;
      if (s.have_prev) {
        lit_here = integrate(s, px, v, t, to_voxels(t - s.prev_t, unit_per_t), g, ray,
                             one_lattice && prev_lattice == bl.finer ? &prev_at : nullptr, &at, bl.finer);
        if (s.alpha >= stop) {
          finished = true;
          break;
        }
      }
      s.prev_value = v, s.prev_t = t, s.have_prev = true;
      s.prev_gradient = g, s.have_prev_gradient = gradients, s.have_prev_lighting = lit_here;
      prev_at = at, prev_lattice = one_lattice ? bl.finer : nullptr;
    }
    if (leap) {  // the segment into the clear groups is closed: their last value starts the next
      if constexpr (kOneLevel)
        if (r.p_.leap_chains) t_next = chain_leaps(fine, t_next, dt, finest_dt * s.step_scale, t_end, t_face);
      ++counters.samples;
      prev_lattice = nullptr;  // no gradient at the segment's start
      s.start_segment(sample(bl, t_next - dt, nullptr), t_next - dt);
      t = t_next;
      continue;
    }
    t += dt;
  }
  ray_state = s;
  t_io = t;
  return finished;
}

/// Asks for the cache lines holding the first voxel of each of the four rows of the cell
/// of brick b at brick coordinates l, ahead of a sample there, so that loading them
/// overlaps the samples before it. A hint only: nothing read changes.
template <typename Voxel>
void Tracer<Voxel>::prefetch_cell(const PathNode& b, const double l[3]) const {
  const int e = r.m_ + 2;
  int64_t cell[3];
  for (int a = 0; a < 3; ++a) cell[a] = child_index(l[a], e - 1);  // as brick_cell clamps (NaN: 0)
  const Voxel* q = cell_voxels(b, cell);
  for (const Voxel* row : {q, q + e, q + e * e, q + e * e + e}) {
#if defined(__x86_64__) || defined(__i386__)
    // GCC 12 (-O3 -march=x86-64-v3) emitted no prefetch instruction for __builtin_prefetch
    // here (objdump of the object); an asm volatile statement cannot be removed. prefetcht0
    // never faults, and the "m" operand only supplies the address.
    asm volatile("prefetcht0 %0" : : "m"(*row));
#else
    __builtin_prefetch(row);
#endif
  }
}

/// Asks for the cells of the first kEntryPrefetches sample positions from t, one step dt
/// apart (the step as it is at the entry: an adaptive step that grows on moves the later
/// ones), the exit sample at t_face standing in for those at or past t_end. Each would
/// otherwise wait for its rows only when reached; at a step of 2 voxels they are about half
/// of the samples along a brick's mean chord (21 voxels at M = 32), from step 4 most or all.
/// Measured on a lit 512x512 DVR frame of fBm 1024^3 u16: 3% less time at step 4, 8% at
/// step 16; at step 1, where the 5 positions span 4 voxels and share their cache lines with
/// what the first sample run reads at once, 1-2% more, so it is off there. A hint only:
/// nothing read changes.
template <typename Voxel>
void Tracer<Voxel>::prefetch_entry_samples(const PathNode& b, double t, double dt, double t_end, double t_face) const {
  for (int k = 0; k < kEntryPrefetches; ++k) {
    double tk = t + k * dt;
    const bool at_exit = !(tk < t_end);
    if (at_exit) tk = t_face;
    double l[3];
    brick_coordinates(b, tk, l);
    prefetch_cell(b, l);
    if (at_exit) break;
  }
}

/// Where a DVR leap goes on at one level. A leap that ends at t_next (its last position
/// t_next - dt, in the clear groups it leapt) takes a sample there, then leaps again if t_next
/// lies in clear groups. When the values at both ends lie in one interval the transfer
/// function hides (their groups' voxels do: group_voxel), the pre-integrated segment between
/// them is clear whatever they are, so the ray leaps on with no sample: while t_next's group
/// is clear, in the interval of the group of the last position, and its clear groups reach
/// 2 steps or more (a leap of one step is a plain step, which samples). Steps after the
/// first leap are next_dt (the adaptive step as the sample before the first leap left it).
/// The samples left out would have added only the pre-integration table's slight opacity
/// next to a hidden range; the positions taken are those of leaping one leap at a time.
/// Returns the last leap's end; dt becomes its step.
template <typename Voxel>
double Tracer<Voxel>::chain_leaps(const PathNode& b, double t_next, double& dt, double next_dt, double t_end, double t_face) {
  double t_leave;
  float voxel, next;
  while (t_next < t_end && clear_group(b, t_next - dt, t_leave, voxel) && clear_group(b, t_next, t_leave, next) &&
         !std::isnan(voxel) && !std::isnan(next) && (next == voxel || same_hidden_interval(voxel, next))) {
    const double steps = leap_steps(t_next, t_leave, t_face, next_dt);
    if (!(steps > 1)) break;
    t_next += steps * next_dt;
    dt = next_dt;
    ++leaps_chained;
  }
  return t_next;
}

/// march_dvr<true>'s samples from t on, up to kRunLanes of them, taken side by side in
/// vector lanes (GCC's vector extension): positions and cell groups (then the looks at
/// them one by one, as march_dvr's), cells, gathered corners, values and gradients,
/// lighting, face weights and the lighting between faces (lighting_between), and segments
/// (PreintegratedTf::segments); then the compositing
/// in order. The same samples and arithmetic as one at a time, but for the step: it stays
/// dt across the run, where the adaptive step would grow it after each visible segment.
/// A run ends at the node's exit (t_end), whose sample at t_face (the exit within the ray)
/// is its last, as one at a time takes it; and at a sample whose cell group is clear,
/// which is its last when a leap starts there (march_dvr takes the leap's last position)
/// and is left out otherwise. Needs a segment open (s.have_prev).
template <typename Voxel>
auto Tracer<Voxel>::sample_run(const PathNode& b, RayState& s, PixelResult& px, double& t, double dt, double t_end, double t_face,
                               double unit_per_t, double stop, int& visible_group, CellPoint& prev_at,
                               const PathNode*& prev_lattice, bool face_lighting, const PrimaryRay& ray) -> Run {
  constexpr int L = kRunLanes;
  RunPositions at;
  const int exit_lane = run_positions(b, t, dt, t_end, t_face, at);
  Run ending = Run::advanced;
  std::optional<double> t_after;  // where the march goes on, when not one step past the run's last sample
  const int n = run_looks(b, at, exit_lane, dt, t_end, t_face, visible_group, ending, t_after);
  if (n == 0) return Run::none;
  RunSamples ln;
  run_samples(b, at, s, prev_at, ln);
  for (int k = 0; k < n; ++k) ln.length[k] = to_voxels(at.tk[k] - (k == 0 ? s.prev_t : at.tk[k - 1]), unit_per_t);
  r.preintegrated_.template segments<L>(ln.value, ln.length, n, ln.color, ln.alpha);
  const bool lit = gradients && r.shading_.lit();
  if (lit) run_lighting(at, n, ray, ln);
  // Each segment's face weight, and the lighting between its first and last faces.
  if (face_lighting) {
    face_crossings(ln.cell, ln.u, ln.crossings);
    if (prev_lattice != &b) ln.crossings[0] = {};  // its front end lies in another lattice
    bool any_middle = false;
    for (int k = 0; k < L; ++k) {
      ln.middle[k] = lit && r.p_.middle_lighting && k < n && ln.alpha[k] > 0 && ln.crossings[k].has_middle();
      any_middle |= ln.middle[k];
    }
    if (any_middle)
      lighting_between(b, ln.cell, ln.u, ln.crossings, ln.middle, at.tk, s.prev_t, ray, ln.middle_diffuse, ln.middle_specular,
                       ln.middle_normal);
  }
  if (composite_run(s, px, at, n, lit, stop, ray, ln)) return Run::finished;
  counters.samples += uint64_t(n);
  samples_in_runs += uint64_t(n);
  if (r.p_.adaptive_step > 1) s.step_scale = adaptive_step_scale(s.alpha);
  const int last = n - 1;
  s.prev_value = ln.value[n], s.prev_t = at.tk[last], s.have_prev = true;
  s.prev_gradient = Vec3d(ln.gradient[0][last], ln.gradient[1][last], ln.gradient[2][last]);
  s.have_prev_gradient = gradients, s.have_prev_lighting = ln.alpha[last] > 0;
  if (s.have_prev_lighting) s.prev_lighting = {ln.diffuse[last], ln.specular[last]};
  for (int a = 0; a < 3; ++a) prev_at.cell[a] = ln.cell[a][n], prev_at.u[a] = ln.u[a][n];
  prev_lattice = face_lighting ? &b : nullptr;
  t = t_after ? *t_after : at.tk[last] + dt;
  return ending;
}

/// A run's positions one step after another, as march_dvr takes them; then their brick
/// coordinates (brick_coordinates, read in float as sample_brick_at reads them) and cell groups
/// (group_of) side by side. Returns the exit's lane: the first position at or past the node's
/// exit is the exit itself, when the sample before lies before it (march_dvr's exit sample:
/// t_end is a hair past t_face); kRunLanes when none is.
template <typename Voxel>
int Tracer<Voxel>::run_positions(const PathNode& b, double t, double dt, double t_end, double t_face, RunPositions& at) const {
  constexpr int L = kRunLanes;
  // GCC 12's loop vectoriser left most of these lanes scalar, with their arrays spilled.
  using Doubles = double __attribute__((vector_size(32)));  // half the lanes
  using Floats4 = float __attribute__((vector_size(16)));
  using Ints4 = int32_t __attribute__((vector_size(16)));
  constexpr int H = L / 2;
  static_assert(kCellGroup == 4, "a cell group's index is a shift by 2");
  double (&tk)[L] = at.tk;
  tk[0] = t;
  for (int k = 1; k < L; ++k) tk[k] = tk[k - 1] + dt;
  // The lanes after the exit's are not used.
  int exit_lane = L;
  for (int k = 1; k < L; ++k)
    if (!(tk[k] < t_end)) {
      if (tk[k - 1] < t_face) exit_lane = k, tk[k] = t_face;
      break;
    }
  const double m = double(r.m_);
  const Doubles group_top = Doubles{} + double(r.m_ + 1);
  for (int h = 0; h < L; h += H) {
    Doubles th;
    std::memcpy(&th, &tk[h], sizeof th);
    Ints4 g[3];
    for (int a = 0; a < 3; ++a) {
      const Doubles l = (b.frame.eye[a] + b.frame.dir[a] * th) * m + 0.5;
      const Floats4 f = __builtin_convertvector(l, Floats4);
      std::memcpy(&at.lf[a][h], &f, sizeof f);
      const Doubles clamped = l > 0 ? (l < group_top ? l : group_top) : Doubles{};  // NaN: 0
      g[a] = __builtin_convertvector(clamped, Ints4) >> 2;
    }
    const Ints4 index = (g[2] * r.groups_ + g[1]) * r.groups_ + g[0];
    std::memcpy(&at.group[h], &index, sizeof index);
  }
  return exit_lane;
}

/// How many of a run's positions it samples: the looks at their cell groups, one by one as
/// march_dvr's, up to the node's exit, a leap's start or a clear group (ending and t_after:
/// how the run ends and, after a leap's start, where the march goes on). 0: no run.
template <typename Voxel>
int Tracer<Voxel>::run_looks(const PathNode& b, const RunPositions& at, int exit_lane, double dt, double t_end, double t_face,
                             int& visible_group, Run& ending, std::optional<double>& t_after) const {
  const double(&tk)[kRunLanes] = at.tk;
  int n = 0;
  for (; n < kRunLanes; ++n) {
    if (n == exit_lane) {  // its look may leap nothing (march_dvr's leap of 0 steps)
      ending = Run::exited;
      ++n;
      break;
    }
    if (!(tk[n] < t_end)) break;  // past the exit, with no exit sample
    if (r.p_.skip_cells && at.group[n] != visible_group) {
      if (const uint8_t distance = b.group_distances[at.group[n]]; distance != 0) {
        if (n == 0) return 0;
        // march_dvr's leap from here: a leap of one step is a plain step, which ends the run.
        double l[3];
        int g[3];
        brick_coordinates(b, tk[n], l);
        group_of(l, g);
        const double t_leave = cube_crossing(b, g, distance, true);
        const double steps = leap_steps(tk[n], t_leave, t_face, dt);
        ending = steps > 1 ? Run::leapt : Run::advanced;
        t_after = tk[n] + std::max(steps, 1.0) * dt;
        ++n;
        break;
      }
      visible_group = at.group[n];
    }
  }
  return n;
}

/// A run's cells and values: brick_cell and sample_brick_at. Point 0 is the previous sample
/// (face weights), the run's samples are points 1..L. Lanes past the run's sample past it,
/// inside the brick (clamped as every sample is), and are not used.
template <typename Voxel>
void Tracer<Voxel>::run_samples(const PathNode& b, const RunPositions& at, const RayState& s, const CellPoint& prev_at,
                                RunSamples& ln) const {
  constexpr int L = kRunLanes;
  using Floats = LaneFloats;
  using Ints = LaneInts;
  for (int a = 0; a < 3; ++a) ln.cell[a][0] = prev_at.cell[a], ln.u[a][0] = prev_at.u[a];
  Floats x[3], uf[3], corner[8];
  Ints cells[3];
  for (int a = 0; a < 3; ++a) std::memcpy(&x[a], at.lf[a], sizeof x[a]);
  cells_and_corners(b, x, cells, uf, corner);
  for (int a = 0; a < 3; ++a)
    std::memcpy(&ln.cell[a][1], &cells[a], sizeof cells[a]), std::memcpy(&ln.u[a][1], &uf[a], sizeof uf[a]);
  ln.value[0] = s.prev_value;
  const double to_unit = b.scale * double(r.m_);  // brick voxels to unit coordinates
  if (gradients) {
    Vec3<Floats> g;
    const Floats v = trilinear_with_gradient(corner, uf[0], uf[1], uf[2], g, r.wide_values_);
    std::memcpy(&ln.value[1], &v, sizeof v);
    gradients_in_doubles(g, to_unit, ln.gradient, ln.normal);
  } else {
    const Floats v = trilinear(corner, uf[0], uf[1], uf[2], r.wide_values_);
    std::memcpy(&ln.value[1], &v, sizeof v);
    std::fill_n(&ln.gradient[0][0], 3 * L, 0.0);
    std::fill_n(ln.normal, L, false);
  }
}

/// The lighting at each of a run's n samples (lighting_at), side by side.
template <typename Voxel>
void Tracer<Voxel>::run_lighting(const RunPositions& at, int n, const PrimaryRay& ray, RunSamples& ln) {
  constexpr int L = kRunLanes;
  double world[3][L];
  for (int a = 0; a < 3; ++a)
    for (int k = 0; k < L; ++k) world[a][k] = ln.gradient[a][k] * r.unit_gradient_to_world_[a];
  r.shading_.lighting_of_gradients(world, ray_light, ray_half, ln.diffuse, ln.specular);
  // Lit as lighting_at would light them, but for a zero gradient (facing the ray, as the
  // reference takes it), one too small or too large to normalise, or a sample at the eye.
  bool any_falls_back = false;
  bool falls_back[L];
  for (int k = 0; k < n; ++k) {
    const double length2 = world[0][k] * world[0][k] + world[1][k] * world[1][k] + world[2][k] * world[2][k];
    falls_back[k] = !(ln.normal[k] && length2 > 0 && length2 < kInf && at.tk[k] > 0);
    any_falls_back |= falls_back[k];
  }
  for (int k = 0; any_falls_back && k < n; ++k) {
    if (!falls_back[k]) continue;
    const Vec3d g(ln.gradient[0][k], ln.gradient[1][k], ln.gradient[2][k]);
    const ShadingModel::Lighting l = lighting_at(at.tk[k], g, ray);
    counters.gradients -= ln.normal[k];  // counted below, as for every lane
    ln.diffuse[k] = l.diffuse, ln.specular[k] = l.specular;
  }
}

/// A run's n segments composited in order (integrate and composite). Returns whether the
/// ray is finished, its samples then counted.
template <typename Voxel>
bool Tracer<Voxel>::composite_run(RayState& s, PixelResult& px, const RunPositions& at, int n, bool lit, double stop,
                                  const PrimaryRay& ray, const RunSamples& ln) {
  const ShadingModel::Lighting none{};
  for (int k = 0; k < n; ++k) {
    if (ln.alpha[k] > 0) {
      const ShadingModel::Lighting here{ln.diffuse[k], ln.specular[k]};
      counters.gradients += ln.normal[k];
      ShadingModel::Lighting light = here;
      const bool front_gradient = k > 0 ? gradients : s.have_prev_gradient;
      if (front_gradient) {
        const bool front_lit = k > 0 ? ln.alpha[k - 1] > 0 : s.have_prev_lighting;
        if (k == 0 && !front_lit) s.prev_lighting = lighting_at(s.prev_t, s.prev_gradient, ray);
        if (k > 0 && !front_lit) counters.gradients += ln.normal[k - 1];
        const ShadingModel::Lighting front_light =
            k == 0 ? s.prev_lighting : ShadingModel::Lighting{ln.diffuse[k - 1], ln.specular[k - 1]};
        if (ln.middle[k]) {
          counters.gradients += ln.middle_normal[k];
          light = across_faces(front_light, {ln.middle_diffuse[k], ln.middle_specular[k]}, here, ln.crossings[k]);
        } else {
          light = front_light.mix(here, ln.crossings[k].front_weight());
        }
      }
      const Vec3f c = r.shading_.apply(ln.color[k], lit ? light : none);
      s.last_color = c;
      const double a = ln.alpha[k];
      s.accum += Vec3d(c) * ((1 - s.alpha) * a);
      s.alpha += (1 - s.alpha) * a;
      if (px.depth == kInf && s.alpha >= 0.5) {
        px.depth = at.tk[k];
        if (setup.outputs.normals) px.normal = normal_of(Vec3d(ln.gradient[0][k], ln.gradient[1][k], ln.gradient[2][k]), ray);
      }
    }
    // After every sample, as march_dvr checks (a termination opacity of 0 ends at the first).
    if (s.alpha >= stop) {
      // The samples past it were not the ray's. The state keeps the run's start: a
      // finished ray reads only its colour and opacity.
      counters.samples += uint64_t(k + 1);
      samples_in_runs += uint64_t(k + 1);
      return true;
    }
  }
  return false;
}

/// brick_cell for kRunLanes points of brick b at brick coordinates x, side by side: their
/// cells c (clamped as brick_cell clamps; NaN: the low end), the positions uf in them, and the cells'
/// corners.
template <typename Voxel>
void Tracer<Voxel>::cells_and_corners(const PathNode& b, const LaneFloats (&x)[3], LaneInts (&c)[3], LaneFloats (&uf)[3],
                                      LaneFloats (&corner)[8]) const {
  constexpr int L = kRunLanes;
  const int32_t e = r.m_ + 2;
  LaneInts offset = {};
  for (int a = 2; a >= 0; --a) {
    const LaneFloats inside_lo = LaneFloats{} + b.inside_lo[a], inside_hi = LaneFloats{} + b.inside_hi[a];
    const LaneInts last_cell = LaneInts{} + b.cell_hi[a];
    const LaneFloats clamped = x[a] > inside_lo ? (x[a] < inside_hi ? x[a] : inside_hi) : inside_lo;
    c[a] = __builtin_convertvector(clamped, LaneInts);
    c[a] = c[a] < last_cell ? c[a] : last_cell;
    uf[a] = clamped - __builtin_convertvector(c[a], LaneFloats);
    offset = offset * e + c[a];  // (cell z * e + cell y) * e + cell x
  }
  int32_t offsets[L];
  std::memcpy(offsets, &offset, sizeof offsets);
  float corners[8][L];
  load_cell_corners(b.brick, offsets, e, corners);
  for (int i = 0; i < 8; ++i) std::memcpy(&corner[i], corners[i], sizeof corner[i]);
}

/// Gradient lanes (brick voxels) in doubles, in unit coordinates (to_unit), and whether
/// each has a normal (is not zero).
template <typename Voxel>
void Tracer<Voxel>::gradients_in_doubles(const Vec3<LaneFloats>& g, double to_unit, double (&gradient)[3][kRunLanes],
                                         bool (&normal)[kRunLanes]) {
  using Doubles = double __attribute__((vector_size(32)));  // half the lanes
  using Floats4 = float __attribute__((vector_size(16)));
  constexpr int H = kRunLanes / 2;
  for (int h = 0; h < kRunLanes; h += H) {
    Doubles gd[3];
    for (int a = 0; a < 3; ++a) {
      const Floats4 part = h == 0 ? __builtin_shufflevector(g[a], g[a], 0, 1, 2, 3) : __builtin_shufflevector(g[a], g[a], 4, 5, 6, 7);
      gd[a] = __builtin_convertvector(part, Doubles) * to_unit;
      std::memcpy(&gradient[a][h], &gd[a], sizeof gd[a]);
    }
    const auto has = (gd[0] != 0) | (gd[1] != 0) | (gd[2] != 0);
    for (int k = 0; k < H; ++k) normal[h + k] = has[k] != 0;
  }
}

/// The lighting in the middle of the cells each segment of a run crosses between its first
/// and last faces (crossings), as integrate() takes it one at a time: its point in brick
/// coordinates from its ends' cells (points k and k + 1 of cell and u), then brick_cell,
/// the corners, the analytic gradient and lighting_of_gradients, side by side; lighting_at
/// where that cannot light a lane it is used for. Its gradient is counted where it is used.
template <typename Voxel>
void Tracer<Voxel>::lighting_between(const PathNode& b, const int32_t (&cell)[3][kRunLanes + 1], const float (&u)[3][kRunLanes + 1],
                                     const FaceCrossings (&crossings)[kRunLanes], const bool (&used)[kRunLanes],
                                     const double (&tk)[kRunLanes], double prev_t, const PrimaryRay& ray, float (&diffuse)[kRunLanes],
                                     float (&specular)[kRunLanes], bool (&normal)[kRunLanes]) {
  constexpr int L = kRunLanes;
  using Floats = LaneFloats;
  using Ints = LaneInts;
  float fraction[L];
  for (int k = 0; k < L; ++k) fraction[k] = crossings[k].middle();
  Floats at;
  std::memcpy(&at, fraction, sizeof at);
  Floats x[3], uf[3], corner[8];
  Ints c[3];
  for (int a = 0; a < 3; ++a) {
    Ints c0, c1;
    Floats u0, u1;
    std::memcpy(&c0, &cell[a][0], sizeof c0), std::memcpy(&c1, &cell[a][1], sizeof c1);
    std::memcpy(&u0, &u[a][0], sizeof u0), std::memcpy(&u1, &u[a][1], sizeof u1);
    const Floats l0 = __builtin_convertvector(c0, Floats) + u0, l1 = __builtin_convertvector(c1, Floats) + u1;
    x[a] = l0 + at * (l1 - l0);
  }
  cells_and_corners(b, x, c, uf, corner);
  Vec3<Floats> g;
  trilinear_with_gradient(corner, uf[0], uf[1], uf[2], g, r.wide_values_);
  double gradient[3][L], world[3][L];
  gradients_in_doubles(g, b.scale * double(r.m_), gradient, normal);
  for (int a = 0; a < 3; ++a)
    for (int k = 0; k < L; ++k) world[a][k] = gradient[a][k] * r.unit_gradient_to_world_[a];
  r.shading_.lighting_of_gradients(world, ray_light, ray_half, diffuse, specular);
  for (int k = 0; k < L; ++k) {
    if (!used[k]) continue;
    const double length2 = world[0][k] * world[0][k] + world[1][k] * world[1][k] + world[2][k] * world[2][k];
    const double t_middle = (k == 0 ? prev_t : tk[k - 1]) + double(fraction[k]) * (tk[k] - (k == 0 ? prev_t : tk[k - 1]));
    if (normal[k] && length2 > 0 && length2 < kInf && t_middle > 0) continue;
    const ShadingModel::Lighting l = lighting_at(t_middle, Vec3d(gradient[0][k], gradient[1][k], gradient[2][k]), ray);
    counters.gradients -= normal[k];  // counted where used, as for every lane
    diffuse[k] = l.diffuse, specular[k] = l.specular;
  }
}

/// A segment's lighting from its ends' and its middle's (face_lighting.h): each end's
/// stands for the part in its own cell, the middle's for the cells between.
template <typename Voxel>
ShadingModel::Lighting Tracer<Voxel>::across_faces(const ShadingModel::Lighting& front, const ShadingModel::Lighting& middle,
                                                   const ShadingModel::Lighting& back, const FaceCrossings& f) {
  const float between = f.last - f.first, after = 1 - f.last;
  return {f.first * front.diffuse + between * middle.diffuse + after * back.diffuse,
          f.first * front.specular + between * middle.specular + after * back.specular};
}

/// Whether a sample's gradient (per unit coordinate) is one: not zero (counted as a gradient
/// taken; a zero one is a flat region, which normal_of turns to face the ray).
template <typename Voxel>
bool Tracer<Voxel>::has_normal(const Vec3d& gradient) const {
  return gradients && (gradient.x != 0 || gradient.y != 0 || gradient.z != 0);
}

/// The normal of a sample's gradient, facing the ray; the ray's reverse where the gradient
/// vanishes (a constant region, a mask's inside), as the reference's facing_normal takes it:
/// lit as a surface facing the eye, not left to the ambient term alone. Zero where the frame
/// computes no gradients.
template <typename Voxel>
Vec3d Tracer<Voxel>::normal_of(const Vec3d& gradient, const PrimaryRay& ray) const {
  return gradients ? facing_normal(gradient * r.unit_gradient_to_world_, ray.world.dir) : Vec3d(0.0);
}

/// The lighting at t for the field's gradient there.
template <typename Voxel>
ShadingModel::Lighting Tracer<Voxel>::lighting_at(double t, const Vec3d& gradient, const PrimaryRay& ray) {
  const bool normal = has_normal(gradient);
  counters.gradients += normal;
  if (!r.shading_.lit()) return {};
  if (light_fixed && t > 0) {
    if (normal) {
      // Without forming the unit normal: |n.l| and |n.h| do not depend on which way it faces.
      const Vec3d g = gradient * r.unit_gradient_to_world_;
      const double length2 = dot(g, g);
      if (length2 > 0 && length2 < kInf) return r.shading_.lighting_of_gradient(g, 1 / std::sqrt(length2), ray_light, ray_half);
    }
    return normal ? r.shading_.lighting_with_half(normal_of(gradient, ray), ray_light, ray_half, false) : ray_flat;
  }
  double light_distance;
  return r.shading_.lighting(normal_of(gradient, ray), -ray.world.dir, r.shading_.to_light_along(ray.world, t, light_distance), false);
}

/// DVR: integrates the segment from the previous sample to t, where the value is v and the
/// gradient g (zero: a flat end, lit facing the ray), `voxels` finest voxels long. Shaded
/// with its ends' lighting, weighted by the cell faces between them where both lie in one
/// brick (prev_at and at of `lattice`: face_crossings), the cells between its first and
/// last faces lit at their middle (middle_lighting) or by the ends' mean; else their mean (the back end's alone is
/// half a segment off; the lighting of a mean gradient is not the mean lighting where
/// normals turn). Returns whether the segment showed anything, and so whether t's lighting
/// was computed (s.prev_lighting) for the next segment.
template <typename Voxel>
bool Tracer<Voxel>::integrate(RayState& s, PixelResult& px, float v, double t, double voxels, const Vec3d& g, const PrimaryRay& ray,
                              const CellPoint* prev_at, const CellPoint* at, const PathNode* lattice) {
  Vec3f col;
  float a;
  r.preintegrated_.segment(s.prev_value, v, voxels, col, a);
  if (!(a > 0)) return false;
  const ShadingModel::Lighting back = lighting_at(t, g, ray);
  if (!s.have_prev_lighting && s.have_prev_gradient) s.prev_lighting = lighting_at(s.prev_t, s.prev_gradient, ray);
  if (s.have_prev_gradient) {
    const FaceCrossings f = prev_at ? face_crossings(*prev_at, *at) : FaceCrossings{};
    if (r.p_.middle_lighting && r.shading_.lit() && f.has_middle()) {
      // The lighting where the cells between lie (their middle), as sample_run takes it.
      double l[3];
      for (int k = 0; k < 3; ++k) {
        const float l0 = float(prev_at->cell[k]) + prev_at->u[k], l1 = float(at->cell[k]) + at->u[k];
        l[k] = double(l0 + f.middle() * (l1 - l0));
      }
      Vec3d middle_gradient;
      sample_brick_at(*lattice, l, &middle_gradient, nullptr);
      const ShadingModel::Lighting middle = lighting_at(s.prev_t + double(f.middle()) * (t - s.prev_t), middle_gradient, ray);
      composite(s, px, col, a, t, across_faces(s.prev_lighting, middle, back, f), g, ray);
    } else {
      composite(s, px, col, a, t, s.prev_lighting.mix(back, f.front_weight()), g, ray);
    }
  } else {
    composite(s, px, col, a, t, back, g, ray);
  }
  s.prev_lighting = back;
  return true;
}

/// A stretch dt of ray parameter in finest voxels, opacity's unit (unit_per_t: unit-cube
/// length per unit t).
template <typename Voxel>
double Tracer<Voxel>::to_voxels(double dt, double unit_per_t) const { return dt * unit_per_t / r.finest_voxel_unit_; }

/// DVR's step, in base steps, where a sample counts less. A segment's error reaches the
/// image through the light left to the ray, T = 1 - alpha; where the error per unit
/// length grows with the step (lit DVR: the lighting of a segment's two ends stands for
/// all of it), the fewest samples for a given image error take steps growing as T^-1/2,
/// up to adaptive_step. With face_lighting the error falls faster than the step between
/// steps 0.5 and 0.25 (as its 1.4th power on Marschner-Lobb 64^3), where a law of
/// T^-1/2.4 would fit better; T^-1/2 still takes 0.84x a fixed step's samples at equal
/// error there (AdaptiveStepSpendsSamplesWhereTheyCount; T^-1/2.5 and T^-1/3 saved 0-5%
/// more, not worth a pow per sample). By T alone: weighting the extinction met as well,
/// (T tau)^-1/2, saved 15% more samples on lit fBm but grew the step after every stretch of
/// nothing visible, and stepped over a thin shell behind empty space
/// (AdaptiveStepStillSeesAThinSheetPastEmptySpace: RMSE 0.021 against a fixed step's 0.0025).
template <typename Voxel>
double Tracer<Voxel>::adaptive_step_scale(double alpha) const {
  const double light_left = 1 - alpha, cap = r.p_.adaptive_step;
  return !(light_left * cap * cap > 1) ? cap : 1 / std::sqrt(light_left);  // NaN alpha: the cap, never a NaN step
}

/// Composites a segment of colour c (not premultiplied) and opacity a; t is where it
/// counts for the depth output, and the gradient there its normal. The opacity gathered
/// sets the next step (adaptive_step).
template <typename Voxel>
void Tracer<Voxel>::composite(RayState& s, PixelResult& px, Vec3f c, double a, double t, const ShadingModel::Lighting& light,
                              const Vec3d& gradient, const PrimaryRay& ray) {
  c = r.shading_.apply(c, light);
  s.last_color = c;
  s.accum += Vec3d(c) * ((1 - s.alpha) * a);
  s.alpha += (1 - s.alpha) * a;
  if (r.p_.adaptive_step > 1) s.step_scale = adaptive_step_scale(s.alpha);
  if (px.depth == kInf && s.alpha >= 0.5) {
    px.depth = t;
    if (setup.outputs.normals) px.normal = normal_of(gradient, ray);
  }
}

/// A constant node on a DVR ray (march descends where its next sample is, which may lie inside
/// the node: the ray enters it at t_from). The part-step from the last sample to there goes
/// from that sample's value to the node's; the node is integrated whole from there; and its
/// value at its exit starts the next segment (each part of the ray counts once). Returns
/// whether the ray is finished.
template <typename Voxel>
bool Tracer<Voxel>::dvr_constant(float v, RayState& s, PixelResult& px, const NodeFrame& frame, double t_at, double t_end,
                                 double unit_per_t, double stop, const PrimaryRay& ray) {
  double t_from = t_at;
  if (s.have_prev && s.prev_t < t_at) {
    t_from = std::clamp(node_entry(frame), s.prev_t, t_at);
    integrate(s, px, v, t_from, to_voxels(t_from - s.prev_t, unit_per_t), Vec3d(0.0), ray);
    if (s.alpha >= stop) return true;
  }
  Vec3f col;
  float a;
  r.preintegrated_.segment(v, v, to_voxels(t_end - t_from, unit_per_t), col, a);
  composite(s, px, col, a, t_from, lighting_at(t_from, Vec3d(0.0), ray), Vec3d(0.0), ray);  // flat: facing the ray
  if (s.alpha >= stop) return true;
  s.start_segment(v, t_end);
  return false;
}

/// The pixel of a finished ray: what it gathered over the background, or, terminated, over
/// its last colour.
template <typename Voxel>
void Tracer<Voxel>::finish_dvr(const RayState& s, PixelResult& px, double stop) const {
  if (r.p_.termination_fill && s.alpha >= stop && s.alpha > 0) {
    // Terminated: the light left would have met more of the medium than the background.
    // The last segment's colour is its best guess (the reference's image and raymarch's
    // converge as the termination opacity goes to 1; this estimate converges faster:
    // its error is the light left times how far the colour drifts behind, not times all
    // of it). A ray whose very last segment reaches the opacity is filled too, though
    // nothing lies behind it: an error of at most the light left (1 - the termination
    // opacity) times its colour's distance to the background's.
    px.color = Vec3f(s.accum + Vec3d(s.last_color) * (1 - s.alpha));
    px.alpha = 1;
  } else {
    px.color = Vec3f(s.accum + Vec3d(r.scene_.background) * (1 - s.alpha));
    px.alpha = float(s.alpha);
  }
}

#define BRICKYARD_GIGAVOXELS_DVR(V)                                                                                       \
  template bool Tracer<V>::dvr_constant(float, RayState&, PixelResult&, const NodeFrame&, double, double, double, double,  \
                                        const PrimaryRay&);                                                               \
  template bool Tracer<V>::march_dvr<true>(const Levels&, RayState&, double&, double, double, double, double,             \
                                           const PrimaryRay&, PixelResult&);                                              \
  template bool Tracer<V>::march_dvr<false>(const Levels&, RayState&, double&, double, double, double, double,            \
                                            const PrimaryRay&, PixelResult&);                                             \
  template void Tracer<V>::finish_dvr(const RayState&, PixelResult&, double) const;
BRICKYARD_GIGAVOXELS_FOR_VOXELS(BRICKYARD_GIGAVOXELS_DVR)
#undef BRICKYARD_GIGAVOXELS_DVR

}  // namespace brickyard::gigavoxels
