#pragma once
/// @file tracer.h
/// @brief The rays of the `gigavoxels` back end (renderer.h): a Tracer renders a tile's pixels,
/// each by a march from node to node along its ray (descent.cpp), sampling the bricks of the
/// node each descent stops at with the iso step loop (iso.cpp) or the DVR one (dvr.cpp).
///
/// Here: a ray's state between its nodes, the nodes of its descent as it sees them, and the
/// helpers every part samples and leaps with, defined inline: they run per sample, where a call
/// costs time and a multiply-add split by one rounds differently (the images are kept to the
/// bit). Each part's functions are declared here and defined in its .cpp. Those another part
/// calls are explicitly instantiated there for the brick pool's voxel types; those it keeps to
/// itself are declared inline. Of these, the large ones called from one place are
/// always_inline: with external linkage GCC weighs them as shareable copies and leaves them out
/// of line (sample_run, march), which costs their callers the registers they keep the ray's
/// state in (march_dvr's RayState); in one file's anonymous namespace it had inlined them.
///
/// Thread safety: a Tracer belongs to one thread and one tile (render_tile); it reads its
/// renderer, which nothing writes during a pass, and writes its counters and the ray states of
/// its tile's pixels.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include "core/camera.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/common/pixel.h"
#include "renderers/gigavoxels/face_lighting.h"
#include "renderers/gigavoxels/renderer.h"

namespace brickyard::gigavoxels {

template <typename Voxel>
struct Tracer {
  const GigaVoxelsRenderer<Voxel>& r;
  const FrameSetup& setup;
  const ImageRays rays;
  RayCounters& counters;
  const bool gradients;
  // DVR under a headlight or a directional light: the direction to the light and the half
  // vector are the same at every sample of a ray (past its origin), computed once per ray.
  const bool light_fixed;
  // DVR at one level takes runs of samples side by side (sample_run): with analytic normals
  // (or none), lit by a light fixed along rays (or unlit).
  const bool runs;
  Vec3d ray_light{0.0}, ray_half{0.0};
  // light_fixed: the lighting of a sample with a zero gradient, lit facing the ray (normal_of),
  // the same at every such sample of the ray. Piecewise-constant data (the Shepp-Logan
  // phantom's ellipsoids) has many.
  ShadingModel::Lighting ray_flat;
  uint64_t samples_in_runs = 0;  // of counters.samples
  uint64_t leaps_chained = 0;    // chain_leaps' leaps, each two samples fewer

  Tracer(const GigaVoxelsRenderer<Voxel>& renderer, const FrameSetup& s, RayCounters& c)
      : r(renderer), setup(s), rays(s.camera, s.width, s.height), counters(c), gradients(r.ctx_.needs_gradients(s.outputs)),
        light_fixed(r.scene_.mode == RenderMode::dvr && r.shading_.lit() && r.shading_.light_fixed_along_rays()),
        runs(r.p_.sample_runs && r.scene_.mode == RenderMode::dvr && (!gradients || r.scene_.shading.normals == NormalMethod::analytic) &&
             (!gradients || !r.shading_.lit() || light_fixed)),
        path(size_t(r.source_->max_depth()) + 1), scaled_eye(size_t(r.source_->max_depth()) + 1) {}

  /// A node as the ray sees it, in the node's own coordinates ([0, 1]^3 across the node): the
  /// eye there and the ray's direction per unit t there. Deep zoom needs these: an absolute
  /// unit-cube position has 53 bits, which is one voxel at depth 30 for N = 3, while the eye
  /// relative to a node is computed exactly (see node_frame) and is small wherever the
  /// footprint asks for that node's depth, so a sample is accurate to the last bit of
  /// *relative* position at any depth the tree reaches.
  struct NodeFrame {
    double eye[3] = {};
    double dir[3] = {};
    double inv_dir[3] = {};  // 1 / dir (infinite along an axis the ray is parallel to)
  };

  struct PathNode;
  /// The ray's bricks of the last levels met in the descent, coarsest first: nodes of its
  /// path, stable until the next descent.
  struct Levels {
    const PathNode* b[3] = {};
    int count = 0;
    void push(const PathNode& l) {
      if (count == 3) b[0] = b[1], b[1] = b[2], count = 2;
      b[count++] = &l;
    }
  };

  /// A node of a ray's descent, and its brick as a sample sees it.
  struct PathNode {
    uint32_t address = 0;
    Node node;
    int64_t c[3] = {};  // the node's integer coordinates at its depth
    int depth = 0;
    double scale = 1;  // N^depth, rounded (voxel sizes and gradients only)
    NodeFrame frame;
    const Voxel* brick = nullptr;              // null: no brick
    const uint8_t* group_distances = nullptr;  // per cell group (cell_groups.h)
    const BrickDifferences* differences = nullptr;  // set_brick_bounds
    Levels levels;  // the last 3 bricks down to and including this node's
    // The level's voxel centres within the brick, in brick coordinates, and the last cell
    // between them (enter()): samples clamp to them, as the reference clamps to the volume.
    float inside_lo[3] = {}, inside_hi[3] = {};
    int32_t cell_hi[3] = {};
    bool contains(double t) const {
      for (int a = 0; a < 3; ++a) {
        const double u = frame.eye[a] + frame.dir[a] * t;
        if (!(u >= 0 && u <= 1)) return false;
      }
      return true;
    }
  };

  /// The cell of brick b at brick coordinates l (voxel i + 1 at i; clamped to the level's
  /// voxel centres in the brick, and to the cells between them): its corner values c, where
  /// in it l lies (u), and its lower corner. Past the volume's faces the border only repeats
  /// the face's voxels: a cell reaching into it has no gradient across the face, and a
  /// sample rounded a hair outside (a ray grazing the face) was shaded from a normal lying
  /// in the face.
  void brick_cell(const PathNode& b, const Vec3f& l, int64_t cell[3], float u[3], float c[8]) const {
    const int64_t e = r.m_ + 2;
    for (int a = 0; a < 3; ++a) {
      const float x = l[a] > b.inside_lo[a] ? std::min(l[a], b.inside_hi[a]) : b.inside_lo[a];  // NaN: the low end
      cell[a] = std::min<int64_t>(int64_t(x), b.cell_hi[a]);
      u[a] = x - float(cell[a]);
    }
    const Voxel* q = cell_voxels(b, cell);
    const int64_t dy = e, dz = e * e;
    c[0] = float(q[0]), c[1] = float(q[1]), c[2] = float(q[dy]), c[3] = float(q[dy + 1]);
    c[4] = float(q[dz]), c[5] = float(q[dz + 1]), c[6] = float(q[dz + dy]), c[7] = float(q[dz + dy + 1]);
  }
  /// The trilinear value of brick b at brick coordinates l.
  float brick_value(const PathNode& b, const Vec3f& l) const {
    int64_t cell[3];
    float u[3], c[8];
    brick_cell(b, l, cell, u, c);
    return trilinear(c, u[0], u[1], u[2], r.wide_values_);
  }
  /// sample_brick_at_as for the store's values (needs_wide_interpolation): the flag is tested
  /// once here, so that the usual path is compiled as if there were none (tested inside, it
  /// cost sample_brick_at 30% more instructions).
  float sample_brick_at(const PathNode& b, const double l_at[3], Vec3d* gradient, CellPoint* at) const {
    if (r.wide_values_) [[unlikely]] return sample_wide_brick_at(b, l_at, gradient, at);
    return sample_brick_at_as<false>(b, l_at, gradient, at);
  }
  [[gnu::noinline, gnu::cold]] float sample_wide_brick_at(const PathNode& b, const double l_at[3], Vec3d* gradient,
                                                          CellPoint* at) const {
    return sample_brick_at_as<true>(b, l_at, gradient, at);
  }
  /// The lower corner voxel of a cell of brick b.
  const Voxel* cell_voxels(const PathNode& b, const int64_t cell[3]) const {
    const int64_t e = r.m_ + 2;
    return b.brick + (cell[2] * e + cell[1]) * e + cell[0];
  }
  /// Trilinear value (and gradient per unit coordinate) of a brick at ray parameter t, and
  /// where in the brick's cells t fell (at).
  float sample_brick(const PathNode& b, double t, Vec3d* gradient, CellPoint* at = nullptr) const {
    double l[3];
    brick_coordinates(b, t, l);
    return sample_brick_at(b, l, gradient, at);
  }
  /// Where t lies in brick b, in brick coordinates (voxel i + 1 at i: the border voxel at 0).
  void brick_coordinates(const PathNode& b, double t, double l[3]) const {
    for (int a = 0; a < 3; ++a) l[a] = (b.frame.eye[a] + b.frame.dir[a] * t) * double(r.m_) + 0.5;
  }
  /// sample_brick at brick coordinates l (brick_coordinates), read in float; kWide: for
  /// values near the largest float (needs_wide_interpolation).
  template <bool kWide>
  float sample_brick_at_as(const PathNode& b, const double l_at[3], Vec3d* gradient, CellPoint* at) const {
    const Vec3f l{float(l_at[0]), float(l_at[1]), float(l_at[2])};
    int64_t cell[3];
    float u[3], c[8];
    brick_cell(b, l, cell, u, c);
    if (at)
      for (int a = 0; a < 3; ++a) at->cell[a] = int32_t(cell[a]), at->u[a] = u[a];
    if (!gradient) return trilinear(c, u[0], u[1], u[2], kWide);
    Vec3f g;
    float v;
    if (r.scene_.shading.normals == NormalMethod::analytic) {
      v = trilinear_with_gradient(c, u[0], u[1], u[2], g, kWide);
    } else {
      v = trilinear(c, u[0], u[1], u[2], kWide);
      const Vec3f within{float(cell[0]) + u[0], float(cell[1]) + u[1], float(cell[2]) + u[2]};
      g = difference_gradient(b, within, v, r.scene_.shading.normals == NormalMethod::central);
    }
    *gradient = Vec3d(g) * (b.scale * double(r.m_));
    return v;
  }
  /// The gradient (brick voxels) at brick coordinates l, where the value is v, by central or
  /// forward differences one voxel apart, as the reference and raymarch take them: within
  /// the store brick that holds the cell at l, one-sided at its faces (forward turning
  /// backward at its upper face) and at the volume's. A node's brick starts half a voxel
  /// below its store brick's first voxel, and its 1-voxel border holds one voxel of the
  /// store brick below: in that half voxel, the lower difference reaches that voxel rather
  /// than one further down (the only place the two differ). For the sponge, within the
  /// node's brick. Samples count the values read besides v (raymarch counts 4 or 6 a gradient).
  /// Flattened: confined_difference_gradient, called once here, is otherwise left out of line
  /// (1% more instructions in a lit DVR frame's rays with central differences).
  [[gnu::flatten]] Vec3f difference_gradient(const PathNode& b, const Vec3f& l, float v, bool central) const {
    const int m = r.m_;
    float lo[3], hi[3];  // where the differences may reach, in brick coordinates
    for (int a = 0; a < 3; ++a) {
      if (size_t(b.depth) < r.level_dims_.size()) {
        // The store brick holding the cell of l's voxel position p (clamped into the volume).
        const int64_t dims = r.level_dims_[size_t(b.depth)][a], base = b.c[a] * m - 1;  // p = base + l
        const double p = double(base) + double(l[a]);
        const int64_t cell = std::clamp<int64_t>(int64_t(std::max(p, 0.0)), 0, std::max<int64_t>(0, dims - 2));
        const int64_t brick_lo = cell / m * m, brick_hi = std::min(brick_lo + m, dims - 1);
        lo[a] = float(std::max<int64_t>(brick_lo - base, 0));
        hi[a] = float(std::min<int64_t>(brick_hi - base, m + 1));
      } else {
        lo[a] = l[a] >= 1 ? 1.0f : 0.0f;
        hi[a] = l[a] >= 1 ? float(m + 1) : 1.0f;
      }
    }
    return confined_difference_gradient(l, lo, hi, central, v, [&](const Vec3f& q) {
      ++counters.samples;
      return brick_value(b, q);
    });
  }

  /// The bricks a sample at depth lambda reads: one, or (quadrilinear) the two levels around
  /// lambda among those collected, blended with weight w on the finer.
  struct Blend {
    const PathNode* coarse = nullptr;  // null: `finer` alone
    const PathNode* finer = nullptr;
    double w = 1;
  };
  Blend blend(const Levels& lv, double lambda) const {
    const PathNode& fine = *lv.b[lv.count - 1];
    if (!r.p_.quadrilinear || lv.count == 1 || lambda >= fine.depth) return {nullptr, &fine, 1};
    int i = lv.count - 1;
    while (i > 0 && lv.b[i - 1]->depth > lambda) --i;  // b[i] finer than lambda, b[i-1] coarser
    if (i == 0) return {nullptr, lv.b[0], 1};
    const PathNode& coarse = *lv.b[i - 1];
    const PathNode& finer = *lv.b[i];
    return {&coarse, &finer, std::clamp((lambda - coarse.depth) / double(finer.depth - coarse.depth), 0.0, 1.0)};
  }

  /// Quadrilinear: the two levels around the footprint's depth lambda, among those collected.
  float sample(const Levels& lv, double lambda, double t, Vec3d* gradient) const { return sample(blend(lv, lambda), t, gradient); }
  /// at: where t fell among the finer brick's cells.
  float sample(const Blend& bl, double t, Vec3d* gradient, CellPoint* at = nullptr) const {
    if (!bl.coarse) return sample_brick(*bl.finer, t, gradient, at);
    Vec3d gc(0.0), gf(0.0);
    const float vc = sample_brick(*bl.coarse, t, gradient ? &gc : nullptr);
    const float vf = sample_brick(*bl.finer, t, gradient ? &gf : nullptr, at);
    if (gradient) *gradient = gc * (1 - bl.w) + gf * bl.w;
    return float(vc * (1 - bl.w) + vf * bl.w);
  }

  /// Whether the cell group of brick b at t is clear (holds nothing visible); where the ray
  /// leaves it, or when clear, the cube of clear groups around it; and, when clear, one of its
  /// voxels (every value in the cube is on that voxel's side of every isovalue).
  bool clear_group(const PathNode& b, double t, double& t_leave, float& voxel) const {
    int g[3];
    const int i = group_at(b, t, g);
    t_leave = cube_crossing(b, g, b.group_distances[i], true);
    if (b.group_distances[i] == 0) return false;
    voxel = group_voxel(b, g);
    return true;
  }
  /// A voxel of cell group g of brick b (its lowest corner). In a clear group, every value of
  /// the group, and of each clear group touching it (touching groups share their boundary
  /// voxels), lies in this voxel's interval of hidden values (or on its side of every isovalue).
  float group_voxel(const PathNode& b, const int g[3]) const {
    const size_t e = size_t(r.m_) + 2;
    return float(b.brick[(size_t(g[2]) * kCellGroup * e + size_t(g[1]) * kCellGroup) * e + size_t(g[0]) * kCellGroup]);
  }
  /// DVR: whether every value between two clear groups' voxels is hidden, so that all values
  /// of both groups lie in one interval the transfer function hides.
  bool same_hidden_interval(float a, float b) const { return !r.scene_.value_range_visible(std::min(a, b), std::max(a, b)); }
  /// How many steps dt a leap from t takes to the first sample position past where the clear
  /// groups end (t_leave) or the node does (t_face): 1 or less is a plain step.
  static double leap_steps(double t, double t_leave, double t_face, double dt) {
    return std::ceil((std::max(std::min(t_leave, t_face), t) - t) / dt);
  }

  /// The cell group of brick b at t: its index, and its coordinates in g.
  int group_at(const PathNode& b, double t, int g[3]) const {
    double l[3];
    brick_coordinates(b, t, l);
    return group_of(l, g);
  }
  /// The cell group holding brick coordinates l (clamped into the brick).
  int group_of(const double l[3], int g[3]) const {
    // The voxel clamped into the brick (NaN: 0), then its group by a shift (unsigned division
    // by the power of two). sample_run computes the same in lanes.
    for (int a = 0; a < 3; ++a) g[a] = int(unsigned(child_index(l[a], r.m_ + 2)) / unsigned(kCellGroup));
    return (g[2] * r.groups_ + g[1]) * r.groups_ + g[0];
  }
  /// Where the ray leaves (or enters) the cube of groups centred on group g that its distance
  /// says are clear (just g itself when the distance is 0 or 1).
  double cube_crossing(const PathNode& b, const int g[3], uint8_t distance, bool leaving) const {
    const int reach = std::max(int(distance) - 1, 0);  // clear groups on every side
    double t_cross = leaving ? kInf : -kInf;
    for (int a = 0; a < 3; ++a) {
      if (b.frame.dir[a] == 0) continue;
      const bool upper = (b.frame.dir[a] > 0) == leaving;  // the cube's face the ray crosses there
      const double face = double((upper ? g[a] + reach + 1 : g[a] - reach) * kCellGroup);
      const double ta = ((face - 0.5) * r.inv_m_ - b.frame.eye[a]) * b.frame.inv_dir[a];
      t_cross = leaving ? std::min(t_cross, ta) : std::max(t_cross, ta);
    }
    return t_cross;
  }
  /// Where the ray enters a node, in its frame (before the ray's start when it starts inside).
  static double node_entry(const NodeFrame& frame) {
    double t_entry = -kInf;
    for (int a = 0; a < 3; ++a)
      if (frame.dir[a] != 0) t_entry = std::max(t_entry, ((frame.dir[a] > 0 ? 0.0 : 1.0) - frame.eye[a]) * frame.inv_dir[a]);
    return t_entry;
  }
  /// Where the ray enters the cube of clear groups around t that clear_group leaps (t is in it).
  double clear_cube_entry(const PathNode& b, double t) const {
    int g[3];
    return cube_crossing(b, g, b.group_distances[group_at(b, t, g)], false);
  }

  /// clear_group for what a sample at lambda reads; t_leave is where the answer may change.
  /// Two blended levels are clear together when every blend of theirs is: iso, both clear on
  /// the same side of every isovalue; DVR, both in the same interval of values the transfer
  /// function hides (a clear group's values all lie in one such interval; when the interval
  /// between their voxels is hidden, both lie in the same one).
  bool clear(const Blend& bl, double t, bool iso, double& t_leave, float& voxel) const {
    const bool finer_clear = clear_group(*bl.finer, t, t_leave, voxel);
    if (!bl.coarse || !finer_clear) return finer_clear;
    double t_coarse;
    float coarse_voxel;
    const bool coarse_clear = clear_group(*bl.coarse, t, t_coarse, coarse_voxel);
    t_leave = std::min(t_leave, t_coarse);
    if (!coarse_clear) return false;
    return iso ? !crossing(coarse_voxel, voxel) : same_hidden_interval(coarse_voxel, voxel);
  }

  /// A pixel's footprint at distance t, in unit coordinates, scaled by lod_ratio, and no
  /// larger than the voxels of the coarsest depth that resolves every axis (max_footprint_):
  /// the descent, the levels a sample blends and the step all follow it.
  double footprint(double t) const { return std::min(std::max(t, 1e-300) * r.footprint_per_t_, r.max_footprint_); }
  /// The (fractional) depth whose voxels are as large as a footprint. Per sample wherever
  /// the footprint is coarser than the finest level met, so the log is inlined (log2_fast:
  /// the double log was a tenth of the amplified flight's time, frexp and a float log2 still
  /// 5% of an iso frame's).
  double depth_for(double footprint) const { return -log2_fast(double(r.m_) * footprint) * r.inv_log2_arity_; }
  /// clamp(floor(u), 0, n - 1) (NaN: 0), without floor: below n - 1 and above 0, truncation is it.
  static int64_t child_index(double u, int n) {
    if (u >= double(n - 1)) return n - 1;
    return u > 0 ? int64_t(u) : 0;
  }

  /// The first isosurface whose value going from value a to value b crosses (or lands on);
  /// -1 when none does.
  int first_crossed(float a, float b) const {
    const double da = a, db = b;
    const auto& surfaces = r.scene_.isosurfaces;
    for (size_t k = 0; k < surfaces.size(); ++k)
      if ((da < surfaces[k].value) != (db < surfaces[k].value) || db == surfaces[k].value) return int(k);
    return -1;
  }
  bool crossing(float a, float b) const { return first_crossed(a, b) >= 0; }

  // --- descent.cpp: a ray's march from node to node ------------------------------------------
  [[gnu::always_inline]] inline void pixel(int x, int y, RayState& s, FrameBuffers& out);
  [[gnu::always_inline]] inline void march(const PrimaryRay& ray, RayState& s, RayRecorder& rec, PixelResult& px);
  [[gnu::always_inline]] inline const PathNode& descend(double t_at, Levels& lv, uint32_t& want);
  inline NodeFrame node_frame(int depth, const int64_t c[3]) const;
  /// The eye times N^depth, hi + lo exactly (an error-free product by the double-double
  /// N^depth), for every depth. Every primary ray leaves the same eye, so a tile computes it
  /// once; node frames then only subtract their node's coordinates.
  struct ScaledEye {
    double hi[3] = {}, lo[3] = {};
    bool small = false;  // every |hi| < 2^53
  };
  inline void scale_eye();
  inline void aim(NodeFrame& f, int depth) const;
  inline void enter(PathNode& q, Levels& lv);
  inline void aim_path_along_ray();

  // --- iso.cpp: surfaces ----------------------------------------------------------------------
  /// Two samples on the same side of every isovalue can hide an even number of crossings
  /// between them (a ray grazing a surface, a sheet thinner than the step). A crossing pair
  /// needs both: the ends near enough to an isovalue for the field to reach it and come back
  /// (FieldBounds::slope), and the chord between them near enough for the field to stray to
  /// it (FieldBounds::stray). Where both allow one, the step is halved until each part is
  /// cleared or shows a crossing, or is 2^-hidden_crossings voxels long (search_halvings_).
  struct Bracket {
    double t0 = 0, t1 = 0;
    float v0 = 0, v1 = 0;
  };
  FieldBounds field_bounds(const PathNode& b) const {
    double w[3];  // voxels of b's level per unit t, per axis
    for (int a = 0; a < 3; ++a) w[a] = b.frame.dir[a] * double(r.m_);
    return gigavoxels::field_bounds(*b.differences, w);
  }
  /// The bounds of the brick last searched: a node's level fixes its direction's scale, so
  /// they hold until the brick changes (per ray: the direction does).
  struct CachedBounds {
    const PathNode* node = nullptr;
    const BrickDifferences* differences = nullptr;
    FieldBounds bounds;
    const FieldBounds& of(const PathNode& b, const Tracer& tracer) {
      if (&b != node || b.differences != differences) node = &b, differences = b.differences, bounds = tracer.field_bounds(b);
      return bounds;
    }
  };
  /// What an iso ray's march carries from node to node.
  struct IsoTrace {
    double hit_t = kInf;              // the surface, once found
    uint32_t prev_node = kNoAddress;  // whose brick s.prev_value was sampled from
    CachedBounds bounds;
    double clear_until = -kInf;  // the clear groups the last leap passed end here
  };
  bool iso_constant(float v, IsoTrace& trace, RayState& s, double t_at, double t_face, int entry_axis);
  bool march_iso(const Levels& lv, RayState& s, IsoTrace& trace, double& t_io, double t_end, double t_face, double unit_per_t,
                 bool finest_only);
  inline bool hidden_crossing(const PathNode& b, const FieldBounds& f, uint32_t prev_node, double t0, double t1, float v0,
                              std::optional<float> v1, Bracket& out);
  inline bool may_hide(const FieldBounds& f, double dt, float v0, float v1) const;
  inline bool search_halves(const PathNode& b, const FieldBounds& f, double t0, double t1, float v0, float v1, int halvings,
                            Bracket& out);
  inline double refine_hit(const Levels& lv, double lambda, double t0, double t1, float v0, float v1);
  void finish_iso(const PrimaryRay& ray, double hit_t, PixelResult& px);

  // --- dvr.cpp: volume rendering --------------------------------------------------------------
  bool dvr_constant(float v, RayState& s, PixelResult& px, const NodeFrame& frame, double t_at, double t_end, double unit_per_t,
                    double stop, const PrimaryRay& ray);
  template <bool kOneLevel>
  bool march_dvr(const Levels& lv, RayState& ray_state, double& t_io, double t_end, double t_face, double unit_per_t,
                 double stop, const PrimaryRay& ray, PixelResult& px);
  inline void prefetch_cell(const PathNode& b, const double l[3]) const;
  inline void prefetch_entry_samples(const PathNode& b, double t, double dt, double t_end, double t_face) const;
  inline double chain_leaps(const PathNode& b, double t_next, double& dt, double next_dt, double t_end, double t_face);

  /// How many samples sample_run takes side by side: AVX2's floats.
  static constexpr int kRunLanes = 8;
  // GCC's vector extension: AVX2 where the target has it (x86-64-v3 is the build's floor).
  using LaneFloats = float __attribute__((vector_size(32)));
  using LaneInts = int32_t __attribute__((vector_size(32)));
  /// How a run ended: none (t's group is clear: no run), advanced (t: the next sample
  /// position), finished (the ray is), exited (its last sample was the node's exit: t is past
  /// it), leapt (its last sample started a leap over clear groups: t is the first position
  /// past them, whose last position t - dt starts the next segment).
  enum class Run { none, advanced, finished, exited, leapt };
  /// A sample run's positions (run_positions): one step after another from t, the exit's
  /// at the node's exit; their brick coordinates, read in float as sample_brick_at reads them;
  /// and their cell groups.
  struct RunPositions {
    double tk[kRunLanes];
    float lf[3][kRunLanes];
    int32_t group[kRunLanes];
  };
  /// A sample run's samples, side by side (run_samples, run_lighting, face lighting): point 0
  /// of cell, u and value is the sample before the run, the run's are points 1..kRunLanes.
  struct RunSamples {
    int32_t cell[3][kRunLanes + 1];
    float u[3][kRunLanes + 1];
    float value[kRunLanes + 1];
    double gradient[3][kRunLanes];  // per unit coordinate
    bool normal[kRunLanes];
    // Segments from each sample's predecessor.
    Vec3f color[kRunLanes];
    float alpha[kRunLanes];
    double length[kRunLanes];
    float diffuse[kRunLanes] = {}, specular[kRunLanes] = {};  // the lighting at each sample
    FaceCrossings crossings[kRunLanes];  // none crossed (front weight 1/2) without face lighting
    bool middle[kRunLanes] = {};  // lit between its first and last faces by the lighting at their middle
    float middle_diffuse[kRunLanes] = {}, middle_specular[kRunLanes] = {};
    bool middle_normal[kRunLanes] = {};
  };
  [[gnu::always_inline]] inline Run sample_run(const PathNode& b, RayState& s, PixelResult& px, double& t, double dt, double t_end,
                                               double t_face, double unit_per_t, double stop, int& visible_group, CellPoint& prev_at,
                                               const PathNode*& prev_lattice, bool face_lighting, const PrimaryRay& ray);
  [[gnu::always_inline]] inline int run_positions(const PathNode& b, double t, double dt, double t_end, double t_face,
                                                   RunPositions& at) const;
  [[gnu::always_inline]] inline int run_looks(const PathNode& b, const RunPositions& at, int exit_lane, double dt, double t_end,
                                               double t_face, int& visible_group, Run& ending, std::optional<double>& t_after) const;
  [[gnu::always_inline]] inline void run_samples(const PathNode& b, const RunPositions& at, const RayState& s,
                                                 const CellPoint& prev_at, RunSamples& ln) const;
  [[gnu::always_inline]] inline void run_lighting(const RunPositions& at, int n, const PrimaryRay& ray, RunSamples& ln);
  [[gnu::always_inline]] inline bool composite_run(RayState& s, PixelResult& px, const RunPositions& at, int n, bool lit,
                                                   double stop, const PrimaryRay& ray, const RunSamples& ln);
  [[gnu::always_inline]] inline void cells_and_corners(const PathNode& b, const LaneFloats (&x)[3], LaneInts (&c)[3],
                                                       LaneFloats (&uf)[3], LaneFloats (&corner)[8]) const;
  [[gnu::always_inline]] static inline void gradients_in_doubles(const Vec3<LaneFloats>& g, double to_unit,
                                                                 double (&gradient)[3][kRunLanes], bool (&normal)[kRunLanes]);
  [[gnu::always_inline]] inline void lighting_between(const PathNode& b, const int32_t (&cell)[3][kRunLanes + 1],
                                                      const float (&u)[3][kRunLanes + 1], const FaceCrossings (&crossings)[kRunLanes],
                                                      const bool (&used)[kRunLanes], const double (&tk)[kRunLanes], double prev_t,
                                                      const PrimaryRay& ray, float (&diffuse)[kRunLanes], float (&specular)[kRunLanes],
                                                      bool (&normal)[kRunLanes]);
  static inline ShadingModel::Lighting across_faces(const ShadingModel::Lighting& front, const ShadingModel::Lighting& middle,
                                                    const ShadingModel::Lighting& back, const FaceCrossings& f);
  inline bool has_normal(const Vec3d& gradient) const;
  inline Vec3d normal_of(const Vec3d& gradient, const PrimaryRay& ray) const;
  inline ShadingModel::Lighting lighting_at(double t, const Vec3d& gradient, const PrimaryRay& ray);
  [[gnu::always_inline]] inline bool integrate(RayState& s, PixelResult& px, float v, double t, double voxels, const Vec3d& g,
                                               const PrimaryRay& ray, const CellPoint* prev_at = nullptr, const CellPoint* at = nullptr,
                                               const PathNode* lattice = nullptr);
  inline double to_voxels(double dt, double unit_per_t) const;
  inline double adaptive_step_scale(double alpha) const;
  [[gnu::always_inline]] inline void composite(RayState& s, PixelResult& px, Vec3f c, double a, double t,
                                               const ShadingModel::Lighting& light, const Vec3d& gradient, const PrimaryRay& ray);
  void finish_dvr(const RayState& s, PixelResult& px, double stop) const;

  // --- the ray -----------------------------------------------------------------------------
  double eye[3] = {}, dir[3] = {}, inv_dir[3] = {};  // the ray in the unit cube, per unit t
  /// The last descent (of this ray, or of the tile's previous ray), root first.
  std::vector<PathNode> path;
  int path_size = 0;
  std::vector<ScaledEye> scaled_eye;  // per depth, for the eye scaled_eye_of
  double scaled_eye_of[3] = {kNaN, kNaN, kNaN};  // none yet
  // iso: the surface hit (refine_hit, iso_constant), for finish_iso.
  int hit_surface = -1;
  int face_axis = -1;
  Levels hit_levels;
  double hit_lambda = 0;
  CrossingBracket hit_bracket;  // refine_hit's last bracket, for the normal (crossing_gradient)
};

}  // namespace brickyard::gigavoxels
