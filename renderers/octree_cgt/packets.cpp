// octree_cgt's packets: a square of rays descends the octree's implicit macrocells once,
// nearer half along the frame's major axis K first, culled by the packet's frustum over K and
// by node ranges; each node keeps the lanes whose ray crosses it before their hit so far, and
// the leaves' cells are solved for those lanes (cells.h).

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "renderers/octree_cgt/cells.h"
#include "renderers/octree_cgt/nodes.h"
#include "renderers/octree_cgt/tracer.h"

namespace brickyard::octree_cgt {

namespace {

/// Which of the W lanes from `base` on cross the box [lo, hi] (relative to the packet's eye)
/// within their [t_enter, t_exit]: bit j for lane base + j. One SIMD pass over the packlet.
template <int W>
uint32_t packlet_through(const Packet& p, int base, const float lo[3], const float hi[3]) {
  const float* ix = p.finv[0].data() + base;
  const float* iy = p.finv[1].data() + base;
  const float* iz = p.finv[2].data() + base;
  const float* enter = p.t_enter.data() + base;
  const float* exit = p.t_exit.data() + base;
  int32_t ok[W];
  for (int j = 0; j < W; ++j) {
    const float ax = lo[0] * ix[j], bx = hi[0] * ix[j];
    const float ay = lo[1] * iy[j], by = hi[1] * iy[j];
    const float az = lo[2] * iz[j], bz = hi[2] * iz[j];
    const float t0 = std::max(std::max(enter[j], std::min(ax, bx)), std::max(std::min(ay, by), std::min(az, bz)));
    const float t1 = std::min(std::min(exit[j], std::max(ax, bx)), std::min(std::max(ay, by), std::max(az, bz)));
    ok[j] = t0 <= t1 ? 1 : 0;
  }
  uint32_t bits = 0;
  for (int j = 0; j < W; ++j) bits |= uint32_t(ok[j]) << j;
  return bits;
}

}  // namespace

/// The lanes of `from` whose ray crosses box b before its hit so far, into `to`; whether any
/// does. Packlet by packlet, skipping those with no lane of `from`. In float: the box is
/// widened by more than float's rounding, so no lane that crosses it is lost (a lane let
/// through in excess finds nothing in the cells, which are solved in double).
template <typename T>
template <int W>
bool Tracer<T>::lanes_through(const Packet& p, const Box3d& b, const LaneSet& from, LaneSet& to) const {
  float lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    const double l = b.lo[a] - p.o[a], h = b.hi[a] - p.o[a];
    const double margin = 1e-4 + 1e-6 * std::max(std::abs(l), std::abs(h));
    lo[a] = float(l - margin), hi[a] = float(h + margin);
  }
  constexpr uint64_t kPackletBits = W == 64 ? ~uint64_t(0) : (uint64_t(1) << W) - 1;
  bool any = false;
  const size_t words = size_t(p.lanes + 63) / 64;
  for (size_t w = 0; w < words; ++w) {
    const uint64_t in = from.words[w];
    uint64_t out = 0;
    for (int q = 0; q < 64 / W; ++q) {
      const uint64_t mask = (in >> (q * W)) & kPackletBits;
      if (!mask) continue;
      out |= (uint64_t(packlet_through<W>(p, int(w) * 64 + q * W, lo, hi)) & mask) << (q * W);
    }
    to.words[w] = out;
    any |= out != 0;
  }
  for (size_t w = words; w < to.words.size(); ++w) to.words[w] = 0;
  return any;
}

template <typename T>
void Tracer<T>::render_packets(const Tile& tile, int size, FrameBuffers& out) {
  for (int y0 = tile.y0; y0 < tile.y1; y0 += size)
    for (int x0 = tile.x0; x0 < tile.x1; x0 += size) {
      // A partial packet at the image's border holds only the pixels that are there.
      Packet& p = thread_packet(0);
      p.lanes = 0;
      for (int y = y0; y < std::min(y0 + size, tile.y1); ++y)
        for (int x = x0; x < std::min(x0 + size, tile.x1); ++x) {
          const int i = p.lanes++;
          p.px[size_t(i)] = x, p.py[size_t(i)] = y;
          p.ray[size_t(i)] = primary_ray(rays, r.geo, x, y);
          p.hit[size_t(i)] = Hit{};
        }
      counters.rays += uint64_t(p.lanes);
      pages.begin_ray();
      switch (r.packlet_lanes) {
        case 4: trace_packet<4>(p); break;
        case 8: trace_packet<8>(p); break;
        default: trace_packet<16>(p); break;
      }
      for (int i = 0; i < p.lanes; ++i) {
        PixelResult px;
        px.color = r.scene.background;
        if (p.hit[size_t(i)].surface >= 0) shade(p.ray[size_t(i)], p.hit[size_t(i)], px);
        write_pixel(out, p.px[size_t(i)], p.py[size_t(i)], px);
      }
    }
}

template <typename T>
template <int W>
void Tracer<T>::trace_packet(Packet& p) {
  const int K = r.major_axis, U = (K + 1) % 3, V = (K + 2) % 3;
  int live = 0, forward = 0;
  p.su_lo = p.sv_lo = std::numeric_limits<double>::infinity();
  p.su_hi = p.sv_hi = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < p.lanes; ++i) {
    const PrimaryRay& ray = p.ray[size_t(i)];
    p.live[size_t(i)] = ray.hits();
    p.t_enter[size_t(i)] = std::numeric_limits<float>::infinity();  // in no box
    p.t_exit[size_t(i)] = -std::numeric_limits<float>::infinity();
    if (!ray.hits()) continue;
    p.o = ray.org;  // one eye: every lane starts there
    ++live;
    const double dk = ray.dir[K];
    forward += dk > 0;
    p.inv_dk[size_t(i)] = 1.0 / dk;
    p.inv[size_t(i)] = {1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z};
    for (int a = 0; a < 3; ++a) p.finv[size_t(a)][size_t(i)] = float(std::clamp(p.inv[size_t(i)][a], -1e20, 1e20));
    p.t_enter[size_t(i)] = float_below(ray.span.t0);
    p.update_exit(i);
    const double su = ray.dir[U] / dk, sv = ray.dir[V] / dk;
    p.su_lo = std::min(p.su_lo, su), p.su_hi = std::max(p.su_hi, su);
    p.sv_lo = std::min(p.sv_lo, sv), p.sv_hi = std::max(p.sv_hi, sv);
  }
  if (live == 0) return;
  // Rays that do not all head one way along K (or run parallel to its slices) have no
  // bounding frustum over K: each goes alone.
  const bool coherent = (forward == live || forward == 0) && std::isfinite(p.su_lo + p.su_hi + p.sv_lo + p.sv_hi);
  if (!coherent) {
    ++counters.nodes;  // counted as the packet's one test
    for (int i = 0; i < p.lanes; ++i)
      if (p.live[size_t(i)]) p.hit[size_t(i)] = trace(p.ray[size_t(i)].org, p.ray[size_t(i)].dir, p.ray[size_t(i)].span);
    return;
  }
  p.forward = forward == live;
  LaneSet& all = lanes_at[0];
  all.clear();
  for (int i = 0; i < p.lanes; ++i)
    if (p.live[size_t(i)]) all.set(i);
  descend_packet<W>(p, root(), all, K, U, V);
}

/// Whether the packet's frustum meets the box [lo, hi] (finest voxel coordinates): one test
/// for every lane, before each lane's own.
template <typename T>
bool Tracer<T>::packet_meets(const Packet& p, const Vec3d& lo, const Vec3d& hi, int K, int U, int V) const {
  double k0 = lo[K], k1 = hi[K];
  if (p.forward) k0 = std::max(k0, p.o[K]);
  else k1 = std::min(k1, p.o[K]);
  if (k0 > k1) return false;
  const double s0 = k0 - p.o[K], s1 = k1 - p.o[K];
  const double u_lo = p.o[U] + std::min({s0 * p.su_lo, s0 * p.su_hi, s1 * p.su_lo, s1 * p.su_hi});
  const double u_hi = p.o[U] + std::max({s0 * p.su_lo, s0 * p.su_hi, s1 * p.su_lo, s1 * p.su_hi});
  if (u_hi < lo[U] || u_lo > hi[U]) return false;
  const double v_lo = p.o[V] + std::min({s0 * p.sv_lo, s0 * p.sv_hi, s1 * p.sv_lo, s1 * p.sv_hi});
  const double v_hi = p.o[V] + std::max({s0 * p.sv_lo, s0 * p.sv_hi, s1 * p.sv_lo, s1 * p.sv_hi});
  if (v_hi < lo[V] || v_lo > hi[V]) return false;
  return true;
}

template <typename T>
template <int W>
void Tracer<T>::descend_packet(Packet& p, const Node<T>& n, const LaneSet& parent_lanes, int K, int U, int V) {
  ++counters.nodes;
  if (n.depth < 0) return;  // none(): an unreadable root page
  if (!crosses(n.min, n.max)) return;
  const Box3d box = node_box(n);
  if (!packet_meets(p, box.lo, box.hi, K, U, V)) return;
  LaneSet& lanes = lanes_at[size_t(n.depth) + 1];
  if (!lanes_through<W>(p, box, parent_lanes, lanes)) return;
  if (n.unread_page) {
    Node<T> read = n;
    read.page = page(n.unread_page);
    if (!read.page) return;  // unreadable: its subtree is left empty
    read.unread_page = 0;
    on_path(read);
    lod_leaf(read) ? leaf_cells<W>(p, read, lanes, K, U, V) : descend_children<W>(p, read, lanes, K, U, V);
    return;
  }
  on_path(n);
  if (lod_leaf(n)) return leaf_cells<W>(p, n, lanes, K, U, V);
  descend_children<W>(p, n, lanes, K, U, V);
}

template <typename T>
template <int W>
void Tracer<T>::descend_children(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V) {
  // The half of the children nearer along K first: a lane's hit there is nearer than any
  // in the far half. Within a half, front to back for the packet's middle ray along U and V
  // (for every lane whose ray heads the same way; any other keeps its nearest hit): a lane
  // that hits in a nearer child leaves the farther ones untested.
  const bool flip_k = !p.forward;
  const bool flip_u = p.forward ? p.su_lo + p.su_hi < 0 : p.su_lo + p.su_hi > 0;
  const bool flip_v = p.forward ? p.sv_lo + p.sv_hi < 0 : p.sv_lo + p.sv_hi > 0;
  for (int i = 0; i < 8; ++i) {
    const int oct = ((((i >> 2) & 1) ^ int(flip_k)) << K) | ((((i >> 1) & 1) ^ int(flip_u)) << U) | (((i & 1) ^ int(flip_v)) << V);
    const Node<T> c = child(n, oct);
    if (c.depth >= 0) descend_packet<W>(p, c, lanes, K, U, V);
  }
}

/// A leaf's cells for the lanes that reach it: packlet by packlet where enough do, else lane by
/// lane (packet_cells(), whose per-lane slice walk costs less for a lane or two).
template <typename T>
template <int W>
void Tracer<T>::leaf_cells(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V) {
  if (lanes.count() >= kPackletCellsLanes) packlet_cells<W>(p, n, lanes, K, U, V);
  else packet_cells(p, n, lanes, K, U, V);
}

/// A leaf's cells, nearer slice along K first, each tested against the lanes a packlet at a
/// time (lanes_through(): the lanes whose ray crosses the cell before their hit so far), its
/// corners gathered only if one does, and its cubic solved for those lanes. A lane's hit lowers
/// its exit, so farther cells no longer take it.
template <typename T>
template <int W>
void Tracer<T>::packlet_cells(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V) {
  LeafCells<T> leaf(*this, n);
  if (leaf.empty()) return;
  const double w = double(int64_t(1) << leaf.L);
  LaneSet crossing;
  for (int64_t step = 0; step <= leaf.hi[K] - leaf.lo[K]; ++step) {
    const int64_t k = p.forward ? leaf.lo[K] + step : leaf.hi[K] - step;
    for (int64_t a = leaf.lo[U]; a <= leaf.hi[U]; ++a)
      for (int64_t b = leaf.lo[V]; b <= leaf.hi[V]; ++b) {
        Vec3s cell;
        cell[K] = k, cell[U] = a, cell[V] = b;
        Box3d box;
        for (int x = 0; x < 3; ++x) box.lo[x] = (double(cell[x]) + 0.5) * w - 0.5, box.hi[x] = box.lo[x] + w;
        if (!lanes_through<W>(p, box, lanes, crossing) || !leaf.gather(cell)) continue;
        crossing.for_each([&](int i) { leaf.intersect(p, i, cell); });
      }
  }
  if (leaf.coarse >= 0) lanes.for_each([&](int i) { leaf.transition(p, i); });
}

#define BRICKYARD_OCTREE_CGT_PACKETS(V) template void Tracer<V>::render_packets(const Tile&, int, FrameBuffers&);
BRICKYARD_OCTREE_CGT_FOR_VOXELS(BRICKYARD_OCTREE_CGT_PACKETS)
#undef BRICKYARD_OCTREE_CGT_PACKETS

}  // namespace brickyard::octree_cgt
