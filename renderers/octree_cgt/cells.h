#pragma once
/// @file cells.h
/// @brief octree_cgt: a leaf node's cells for the lanes that reach it, slice by slice along
/// K, their corners gathered once, and each cell's trilinear cubic along a ray solved for its
/// first root. Part of Tracer (tracer.h).

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/octree_cgt/tracer.h"
#include "renderers/octree_cgt/transition.h"

namespace brickyard::octree_cgt {

/// The scalars of the node at depth d and coordinates c (a cap, or a coarser node where the
/// level of detail stops above the caps).
template <typename T>
const OctreeScalars<T>& Tracer<T>::scalars_at(int d, const Vec3s& c) {
  CapEntry& e = caps[cap_slot(d, c)];
  if (e.c == c && e.depth == d && e.generation == pages.generation()) return e.scalars;
  ++counters.samples;  // a lookup of the octree
  e.c = c, e.depth = d, e.generation = pages.generation();
  for (int a = d - 1; a >= 0; --a) {
    const PathEntry& anc = path[size_t(a)];
    const int up = d - a;
    if (anc.generation == pages.generation() && anc.c == Vec3s{c.x >> up, c.y >> up, c.z >> up}) {
      e.scalars = octree_scalars_below<T>(r.layout, pages, {*anc.page, anc.page->header->root_depth, anc.level, anc.index, a}, d, c);
      return e.scalars;
    }
  }
  e.scalars = octree_scalars<T>(r.layout, pages, d, c);
  return e.scalars;
}

/// Voxels lo + {0, 1, 2}^3 of the cap n (lo = 2 n.c), x fastest: the cap's own 8 and its
/// forward neighbours', one lookup per neighbouring cap, of the neighbours (bit x + 2y + 4z of
/// `parts`, 0 the cap itself) asked for. Voxels past the volume's last are never a corner of a
/// cell; they are left at the cap's first.
template <typename T>
void Tracer<T>::cap_block(const Node<T>& n, const Vec3s& lo, double block[27], unsigned parts) {
  const T* own = own_scalars(n);
  const Vec3s all = r.nodes_at[size_t(n.depth)];
  for (int nb = 0; nb < 8; ++nb) {
    if (!((parts >> nb) & 1u)) continue;
    const Vec3s off{nb & 1, (nb >> 1) & 1, (nb >> 2) & 1};
    const Vec3s cc = n.c + off;
    if (cc.x >= all.x || cc.y >= all.y || cc.z >= all.z) {
      for (int64_t z = 0; z < 3; ++z)
        for (int64_t y = 0; y < 3; ++y)
          for (int64_t x = 0; x < 3; ++x)
            if ((x == 2) == bool(off.x) && (y == 2) == bool(off.y) && (z == 2) == bool(off.z))
              block[(z * 3 + y) * 3 + x] = own ? double(own[0]) : n.constant;
      continue;
    }
    const OctreeScalars<T>* other = nb == 0 ? nullptr : &scalars_at(n.depth, cc);
    for (int64_t z = off.z * 2; z <= (off.z ? 2 : 1); ++z)
      for (int64_t y = off.y * 2; y <= (off.y ? 2 : 1); ++y)
        for (int64_t x = off.x * 2; x <= (off.x ? 2 : 1); ++x) {
          const int octant = int((lo.x + x) & 1) | int(((lo.y + y) & 1) << 1) | int(((lo.z + z) & 1) << 2);
          block[(z * 3 + y) * 3 + x] = nb == 0 ? (own ? double(own[octant]) : n.constant) : double((*other)[octant]);
        }
  }
}

/// A leaf's cells at its own level L (0 at the caps), in level coordinates (level-L voxel i
/// sits at finest coordinate (i + 1/2) 2^L - 1/2; rays keep their parameter t): each cell's
/// corners gathered once, for the first lane that reaches it, from the cap's 3x3x3 block (its
/// own voxels and its forward neighbours', each neighbour read when a cell needs it) or, without
/// slice reuse, by 8 lookups; and whether the cell's range holds an isovalue.
template <typename T>
struct LeafCells {
  Tracer<T>& t;
  const Node<T>& n;
  const int L;
  const double scale;  // 2^-L
  Vec3s lo, hi;        // the cells, level-L voxel coordinates
  double block[27];
  unsigned block_parts = 0;
  double corners[8][8], vlo[8], vhi[8];
  uint8_t state[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // 0: not gathered, 1: may cross, 2: culled
  const int coarse;  // the +K neighbour's level where it is coarser (transition.h); -1: none
  bool transition_built = false;

  LeafCells(Tracer<T>& tracer, const Node<T>& node)
      : t(tracer), n(node), L(t.r.layout.level_of_depth(n.depth)), scale(1.0 / double(int64_t(1) << L)),
        coarse(t.coarser_neighbour_level(n)) {
    const Vec3s dims = t.r.level_dims[size_t(L)];
    lo = n.c * int64_t(2);
    hi = {std::min(lo.x + 1, dims.x - 2), std::min(lo.y + 1, dims.y - 2), std::min(lo.z + 1, dims.z - 2)};
  }
  bool empty() const { return hi.x < lo.x || hi.y < lo.y || hi.z < lo.z; }
  Vec3d to_level(const Vec3d& x) const { return L ? (x + Vec3d(0.5)) * scale - Vec3d(0.5) : x; }
  static int local(const Vec3s& q) { return int(q.x) | int(q.y << 1) | int(q.z << 2); }

  /// Gathers the corners of `cell` (once); whether its range may hold an isovalue.
  bool gather(const Vec3s& cell) {
    const Vec3s q = cell - lo;
    const int c = local(q);
    if (state[c] == 0 && !t.r.p.slice) {
      t.cell_corners(cell, n, t.own_scalars(n), corners[c], vlo[c], vhi[c]);
      state[c] = t.crosses_corners(vlo[c], vhi[c]) ? 1 : 2;
    }
    if (state[c] == 0) {
      double& l = vlo[c] = std::numeric_limits<double>::max();
      double& h = vhi[c] = std::numeric_limits<double>::lowest();
      // Cell q's corners lie in the neighbours nb with nb's bits among q's.
      static constexpr uint8_t kCornerParts[8] = {0x01, 0x03, 0x05, 0x0f, 0x11, 0x33, 0x55, 0xff};
      const unsigned need = kCornerParts[c];
      if (need & ~block_parts) t.cap_block(n, lo, block, need & ~block_parts), block_parts |= need;
      for (int m = 0; m < 8; ++m) {
        const double v = block[((q.z + ((m >> 2) & 1)) * 3 + q.y + ((m >> 1) & 1)) * 3 + q.x + (m & 1)];
        corners[c][m] = v, l = std::min(l, v), h = std::max(h, v);
      }
      state[c] = t.crosses_corners(l, h) ? 1 : 2;
    }
    return state[c] == 1;
  }

  /// Lane i's ray against a gathered cell: the nearer root, its level, the lane's float exit.
  bool intersect(Packet& p, int i, const Vec3s& cell) {
    const PrimaryRay& ray = p.ray[size_t(i)];
    const int c = local(cell - lo);
    const bool found = t.intersect(cell, corners[c], vlo[c], vhi[c], to_level(ray.org), L ? ray.dir * scale : ray.dir,
                                   L ? p.inv[size_t(i)] / scale : p.inv[size_t(i)], ray.span, p.hit[size_t(i)]);
    if (found) p.hit[size_t(i)].level = L, p.update_exit(i);
    return found;
  }

  /// Lane i's ray against the slab between this leaf and its coarser +K neighbour.
  void transition(Packet& p, int i) {
    if (coarse < 0) return;
    if (!transition_built) t.build_transition(n, coarse, t.transition), transition_built = true;
    const PrimaryRay& ray = p.ray[size_t(i)];
    bool found = false;
    for (int b = 0; b < t.transition.boxes; ++b)
      found |= t.intersect_box(t.transition.box[size_t(b)], ray.org, ray.dir, p.inv[size_t(i)], ray.span, p.hit[size_t(i)]);
    if (found) p.hit[size_t(i)].level = L, p.update_exit(i);
  }
};

/// A leaf's cells lane by lane: each lane visits only the cells its ray crosses in each of the
/// leaf's slices along K (at most 2 x 2 a slice: K is the major axis), nearer slice first, and
/// stops at its first hit. For the single-ray mode and for leaves few lanes reach
/// (packlet_cells() takes the others).
template <typename T>
void Tracer<T>::packet_cells(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V) {
  LeafCells<T> leaf(*this, n);
  if (leaf.empty()) return;
  const Vec3s lo = leaf.lo, hi = leaf.hi;
  const Vec3d o = leaf.to_level(p.o);
  constexpr double kSlack = 1e-9;  // cell ranges are widened: the exact test is intersect()'s
  lanes.for_each([&](int i) {
    const PrimaryRay& ray = p.ray[size_t(i)];
    const double su = ray.dir[U] * p.inv_dk[size_t(i)], sv = ray.dir[V] * p.inv_dk[size_t(i)];
    for (int64_t step = 0; step <= hi[K] - lo[K]; ++step) {
      const int64_t k = p.forward ? lo[K] + step : hi[K] - step;
      const double s0 = double(k) - o[K], s1 = s0 + 1;
      const double u0 = o[U] + s0 * su, u1 = o[U] + s1 * su, v0 = o[V] + s0 * sv, v1 = o[V] + s1 * sv;
      const int64_t a0 = std::max(lo[U], int64_t(std::floor(std::min(u0, u1) - kSlack)));
      const int64_t a1 = std::min(hi[U], int64_t(std::floor(std::max(u0, u1) + kSlack)));
      const int64_t b0 = std::max(lo[V], int64_t(std::floor(std::min(v0, v1) - kSlack)));
      const int64_t b1 = std::min(hi[V], int64_t(std::floor(std::max(v0, v1) + kSlack)));
      bool found = false;
      for (int64_t a = a0; a <= a1; ++a)
        for (int64_t b = b0; b <= b1; ++b) {
          Vec3s cell;
          cell[K] = k, cell[U] = a, cell[V] = b;
          if (leaf.gather(cell)) found |= leaf.intersect(p, i, cell);
        }
      if (found) break;  // the next slice is farther along this ray
    }
    leaf.transition(p, i);
  });
}

/// The cells of a leaf node for one ray: the packets' cell code with one lane, K the ray's
/// own major axis (never parallel to its slices).
template <typename T>
void Tracer<T>::single_cells(const Node<T>& n, const Vec3d& o, const Vec3d& d, Interval<double> span, Hit& best) {
  Packet& p = thread_packet(1);
  const int K = std::abs(d.x) >= std::abs(d.y) && std::abs(d.x) >= std::abs(d.z) ? 0 : std::abs(d.y) >= std::abs(d.z) ? 1 : 2;
  p.lanes = 1;
  p.ray[0].org = o, p.ray[0].dir = d, p.ray[0].span = span;
  p.inv[0] = {1.0 / d.x, 1.0 / d.y, 1.0 / d.z};
  p.inv_dk[0] = 1.0 / d[K];
  p.o = o;
  p.forward = d[K] > 0;
  p.hit[0] = best;
  LaneSet lane;
  lane.set(0);
  packet_cells(p, n, lane, K, (K + 1) % 3, (K + 2) % 3);
  best = p.hit[0];
}

/// Voxel v of the level node n holds (its own scalars, or a neighbour's at n's depth).
template <typename T>
double Tracer<T>::corner(const Vec3s& v, const Node<T>& n, const T* own) {
  const int octant = int(v.x & 1) | int((v.y & 1) << 1) | int((v.z & 1) << 2);
  if (v.x >> 1 == n.c.x && v.y >> 1 == n.c.y && v.z >> 1 == n.c.z) return n.consolidated ? n.constant : double(own[octant]);
  return double(scalars_at(n.depth, {v.x >> 1, v.y >> 1, v.z >> 1})[octant]);
}

/// A cell's 8 corners (index dx + 2 dy + 4 dz) and their range.
template <typename T>
void Tracer<T>::cell_corners(const Vec3s& cell, const Node<T>& n, const T* cap, double c[8], double& lo, double& hi) {
  lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
  for (int k = 0; k < 8; ++k) {
    c[k] = corner({cell.x + (k & 1), cell.y + ((k >> 1) & 1), cell.z + ((k >> 2) & 1)}, n, cap);
    lo = std::min(lo, c[k]), hi = std::max(hi, c[k]);
  }
}

/// One ray against one cell of corners c: the first root of each isosurface's cubic.
template <typename T>
bool Tracer<T>::intersect(const Vec3s& cell, const double c[8], double lo, double hi, const Vec3d& o, const Vec3d& d,
               const Vec3d& inv, Interval<double> s, Hit& best) {
  const Vec3d cell_lo{double(cell.x), double(cell.y), double(cell.z)};
  const Interval<double> cs = clip_to_box(s, cell_lo, cell_lo + Vec3d(1.0), o, inv);
  if (cs.t0 > cs.t1 || cs.t0 >= best.t) return false;
  ++counters.cells;
  bool found = false;
  for (size_t i = 0; i < r.iso.size(); ++i) {
    const double iso = r.iso[i];
    if (r.p.cell && (iso < lo || iso > hi)) continue;
    const Vec3d p0 = o + d * cs.t0;
    const double u0[3] = {p0.x - double(cell.x), p0.y - double(cell.y), p0.z - double(cell.z)};
    const double du[3] = {d.x, d.y, d.z};
    const Cubic g = trilinear_cubic(c, iso, u0, du);
    const auto root = first_root_falsi(g, cs.t1 - cs.t0, 64, r.p.root_tolerance);
    if (!root) continue;
    const double t = cs.t0 + *root;
    if (t >= best.t) continue;
    best.t = t, best.surface = int(i), found = true;
    const Vec3d u{u0[0] + du[0] * *root, u0[1] + du[1] * *root, u0[2] + du[2] * *root};
    best.normal_voxel = trilinear_gradient(c, u.x, u.y, u.z);
  }
  return found;
}

}  // namespace brickyard::octree_cgt
