#pragma once
/// @file nodes.h
/// @brief octree_cgt: the octree's nodes on the way down, for single rays and packets alike:
/// a node's children (through consolidated subtrees and into the pages below), its box and
/// where the level of detail stops. Part of Tracer (tracer.h).

#include <algorithm>
#include <cmath>
#include <limits>

#include "renderers/octree_cgt/tracer.h"

namespace brickyard::octree_cgt {

/// Whether the level of detail stops at the node at depth d and coordinates c (above the
/// caps): one of its voxels covers at most dpdv pixels at its nearest slice along K (the
/// frame's transition slices).
template <typename T>
bool Tracer<T>::lod_stops(int d, const Vec3s& c) const {
  if (!r.lod) return false;
  const int K = r.major_axis;
  const int64_t w = width(d);
  const double lo = double(c[K] * w), hi = double((c[K] + 1) * w);
  const double e = r.eye_k;
  const double distance = e < lo ? lo - e : e > hi ? e - hi : 0.0;
  return distance >= lod_k[size_t(d)];
}

/// Whether node n is drawn with its own voxels: a cap, or where the level of detail stops.
template <typename T>
bool Tracer<T>::lod_leaf(const Node<T>& n) const {
  return n.depth == r.layout.cap_depth() || lod_stops(n.depth, n.c);
}

/// How far a node's cells reach past its region at the levels of detail it or a node below it
/// may be drawn at: a level-L voxel i sits at finest coordinate (i + 1/2) 2^L - 1/2, so
/// level-L cells reach (2^L - 1) / 2 past, and a smooth transition's slab reaches as far as its
/// coarser neighbour's cells begin. The coarsest level possible is that of the shallowest
/// depth whose transition slice lies within the node's K extent.
template <typename T>
double Tracer<T>::lod_reach(const Node<T>& n) const {
  if (!r.lod) return 0;
  const int K = r.major_axis;
  const int64_t w = width(n.depth);
  const double far = std::max(std::abs(double(n.c[K] * w) - r.eye_k), std::abs(double((n.c[K] + 1) * w) - r.eye_k));
  for (int d = r.p.smooth ? 0 : n.depth; d < r.layout.cap_depth(); ++d)
    if (lod_k[size_t(d)] <= far) return 0.5 * double((int64_t(1) << r.layout.level_of_depth(d)) - 1);
  return 0;
}

/// The ray's interval over a node's cells: voxels [c W, (c + 1) W] clipped to the volume's
/// last voxel (a cell's upper corner lies in the next node).
template <typename T>
Interval<double> Tracer<T>::node_span(const Node<T>& n, const Vec3d& o, const Vec3d& inv, Interval<double> span) const {
  const Box3d box = node_box(n);
  return clip_to_box(span, box.lo, box.hi, o, inv);
}

/// The box of a node's cells, as node_span() clips rays to it.
template <typename T>
Box3d Tracer<T>::node_box(const Node<T>& n) const {
  const int64_t w = width(n.depth);
  const double reach = lod_reach(n);
  Vec3d lo, hi;
  for (int a = 0; a < 3; ++a)
    lo[a] = double(n.c[a] * w), hi[a] = std::min(double((n.c[a] + 1) * w) + reach, double(r.layout.dims[a] - 1));
  return {lo, hi};
}

/// Child `oct` of n (depth -1 when it is outside the volume or needs no visit).
template <typename T>
Node<T> Tracer<T>::child(const Node<T>& n, int oct) {
  Node<T> c;
  c.depth = n.depth + 1;
  c.c = {2 * n.c.x + (oct & 1), 2 * n.c.y + ((oct >> 1) & 1), 2 * n.c.z + ((oct >> 2) & 1)};
  const Vec3s all = r.nodes_at[size_t(c.depth)];
  if (c.c.x >= all.x || c.c.y >= all.y || c.c.z >= all.z) return Node<T>::none();
  if (n.consolidated) {
    // Inside a region of one value, only cells on its forward faces meet other values,
    // unless an isovalue equals it.
    const int64_t w = width(c.depth);
    bool face = false;
    for (int a = 0; a < 3; ++a) face |= (c.c[a] + 1) * w >= n.forward_end[a];
    if (r.p.mcell && !face && !std::any_of(r.iso.begin(), r.iso.end(), [&](double v) { return v == n.constant; }))
      return Node<T>::none();
    c.consolidated = true, c.constant = n.constant, c.min = n.min, c.max = n.max, c.forward_end = n.forward_end;
    return c;
  }
  const OctreeNode& rec = n.page->nodes[size_t(n.level)][n.index];
  const T* scalars = n.page->node_scalars(n.level, n.index);
  if (rec.const_mask & (1u << oct)) {
    c.consolidated = true;
    c.constant = double(scalars[oct]);
    c.min = rec.min, c.max = rec.max;  // the parent's: cells on the forward faces reach its neighbours
    const int64_t w = width(c.depth);
    c.forward_end = (c.c + Vec3s(1)) * w;
    return c;
  }
  if (!(rec.child_mask & (1u << oct))) return Node<T>::none();
  if (c.depth == r.layout.cap_depth()) {
    c.page = n.page, c.level = n.level, c.index = rec.child_index(oct);
    c.min = rec.min, c.max = rec.max;  // caps hold no range: their parent's covers them
    return c;
  }
  if (n.level + 1 < n.page->header->levels) {
    c.page = n.page, c.level = n.level + 1, c.index = rec.child_index(oct);
  } else {
    // The child's page: its range from the page table, the page itself when a ray enters it.
    const OctreePageRange* p = r.view.page(OctreeLayout::page_id(c.depth, c.c));
    if (!p) return Node<T>::none();
    c.unread_page = p->id, c.level = 0, c.index = 0;
    c.min = p->min, c.max = p->max;
    return c;
  }
  const OctreeNode& crec = c.page->nodes[size_t(c.level)][c.index];
  c.min = crec.min, c.max = crec.max;
  return c;
}

/// The root node, its page read.
template <typename T>
Node<T> Tracer<T>::root() {
  Node<T> n;
  n.page = page(OctreeLayout::page_id(0, Vec3s(0)));
  if (!n.page) return Node<T>::none();  // the root page cannot be read: nothing to draw
  n.min = n.page->nodes[0][0].min, n.max = n.page->nodes[0][0].max;
  return n;
}

}  // namespace brickyard::octree_cgt
