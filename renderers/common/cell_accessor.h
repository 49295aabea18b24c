#pragma once
/// @file cell_accessor.h
/// @brief Reads the cells of one level of a store through the cache, remembering the brick
/// it used last, so that the coherent accesses of a ray cost one comparison (OpenVDB's
/// ValueAccessor, STYLE.md 5).
///
/// Not thread-safe: each thread (each tile) takes its own. It holds at most one pinned
/// brick handle at a time and releases it when destroyed. Reads block (BrickCache::fetch)
/// when a brick is not resident: for the reference renderer, the `raymarch` baseline and
/// tools; the GPU-style back ends use non-blocking lookups instead.
///
/// Cell (i, j, k) is the cube between voxels (i, j, k) and (i+1, j+1, k+1); its corners
/// beyond the last voxel clamp to it, so 1-voxel-thick volumes have flat cells.
///
/// A brick that cannot be read (corrupt or missing: the cache records it, and the render
/// command reports it) is stood in for by the level above, trilinearly, up to the root; voxels
/// no readable level holds are NaN, which no isovalue crosses and the transfer function
/// takes as its lowest value. The other back ends follow the same rule: a coarser level where
/// one can be read, else nothing.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>

#include "cache/brick_cache.h"
#include "renderers/common/frame.h"

namespace brickyard {

namespace detail {
template <typename V>
V trilinear_wide(const V c[8], V ux, V uy, V uz);
}  // namespace detail

template <typename Stored>
class CellAccessor {
 public:
  CellAccessor(BrickCache& cache, RayCounters& counters, int level)
      : cache_(cache),
        counters_(counters),
        level_(level),
        M_(cache.layout().brick_size),
        A_(cache.shape().apron),
        E_(cache.shape().edge()),
        dims_(cache.layout().level_dims(level)),
        bricks_(cache.layout().level_bricks(level)) {}

  const Vec3s& dims() const { return dims_; }

  /// @brief The brick holding cell (i, j, k) of the level (i, j, k >= 0); cells past the last
  /// brick belong to it.
  Vec3s brick_of(int64_t i, int64_t j, int64_t k) const {
    return {std::min(i / M_, bricks_.x - 1), std::min(j / M_, bricks_.y - 1), std::min(k / M_, bricks_.z - 1)};
  }

  /// @brief The 8 corner values of cell (i, j, k), index dx + 2 dy + 4 dz. The cell must lie
  /// in the level (0 <= i < dims); corners past the last voxel clamp.
  template <typename V>
  void corners(int64_t i, int64_t j, int64_t k, V c[8]) {
    if (A_ < 1) {  // no apron: corners may lie in neighbouring bricks
      for (int n = 0; n < 8; ++n) c[n] = voxel<V>(i + (n & 1), j + ((n >> 1) & 1), k + ((n >> 2) & 1));
      return;
    }
    const Vec3s b = brick_of(i, j, k);
    bind(b);
    if (damaged_) [[unlikely]] {
      for (int n = 0; n < 8; ++n) c[n] = V(stand_in(i + (n & 1), j + ((n >> 1) & 1), k + ((n >> 2) & 1)));
      return;
    }
    if (!data_) {
      for (int n = 0; n < 8; ++n) c[n] = V(constant_);
      return;
    }
    // The apron holds the forward neighbours, so every corner is inside this brick.
    const int64_t x0 = i - b.x * M_ + A_, y0 = j - b.y * M_ + A_, z0 = k - b.z * M_ + A_;
    const int64_t dx = i + 1 < dims_.x ? 1 : 0, dy = j + 1 < dims_.y ? E_ : 0, dz = k + 1 < dims_.z ? int64_t(E_) * E_ : 0;
    const Stored* p = data_ + (z0 * E_ + y0) * E_ + x0;
    c[0] = V(p[0]);
    c[1] = V(p[dx]);
    c[2] = V(p[dy]);
    c[3] = V(p[dx + dy]);
    c[4] = V(p[dz]);
    c[5] = V(p[dx + dz]);
    c[6] = V(p[dy + dz]);
    c[7] = V(p[dx + dy + dz]);
  }

  /// @brief One voxel, clamped into the level.
  template <typename V>
  V voxel(int64_t i, int64_t j, int64_t k) {
    i = std::clamp<int64_t>(i, 0, dims_.x - 1);
    j = std::clamp<int64_t>(j, 0, dims_.y - 1);
    k = std::clamp<int64_t>(k, 0, dims_.z - 1);
    const Vec3s b{i / M_, j / M_, k / M_};
    bind(b);
    if (damaged_) [[unlikely]] return V(stand_in(i, j, k));
    if (!data_) return V(constant_);
    return V(data_[((k - b.z * M_ + A_) * E_ + (j - b.y * M_ + A_)) * E_ + (i - b.x * M_ + A_)]);
  }

 private:
  void bind(const Vec3s& b) {
    if (bound_ && b == brick_) return;
    handle_.release();
    const BrickKey key{uint32_t(level_), uint32_t(b.x), uint32_t(b.y), uint32_t(b.z)};
    ++counters_.lookups;
    ++counters_.bricks;
    handle_ = cache_.lookup(key, 0, /*request_on_miss=*/false);
    if (handle_.ready()) {
      ++counters_.hits;
    } else {
      ++counters_.misses;
      handle_ = cache_.fetch_or_failed(key);
    }
    damaged_ = handle_.failed();
    data_ = handle_.constant() || damaged_ ? nullptr : handle_.voxels<Stored>();
    constant_ = handle_.constant_value();
    brick_ = b;
    bound_ = true;
  }

  /// Voxel (i, j, k) of this level (clamped into it) from the level above: its voxel i lies at
  /// i / 2 - 1 / 4 there (voxel centres of a 2x2x2 average, dataset/grid.h). Out of line: only
  /// damaged bricks take it.
  [[gnu::noinline, gnu::cold]] double stand_in(int64_t i, int64_t j, int64_t k) {
    if (level_ == 0) return std::numeric_limits<double>::quiet_NaN();
    if (!coarser_) coarser_ = std::make_unique<CellAccessor>(cache_, counters_, level_ - 1);
    const int64_t p[3] = {std::clamp<int64_t>(i, 0, dims_.x - 1), std::clamp<int64_t>(j, 0, dims_.y - 1),
                          std::clamp<int64_t>(k, 0, dims_.z - 1)};
    int64_t lo[3];
    double u[3];
    for (int a = 0; a < 3; ++a) {
      const double x = std::clamp(0.5 * double(p[a]) - 0.25, 0.0, double(coarser_->dims()[a] - 1));
      lo[a] = int64_t(x);
      u[a] = x - double(lo[a]);
    }
    double c[8];
    for (int n = 0; n < 8; ++n)
      c[n] = coarser_->template voxel<double>(lo[0] + (n & 1), lo[1] + ((n >> 1) & 1), lo[2] + ((n >> 2) & 1));
    return detail::trilinear_wide(c, u[0], u[1], u[2]);
  }

  BrickCache& cache_;
  RayCounters& counters_;
  int level_;
  int64_t M_, A_, E_;
  Vec3s dims_, bricks_;
  BrickHandle handle_;
  bool bound_ = false;
  Vec3s brick_{-1};
  const Stored* data_ = nullptr;
  float constant_ = 0;
  bool damaged_ = false;
  std::unique_ptr<CellAccessor> coarser_;  // the stand-in level for damaged bricks, made on need
};

namespace detail {

/// @brief a + (b - a) u without forming b - a, which overflows where a and b are of opposite
/// signs near the largest float: a - a u + b u, exact at u = 0 and u = 1.
template <typename V>
[[gnu::always_inline]] inline V lerp_wide(V a, V b, V u) {
  return (a - a * u) + b * u;
}

/// @brief trilinear() where no difference of corners overflows.
template <typename V>
[[gnu::always_inline]] inline V trilinear_fast(const V c[8], V ux, V uy, V uz) {
  const V x00 = c[0] + (c[1] - c[0]) * ux, x10 = c[2] + (c[3] - c[2]) * ux;
  const V x01 = c[4] + (c[5] - c[4]) * ux, x11 = c[6] + (c[7] - c[6]) * ux;
  const V y0 = x00 + (x10 - x00) * uy, y1 = x01 + (x11 - x01) * uy;
  return y0 + (y1 - y0) * uz;
}

/// @brief trilinear_gradient() where no difference of corners overflows.
template <typename V>
[[gnu::always_inline]] inline Vec3<V> trilinear_gradient_fast(const V c[8], V ux, V uy, V uz) {
  const V one = V{} + 1.0f;  // (a vector takes no int)
  const V vx = one - ux, vy = one - uy, vz = one - uz;
  Vec3<V> g;
  g.x = ((c[1] - c[0]) * vy + (c[3] - c[2]) * uy) * vz + ((c[5] - c[4]) * vy + (c[7] - c[6]) * uy) * uz;
  g.y = ((c[2] - c[0]) * vx + (c[3] - c[1]) * ux) * vz + ((c[6] - c[4]) * vx + (c[7] - c[5]) * ux) * uz;
  g.z = ((c[4] - c[0]) * vx + (c[5] - c[1]) * ux) * vy + ((c[6] - c[2]) * vx + (c[7] - c[3]) * ux) * uy;
  return g;
}

/// @brief trilinear_with_gradient() where no difference of corners overflows.
template <typename V>
[[gnu::always_inline]] inline V trilinear_with_gradient_fast(const V c[8], V ux, V uy, V uz, Vec3<V>& g) {
  const V c1 = c[1] - c[0], c2 = c[2] - c[0], c3 = c[3] - c[0];
  const V c4 = c[4] - c[0], c5 = c[5] - c[0], c6 = c[6] - c[0], c7 = c[7] - c[0];
  const V x00 = c1 * ux, x10 = c2 + (c3 - c2) * ux;
  const V x01 = c4 + (c5 - c4) * ux, x11 = c6 + (c7 - c6) * ux;
  const V d0 = c1 + ((c3 - c2) - c1) * uy;
  const V d1 = (c5 - c4) + ((c7 - c6) - (c5 - c4)) * uy;
  const V y0 = x00 + (x10 - x00) * uy, y1 = x01 + (x11 - x01) * uy;
  g.x = d0 + (d1 - d0) * uz;
  g.y = (x10 - x00) + ((x11 - x01) - (x10 - x00)) * uz;
  g.z = y1 - y0;
  return c[0] + (y0 + (y1 - y0) * uz);
}

/// @brief trilinear() for corners whose differences overflow (lerp_wide): finite wherever
/// they are. Out of line, so that the rare path does not grow every sampler it is inlined into.
template <typename V>
[[gnu::noinline, gnu::cold]] V trilinear_wide(const V c[8], V ux, V uy, V uz) {
  const V x00 = lerp_wide(c[0], c[1], ux), x10 = lerp_wide(c[2], c[3], ux);
  const V x01 = lerp_wide(c[4], c[5], ux), x11 = lerp_wide(c[6], c[7], ux);
  return lerp_wide(lerp_wide(x00, x10, uy), lerp_wide(x01, x11, uy), uz);
}

/// @brief trilinear_gradient() for corners whose differences overflow: of halved corners,
/// doubled at the end, so that a gradient within the float range is finite; one past it is
/// infinite along the axes it overflows (facing_normal takes those for its direction).
template <typename V>
[[gnu::noinline, gnu::cold]] Vec3<V> trilinear_gradient_wide(const V c[8], V ux, V uy, V uz) {
  V h[8];
  for (int i = 0; i < 8; ++i) h[i] = c[i] * 0.5f;
  Vec3<V> g = trilinear_gradient_fast(h, ux, uy, uz);
  g.x = g.x * 2.0f, g.y = g.y * 2.0f, g.z = g.z * 2.0f;
  return g;
}

}  // namespace detail

/// @brief Whether a grid's values come near enough to the largest float for differences of
/// corners, and differences of those (trilinear_with_gradient), to overflow: beyond a quarter
/// of it. Then the samplers interpolate the wide way (`wide` below), slower but finite; a
/// step between +-0.6 FLT_MAX once drew flat surfaces up to 11 voxels deep in every float
/// back end. Elsewhere the usual arithmetic costs nothing more.
inline bool needs_wide_interpolation(const GridView& grid) {
  double largest = 0;
  for (const NodeRecord& n : grid.nodes().level(0)) largest = std::max({largest, std::fabs(double(n.min)), std::fabs(double(n.max))});
  return !(largest <= 0.25 * double(std::numeric_limits<float>::max()));
}

/// @brief Trilinear interpolation of corners c (index dx + 2 dy + 4 dz) at local u in [0,1]^3;
/// `wide` for corners whose differences may overflow (needs_wide_interpolation).
template <typename V>
[[gnu::always_inline]] inline V trilinear(const V c[8], V ux, V uy, V uz, bool wide = false) {
  if (wide) [[unlikely]] return detail::trilinear_wide(c, ux, uy, uz);
  return detail::trilinear_fast(c, ux, uy, uz);
}

/// @brief Exact gradient of the trilinear interpolant at u, in voxel units (per voxel).
template <typename V>
[[gnu::always_inline]] inline Vec3<V> trilinear_gradient(const V c[8], V ux, V uy, V uz, bool wide = false) {
  if (wide) [[unlikely]] return detail::trilinear_gradient_wide(c, ux, uy, uz);
  return detail::trilinear_gradient_fast(c, ux, uy, uz);
}

/// @brief trilinear() and trilinear_gradient() together, sharing their interpolations
/// (about half the arithmetic of the two apart). The y and z derivatives are differences of
/// interpolated values, so the corners are taken relative to c[0] first: their rounding then
/// scales with the cell's variation, as trilinear_gradient()'s does, not with its values.
/// Wide corners take the two apart.
template <typename V>
[[gnu::always_inline]] inline V trilinear_with_gradient(const V c[8], V ux, V uy, V uz, Vec3<V>& g, bool wide = false) {
  if (wide) [[unlikely]] {
    g = detail::trilinear_gradient_wide(c, ux, uy, uz);
    return detail::trilinear_wide(c, ux, uy, uz);
  }
  return detail::trilinear_with_gradient_fast(c, ux, uy, uz, g);
}

/// @brief Gradient (voxel units) at p by central or forward differences one voxel apart, each
/// axis confined to [lo, hi]: one-sided at those bounds, forward turning backward at the upper
/// one. f0 is the value at p (read by forward differences alone); value(q) the field at q.
template <typename V, typename Value>
inline Vec3<V> confined_difference_gradient(const Vec3<V>& p, const V lo[3], const V hi[3], bool central, V f0, Value&& value) {
  Vec3<V> g;
  for (int a = 0; a < 3; ++a) {
    Vec3<V> q1 = p, q0 = p;
    q1[a] = std::min(p[a] + V(1), hi[a]);
    q0[a] = central ? std::max(p[a] - V(1), lo[a]) : p[a];
    if (!central && q1[a] - q0[a] < V(0.5)) q0[a] = std::max(p[a] - V(1), lo[a]);  // at the upper face: backward
    const V span = q1[a] - q0[a];
    if (!(span > V(0))) {
      g[a] = 0;  // a flat axis (1-voxel-thick volume)
      continue;
    }
    const V f1 = value(q1);
    const V fm = (!central && q0[a] == p[a]) ? f0 : value(q0);
    g[a] = (f1 - fm) / span;
  }
  return g;
}

/// @brief Continuous sampling of a level at voxel coordinates (clamped into the volume).
template <typename Stored, typename V>
class TrilinearSampler {
 public:
  TrilinearSampler(BrickCache& cache, RayCounters& counters, int level)
      : cells_(cache, counters, level), wide_(needs_wide_interpolation(cache.grid())) {
    for (int a = 0; a < 3; ++a) last_cell_[a] = std::max<int64_t>(0, cells_.dims()[a] - 2);
  }

  V sample(const Vec3<V>& p) {
    int64_t cell[3];
    locate(p, cell, last_u_);
    load(cell);
    return trilinear(c_, last_u_[0], last_u_[1], last_u_[2], wide_);
  }
  /// @brief The exact trilinear gradient (voxel units) at the point of the last sample(p), from
  /// its cell's corners: what sample(p, gradient) gives, for a caller that needs the gradient
  /// only once the value has shown it is wanted (a DVR sample the transfer function makes
  /// visible), without locating p and interpolating again (a tenth of raymarch's lit DVR
  /// instructions). Valid only directly after sample(p): the other sampling calls load other
  /// cells without recording where in them they sampled.
  Vec3<V> last_sample_gradient() const { return trilinear_gradient(c_, last_u_[0], last_u_[1], last_u_[2], wide_); }
  /// @brief Value and exact trilinear gradient (voxel units).
  V sample(const Vec3<V>& p, Vec3<V>& gradient) {
    int64_t cell[3];
    V u[3];
    locate(p, cell, u);
    load(cell);
    gradient = trilinear_gradient(c_, u[0], u[1], u[2], wide_);
    return trilinear(c_, u[0], u[1], u[2], wide_);
  }
  /// @brief Value at p with its cell confined to cells [lo, hi] per axis (p outside them
  /// clamps to their faces): reads only the bricks those cells lie in.
  V sample_within(const Vec3<V>& p, const int64_t lo[3], const int64_t hi[3]) {
    int64_t cell[3];
    V u[3];
    for (int a = 0; a < 3; ++a) {
      const V x = std::clamp(p[a], V(lo[a]), V(hi[a] + (cells_.dims()[a] > 1 ? 1 : 0)));
      cell[a] = std::clamp<int64_t>(int64_t(x), lo[a], hi[a]);
      u[a] = cells_.dims()[a] > 1 ? std::clamp(x - V(cell[a]), V(0), V(1)) : V(0);
    }
    load(cell);
    return trilinear(c_, u[0], u[1], u[2], wide_);
  }

  /// @brief Gradient (voxel units) by central or forward differences one voxel apart,
  /// confined to the brick that holds p's cell: one-sided at its faces, so that shading never
  /// fetches a brick the ray itself did not need (a neighbour whose values cannot contribute).
  /// Takes 6 (central) or 4 (forward) samples.
  Vec3<V> difference_gradient(const Vec3<V>& p, bool central, int64_t brick_size) {
    int64_t lo[3], hi[3];
    V plo[3], phi[3];
    for (int a = 0; a < 3; ++a) {
      const int64_t cell = std::clamp<int64_t>(int64_t(std::max(p[a], V(0))), 0, last_cell_[a]);
      lo[a] = cell / brick_size * brick_size;
      hi[a] = std::min(lo[a] + brick_size - 1, last_cell_[a]);
      plo[a] = V(lo[a]);
      phi[a] = V(std::min(hi[a] + 1, cells_.dims()[a] - 1));
    }
    const V f0 = central ? V(0) : sample_within(p, lo, hi);
    return confined_difference_gradient(p, plo, phi, central, f0, [&](const Vec3<V>& q) { return sample_within(q, lo, hi); });
  }

  CellAccessor<Stored>& cells() { return cells_; }
  const Vec3s& dims() const { return cells_.dims(); }

 private:
  void locate(const Vec3<V>& p, int64_t cell[3], V u[3]) const {
    for (int a = 0; a < 3; ++a) {
      const V hi = V(cells_.dims()[a] - 1);
      const V x = std::clamp(p[a], V(0), hi);  // NaN stays NaN and is caught below
      int64_t i = x >= V(0) ? int64_t(x) : 0;
      i = std::min(i, last_cell_[a]);
      cell[a] = i;
      u[a] = cells_.dims()[a] > 1 ? std::clamp(x - V(i), V(0), V(1)) : V(0);
    }
  }
  void load(const int64_t cell[3]) {
    if (cell[0] == cur_[0] && cell[1] == cur_[1] && cell[2] == cur_[2]) return;
    cells_.corners(cell[0], cell[1], cell[2], c_);
    cur_[0] = cell[0], cur_[1] = cell[1], cur_[2] = cell[2];
  }

  CellAccessor<Stored> cells_;
  bool wide_;  // needs_wide_interpolation
  int64_t last_cell_[3];
  int64_t cur_[3] = {-1, -1, -1};
  V c_[8] = {};
  V last_u_[3] = {};  // where in its cell the last sample(p) was taken
};

}  // namespace brickyard
