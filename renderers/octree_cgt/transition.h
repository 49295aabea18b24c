#pragma once
/// @file transition.h
/// @brief octree_cgt's smooth transitions between levels of detail (the issue's "smooth
/// transitions by reading coarser voxels at the transition slice"). A leaf drawn at level L
/// whose +K neighbour is drawn at a coarser level C leaves a slab without cells: its own cells
/// end at its neighbour's first level-L voxel slice, (2^L - 1) / 2 past their common face, the
/// neighbour's begin at its first level-C slice, (2^C - 1) / 2 past it; a ray through the slab
/// would see neither surface (a crack). The slab gets cells of its own: their near face the
/// level-L voxels' bilinear interpolant, their far face the level-C one's, so that each face
/// is exactly the surface beside it. A fine cell's column is split where a coarse voxel
/// centre falls inside it (at most once per axis), so that the far face is bilinear on every
/// piece and meets the coarse cells' faces exactly. (On the -K side a coarser neighbour's
/// cells overlap the leaf's instead: nearest hit wins, no gap.) Part of Tracer (tracer.h).

#include <algorithm>
#include <array>
#include <cmath>

#include "renderers/octree_cgt/tracer.h"

namespace brickyard::octree_cgt {

template <typename T>
int Tracer<T>::coarser_neighbour_level(const Node<T>& n) const {
  if (!r.lod || !r.p.smooth) return -1;
  const int K = r.major_axis;
  Vec3s nb = n.c;
  nb[K] += 1;
  if (nb[K] >= r.nodes_at[size_t(n.depth)][K]) return -1;
  // The neighbour's leaf is its shallowest ancestor where the level of detail stops (n's own
  // ancestors do not stop there: n is drawn).
  for (int a = 0; a < n.depth; ++a) {
    const int up = n.depth - a;
    if (lod_stops(a, {nb.x >> up, nb.y >> up, nb.z >> up})) return r.layout.level_of_depth(a);
  }
  return -1;
}

template <typename T>
double Tracer<T>::voxel_at(int level, const Vec3s& v) {
  const int octant = int(v.x & 1) | int((v.y & 1) << 1) | int((v.z & 1) << 2);
  return double(scalars_at(r.layout.depth - 1 - level, {v.x >> 1, v.y >> 1, v.z >> 1})[octant]);
}

template <typename T>
void Tracer<T>::build_transition(const Node<T>& n, int coarse, Transition& out) {
  out.boxes = 0;
  const int K = r.major_axis, U = (K + 1) % 3, V = (K + 2) % 3;
  const int L = r.layout.level_of_depth(n.depth);
  const Vec3s fine_dims = r.level_dims[size_t(L)], coarse_dims = r.level_dims[size_t(coarse)];
  const double fine_w = double(int64_t(1) << L), coarse_w = double(int64_t(1) << coarse);
  const auto centre = [](int64_t i, double w) { return (double(i) + 0.5) * w - 0.5; };  // finest coordinates
  const int64_t kf = 2 * n.c[K] + 2;                                 // the neighbour's first level-L slice
  const int64_t kc = ((n.c[K] + 1) * width(n.depth)) >> coarse;      // and its first level-C slice
  if (kf >= fine_dims[K] || kc >= coarse_dims[K]) return;
  const double s_near = centre(kf, fine_w), s_far = centre(kc, coarse_w);
  // Each box corner reads 4 voxels of one face; the faces' few voxels (3 x 3 of the near one,
  // as many of the far one) are read once each.
  std::array<double, 9> fine{};
  std::array<bool, 9> have_fine{};
  const auto fine_voxel = [&](int64_t a, int64_t b) {
    const size_t m = size_t((a - 2 * n.c[U]) * 3 + (b - 2 * n.c[V]));
    if (!have_fine[m]) {
      Vec3s x;
      x[K] = kf, x[U] = a, x[V] = b;
      fine[m] = voxel_at(L, x), have_fine[m] = true;
    }
    return fine[m];
  };
  struct CoarseVoxel {
    int64_t u, v;
    double value;
  };
  std::array<CoarseVoxel, 16> coarse_read{};
  size_t coarse_reads = 0;
  const auto coarse_voxel = [&](int64_t u, int64_t v) {
    for (size_t m = 0; m < coarse_reads; ++m)
      if (coarse_read[m].u == u && coarse_read[m].v == v) return coarse_read[m].value;
    Vec3s x;
    x[K] = kc, x[U] = u, x[V] = v;
    const double value = voxel_at(coarse, x);
    if (coarse_reads < coarse_read.size()) coarse_read[coarse_reads++] = {u, v, value};
    return value;
  };
  // The level-L voxels' bilinear interpolant on the near face, inside the column (a, b).
  const auto near_value = [&](int64_t a, int64_t b, double u, double v) {
    const double fu = (u - centre(a, fine_w)) / fine_w, fv = (v - centre(b, fine_w)) / fine_w;
    double c[2][2];
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) c[i][j] = fine_voxel(a + i, b + j);
    return (1 - fv) * ((1 - fu) * c[0][0] + fu * c[1][0]) + fv * ((1 - fu) * c[0][1] + fu * c[1][1]);
  };
  // The level-C voxels' bilinear interpolant on the far face (clamped at the volume's edges).
  const auto far_value = [&](double u, double v) {
    double w[2];
    int64_t i0[2];
    const double pos[2] = {u, v};
    const int axes[2] = {U, V};
    for (int q = 0; q < 2; ++q) {
      const double x = (pos[q] + 0.5) / coarse_w - 0.5;
      const int64_t last = coarse_dims[axes[q]] - 1;
      i0[q] = std::clamp<int64_t>(int64_t(std::floor(x)), 0, std::max<int64_t>(last - 1, 0));
      w[q] = last == 0 ? 0.0 : std::clamp(x - double(i0[q]), 0.0, 1.0);
    }
    double c[2][2];
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) c[i][j] = coarse_voxel(std::min(i0[0] + i, coarse_dims[U] - 1), std::min(i0[1] + j, coarse_dims[V] - 1));
    return (1 - w[1]) * ((1 - w[0]) * c[0][0] + w[0] * c[1][0]) + w[1] * ((1 - w[0]) * c[0][1] + w[0] * c[1][1]);
  };
  // Where a column's side [lo, hi] (finest coordinates) is cut: at the coarse voxel centre
  // inside it, if one is.
  const auto cuts = [&](double lo, double hi, double out_cuts[3]) {
    out_cuts[0] = lo;
    const double inside = centre(int64_t(std::floor((lo + 0.5) / coarse_w - 0.5)) + 1, coarse_w);
    int m = 1;
    if (inside > lo && inside < hi) out_cuts[m++] = inside;
    out_cuts[m++] = hi;
    return m;
  };
  const int64_t a_hi = std::min(2 * n.c[U] + 1, fine_dims[U] - 2), b_hi = std::min(2 * n.c[V] + 1, fine_dims[V] - 2);
  for (int64_t a = 2 * n.c[U]; a <= a_hi; ++a)
    for (int64_t b = 2 * n.c[V]; b <= b_hi; ++b) {
      double cu[3], cv[3];
      const int mu = cuts(centre(a, fine_w), centre(a + 1, fine_w), cu);
      const int mv = cuts(centre(b, fine_w), centre(b + 1, fine_w), cv);
      for (int i = 0; i + 1 < mu; ++i)
        for (int j = 0; j + 1 < mv; ++j) {
          TransitionBox& box = out.box[size_t(out.boxes++)];
          box.lo[K] = s_near, box.hi[K] = s_far;
          box.lo[U] = cu[i], box.hi[U] = cu[i + 1];
          box.lo[V] = cv[j], box.hi[V] = cv[j + 1];
          box.vlo = std::numeric_limits<double>::max(), box.vhi = std::numeric_limits<double>::lowest();
          for (int m = 0; m < 8; ++m) {
            const int bit[3] = {m & 1, (m >> 1) & 1, (m >> 2) & 1};  // x, y, z
            const double u = bit[U] ? box.hi[U] : box.lo[U], v = bit[V] ? box.hi[V] : box.lo[V];
            const double value = bit[K] ? far_value(u, v) : near_value(a, b, u, v);
            box.corners[m] = value, box.vlo = std::min(box.vlo, value), box.vhi = std::max(box.vhi, value);
          }
        }
    }
}

template <typename T>
bool Tracer<T>::intersect_box(const TransitionBox& box, const Vec3d& o, const Vec3d& d, const Vec3d& inv, Interval<double> s,
                              Hit& best) {
  if (!crosses_corners(box.vlo, box.vhi)) return false;
  const Interval<double> cs = clip_to_box(s, box.lo, box.hi, o, inv);
  if (cs.t0 > cs.t1 || cs.t0 >= best.t) return false;
  ++counters.cells;
  const Vec3d extent = box.hi - box.lo;
  const Vec3d p0 = o + d * cs.t0;
  const double u0[3] = {(p0.x - box.lo.x) / extent.x, (p0.y - box.lo.y) / extent.y, (p0.z - box.lo.z) / extent.z};
  const double du[3] = {d.x / extent.x, d.y / extent.y, d.z / extent.z};
  bool found = false;
  for (size_t i = 0; i < r.iso.size(); ++i) {
    const double iso = r.iso[i];
    if (r.p.cell && (iso < box.vlo || iso > box.vhi)) continue;
    const Cubic g = trilinear_cubic(box.corners, iso, u0, du);
    const auto root = first_root_falsi(g, cs.t1 - cs.t0, 64, r.p.root_tolerance);
    if (!root) continue;
    const double t = cs.t0 + *root;
    if (t >= best.t) continue;
    best.t = t, best.surface = int(i), found = true;
    const Vec3d g_local = trilinear_gradient(box.corners, u0[0] + du[0] * *root, u0[1] + du[1] * *root, u0[2] + du[2] * *root);
    best.normal_voxel = g_local / extent;  // back to finest voxel coordinates
  }
  return found;
}

}  // namespace brickyard::octree_cgt
