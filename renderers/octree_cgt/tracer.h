#pragma once
/// @file tracer.h
/// @brief octree_cgt's traversal state for one tile: the pages it holds, the caps near its
/// rays, its packet; the members are defined by part (see renderer.h).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "dataset/octree_walk.h"
#include "renderers/common/frame.h"
#include "renderers/common/pixel.h"
#include "renderers/octree_cgt/page_memo.h"
#include "renderers/octree_cgt/renderer.h"

namespace brickyard::octree_cgt {

struct Hit {
  double t = std::numeric_limits<double>::infinity();
  int surface = -1;
  int level = 0;            // the level of detail of the cell it was found in (0: finest)
  Vec3d normal_voxel{0.0};  // gradient of the interpolant, voxel coordinates
};

/// A node on the way down: where it is, and where its record is (null for a node inside a
/// consolidated subtree, which has none: its value is `constant`).
template <typename T>
struct Node {
  int depth = 0;
  Vec3s c{0};
  const OctreePage<T>* page = nullptr;
  int level = 0;
  uint32_t index = 0;
  bool consolidated = false;
  double constant = 0;
  float min = 0, max = 0;
  uint64_t unread_page = 0;  // the page rooted here, fetched only once the ray needs it (0: read)
  Vec3s forward_end{0};      // for consolidated nodes: the end (finest voxels) of the subtree that is one value

  static Node none() {
    Node n;
    n.depth = -1;
    return n;
  }
};

/// The part of span where the ray o + t d (inv = 1 / d) is inside the box [lo, hi]. A ray on
/// a face and parallel to it (0 * inf: NaN) stays inside along that axis.
inline Interval<double> clip_to_box(Interval<double> span, const Vec3d& lo, const Vec3d& hi, const Vec3d& o, const Vec3d& inv) {
  for (int a = 0; a < 3; ++a) {
    double t0 = (lo[a] - o[a]) * inv[a], t1 = (hi[a] - o[a]) * inv[a];
    if (t0 > t1) std::swap(t0, t1);
    if (std::isnan(t0)) t0 = -std::numeric_limits<double>::infinity();
    if (std::isnan(t1)) t1 = std::numeric_limits<double>::infinity();
    span.t0 = std::max(span.t0, t0), span.t1 = std::min(span.t1, t1);
  }
  return span;
}

constexpr int kMaxLanes = 16 * 16;

/// Lanes of a packet as bits: lane i is bit i % 64 of word i / 64, so that a packlet of W
/// lanes (W dividing 64) is W adjacent bits of one word.
struct LaneSet {
  std::array<uint64_t, kMaxLanes / 64> words{};

  void clear() { words.fill(0); }
  void set(int i) { words[size_t(i >> 6)] |= uint64_t(1) << (i & 63); }
  bool any() const {
    for (uint64_t w : words)
      if (w) return true;
    return false;
  }
  int count() const {
    int n = 0;
    for (uint64_t w : words) n += __builtin_popcountll(w);
    return n;
  }
  template <typename F>
  void for_each(F&& f) const {
    for (size_t w = 0; w < words.size(); ++w)
      for (uint64_t bits = words[w]; bits; bits &= bits - 1) f(int(w * 64) + __builtin_ctzll(bits));
  }
};

/// The float nearest t from below (above): packlet tests in float stay conservative.
inline float float_below(double t) {
  const float f = float(t);
  return double(f) > t ? std::nextafter(f, -std::numeric_limits<float>::infinity()) : f;
}
inline float float_above(double t) {
  const float f = float(t);
  return double(f) < t ? std::nextafter(f, std::numeric_limits<float>::infinity()) : f;
}

/// Rays of one packet, structure of arrays; lanes outside the volume start done.
struct Packet {
  int lanes = 0;
  std::array<int, kMaxLanes> px{}, py{};
  std::array<PrimaryRay, kMaxLanes> ray{};
  std::array<Hit, kMaxLanes> hit{};
  std::array<double, kMaxLanes> inv_dk{};
  std::array<Vec3d, kMaxLanes> inv{};
  std::array<uint8_t, kMaxLanes> live{};
  // Per lane, in float for the packlet tests (SIMD lanes of the build): 1/d (never infinite:
  // +-0 components give +-1e20), the ray's span entry, and its exit or hit so far.
  alignas(64) std::array<std::array<float, kMaxLanes>, 3> finv{};
  alignas(64) std::array<float, kMaxLanes> t_enter{}, t_exit{};
  Vec3d o{0.0};
  double su_lo = 0, su_hi = 0, sv_lo = 0, sv_hi = 0;  // slopes du/dK, dv/dK over the live lanes
  bool forward = true;                                // the live lanes' d_K > 0

  /// Lane i's float exit after its hit changed.
  void update_exit(int i) { t_exit[size_t(i)] = float_above(std::min(ray[size_t(i)].span.t1, hit[size_t(i)].t)); }
};

template <typename T>
struct Tracer {
  const Shared& r;
  const FrameSetup& setup;
  const ImageRays rays;
  RayCounters& counters;
  PageMemo<T> pages;
  const double* lod_k;  // the transition slices of the rays being traced: primary or shadow

  Tracer(const Shared& shared, const FrameSetup& s, RayCounters& c)
      : r(shared), setup(s), rays(s.camera, s.width, s.height), counters(c),
        pages(r.ctx.pages(), r.layout, size_t(r.p.pinned_pages), c), lod_k(r.lod_k.data()) {}

  const OctreePage<T>* page(uint64_t id) { return pages.page(id); }

  /// Width in finest voxels of a node at depth d.
  int64_t width(int d) const { return int64_t(1) << (r.layout.depth - d); }

  bool holds_isovalue(double lo, double hi) const {
    for (double iso : r.iso)
      if (iso >= lo && iso <= hi) return true;
    return false;
  }
  /// Whether a node's (or page's) range holds an isovalue; always, without macrocell culling.
  bool crosses(float lo, float hi) const { return !r.p.mcell || holds_isovalue(lo, hi); }
  /// Whether a cell's corner range holds an isovalue; always, without cell culling.
  bool crosses_corners(double lo, double hi) const { return !r.p.cell || holds_isovalue(lo, hi); }

  /// A node's own 8 scalars (null for one inside a consolidated subtree: its value is n.constant).
  const T* own_scalars(const Node<T>& n) const {
    if (n.consolidated) return nullptr;
    return n.depth == r.layout.cap_depth() ? n.page->cap_scalars(n.index) : n.page->node_scalars(n.level, n.index);
  }

  // --- The octree's nodes on the way down (nodes.h) ---
  bool lod_stops(int depth, const Vec3s& c) const;
  bool lod_leaf(const Node<T>& n) const;
  double lod_reach(const Node<T>& n) const;
  Interval<double> node_span(const Node<T>& n, const Vec3d& o, const Vec3d& inv, Interval<double> span) const;
  Box3d node_box(const Node<T>& n) const;
  Node<T> root();
  Node<T> child(const Node<T>& n, int oct);

  // --- A leaf's cells (cells.h) ---
  /// Caps near the ray, found by descent once each: a cell's corners lie in up to 8 caps,
  /// and the next cells along the ray share most of them.
  struct CapEntry {
    int depth = -1;
    Vec3s c{-1};
    uint64_t generation = ~uint64_t(0);
    OctreeScalars<T> scalars;
  };
  std::array<CapEntry, 32> caps{};  // direct-mapped by cap_slot()
  static size_t cap_slot(int d, const Vec3s& c) {
    return size_t((uint64_t(c.x) * 73856093u) ^ (uint64_t(c.y) * 19349663u) ^ (uint64_t(c.z) * 83492791u) ^ uint64_t(d)) & 31;
  }
  /// The descent's path: per depth, the last node visited there (with a record), from which a
  /// neighbour's scalars are found by going down from the nearest common ancestor rather than
  /// from the root (the paper's neighbour finding).
  struct PathEntry {
    uint64_t generation = ~uint64_t(0);
    Vec3s c{-1};
    const OctreePage<T>* page = nullptr;
    int level = 0;
    uint32_t index = 0;
  };
  std::array<PathEntry, kOctreeMaxDepth + 1> path{};
  void on_path(const Node<T>& n) {
    if (n.consolidated || n.unread_page || n.depth >= r.layout.cap_depth()) return;
    path[size_t(n.depth)] = {pages.generation(), n.c, n.page, n.level, n.index};
  }
  const OctreeScalars<T>& scalars_at(int d, const Vec3s& c);
  void cap_block(const Node<T>& n, const Vec3s& lo, double block[27], unsigned parts);
  void packet_cells(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V);
  void single_cells(const Node<T>& n, const Vec3d& o, const Vec3d& d, Interval<double> span, Hit& best);
  double corner(const Vec3s& v, const Node<T>& n, const T* own);
  void cell_corners(const Vec3s& cell, const Node<T>& n, const T* cap, double c[8], double& lo, double& hi);
  bool intersect(const Vec3s& cell, const double c[8], double lo, double hi, const Vec3d& o, const Vec3d& d,
                 const Vec3d& inv, Interval<double> s, Hit& best);

  // --- Smooth transitions between levels of detail (transition.h) ---
  /// A cell of the slab between a leaf and its coarser +K neighbour: a box (finest voxel
  /// coordinates) and its corners, index dx + 2 dy + 4 dz.
  struct TransitionBox {
    Vec3d lo{0.0}, hi{0.0};
    double corners[8] = {};
    double vlo = 0, vhi = 0;
  };
  struct Transition {
    int boxes = 0;
    std::array<TransitionBox, 16> box{};  // 2 x 2 columns, each cut at most once per side
  };
  Transition transition;
  /// The level n's +K neighbour is drawn at where it is coarser than n's own; -1 otherwise.
  int coarser_neighbour_level(const Node<T>& n) const;
  double voxel_at(int level, const Vec3s& v);
  void build_transition(const Node<T>& n, int coarse, Transition& out);
  bool intersect_box(const TransitionBox& box, const Vec3d& o, const Vec3d& d, const Vec3d& inv, Interval<double> s, Hit& best);

  // --- Single rays and shading (descent.cpp) ---
  void pixel(int x, int y, FrameBuffers& out);
  void shade(const PrimaryRay& ray, const Hit& h, PixelResult& px);
  Vec3d difference_gradient(const Vec3d& p, int level, bool central);
  Hit trace(const Vec3d& o, const Vec3d& d, Interval<double> span);
  bool in_shadow(const Vec3d& p_world, const Vec3d& l, double light_distance);
  bool descend(const Node<T>& n, const Vec3d& o, const Vec3d& d, const Vec3d& inv, Interval<double> span, Hit& best);

  // --- Packets (packets.cpp) ---
  /// A thread's packets, kept across tiles: they are large (every lane's ray and hit), and a
  /// tile's Tracer is made afresh. 0: render_packets()'s, 1: single_cells()'s one lane (a
  /// packet's shadow rays and incoherent lanes go down the single-ray descent meanwhile).
  static Packet& thread_packet(int which) {
    thread_local std::array<std::unique_ptr<Packet>, 2> packets;
    std::unique_ptr<Packet>& p = packets[size_t(which)];
    if (!p) p = std::make_unique<Packet>();
    return *p;
  }
  /// Per depth, the lanes whose rays still cross the node being visited there and can still
  /// find a nearer hit in it: a node tests only its parent's lanes.
  std::array<LaneSet, kOctreeMaxDepth + 2> lanes_at{};
  void render_packets(const Tile& tile, int size, FrameBuffers& out);
  // W: the lanes of a packlet, the frame's (Shared::packlet_lanes).
  template <int W>
  void trace_packet(Packet& p);
  template <int W>
  bool lanes_through(const Packet& p, const Box3d& b, const LaneSet& from, LaneSet& to) const;
  bool packet_meets(const Packet& p, const Vec3d& lo, const Vec3d& hi, int K, int U, int V) const;
  template <int W>
  void descend_packet(Packet& p, const Node<T>& n, const LaneSet& parent_lanes, int K, int U, int V);
  template <int W>
  void descend_children(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V);
  template <int W>
  void packlet_cells(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V);
  template <int W>
  void leaf_cells(Packet& p, const Node<T>& n, const LaneSet& lanes, int K, int U, int V);
};

}  // namespace brickyard::octree_cgt
