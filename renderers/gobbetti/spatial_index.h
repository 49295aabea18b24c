#pragma once
/// @file spatial_index.h
/// @brief The `gobbetti` back end's per-frame spatial index: the octree of a cut through the
/// brick octree, with six neighbour links on every node, and a stackless ray traversal over
/// it that computes every box on the fly (Gobbetti, Marton and Iglesias Guitian 2008, sec. 4).
///
/// Geometry. Everything is in finest-level voxel coordinates. The octree's domain is the
/// root brick's nominal cube [0, M 2^(levels-1)]^3, which may reach beyond the volume. Node
/// (level l, brick coordinates c) is the box [c S_l, (c + 1) S_l] per axis, with
/// S_l = M 2^(levels-1-l). Boxes are never stored: a traversal derives them from the level
/// and coordinates it tracks.
///
/// Input. The leaves of a cut, each with an opaque 32-bit payload (the renderer's pool slot or
/// "empty" marker). A cut is valid when every existing finest brick lies in exactly one leaf;
/// its inner nodes are then exactly the proper ancestors of its leaves. build() checks this
/// (O(1) per leaf, so always on) and throws Error(Errc::invalid_argument) naming the first
/// offending key: a key that is not a brick of the layout, a leaf given twice, a leaf inside
/// another leaf, or an existing brick that no leaf covers. The children of an inner node
/// that are not bricks of the layout (`!layout.contains(child)`) become leaves flagged
/// "outside" (payload kOutsidePayload): they are empty space, but rays cross them, because a
/// coarser leaf beside them can reach further out than the finest bricks do.
///
/// Node array. One contiguous array of 32-byte nodes (two per cache line), breadth-first: the
/// root is node 0, the 8 children of an inner node are contiguous, in BrickKey::child order
/// (bit 0 = +x, bit 1 = +y, bit 2 = +z). Every node, inner or leaf, has six links
/// (-x, +x, -y, +y, -z, +z; face = 2 axis + (positive side)), each packed as
/// [level: 5 bits][node index: 27 bits]. A link names the node across that face at the same
/// level when the tree has one (leaf, outside leaf or inner node), otherwise the coarser leaf
/// that covers that place; kNullLink beyond the domain. Six 4-byte links do not fit a 16-byte
/// node, and splitting them into a second array would cost every leaf step a second cache
/// line. Beside the nodes, the build keeps each node's BrickKey (16 bytes, for key()) and its
/// hash table (a 48-byte record per inner node, the table at most half full).
///
/// Traversal. Per ray, one descent from the root to the leaf that holds the start, then leaf
/// to leaf through the exit face's link, descending again when the link names an inner node.
/// No stack, no recursion, no stored boxes. Every decision "which side of plane P is the ray
/// at parameter t" is made by comparing t with the crossing parameter (P - o) / d, computed by
/// that one formula everywhere (planes are exact multiples of S_l), never by rounding a point:
///   - a visited leaf's [ta, tb] starts where the previous one ended, bit for bit;
///   - rays through edges and corners neither loop nor skip: at a tie between exit faces the
///     lowest axis goes first, and the leaves passed at zero length are not reported;
///   - a ray lying in a face plane (zero direction component, origin exactly on the plane)
///     belongs to the node on the plane's upper side, except on the domain's upper face;
///   - the result equals a 3D DDA over the finest bricks with the same formula, merged per leaf.
/// Only pieces of positive length are visited; a segment that is a single point (t0 == t1
/// after clipping to the domain) visits one leaf, with ta == tb: on a boundary, the leaf on
/// the side the direction moves to (the upper side for a zero component). Rays with a
/// non-finite origin or direction visit nothing. The domain cube reaches beyond the volume:
/// a renderer clips [t0, t1] to the volume's box first to skip leaves that hold no data. A walk leaves through each plane of the
/// finest brick grid at most once (the crossing parameters are monotone in the plane, and
/// later leaves lie on the far side of every plane already left), so it takes at most
/// 3 * 2^(levels-1) steps; a guard counter enforces that bound whatever the arithmetic does.
///
/// Concurrency and lifetime. build() reuses the allocations of the previous build and
/// invalidates everything read before it; it is not thread-safe. Between builds the index is
/// immutable: any number of threads may call traverse() and the accessors.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "core/brick_key.h"
#include "core/math.h"
#include "dataset/grid.h"

namespace brickyard::gobbetti {

/// @brief One leaf of a cut: a brick and the renderer's opaque value for it.
struct CutLeaf {
  BrickKey key;
  uint32_t payload = 0;
};

/// @brief What traverse() tells its visitor about each leaf a ray crosses: the node, its brick
/// (a key outside the layout for an "outside" leaf), its payload, and the ray's parameter
/// interval inside it, clipped to [t0, t1].
struct LeafVisit {
  uint32_t node = 0;
  BrickKey key;
  uint32_t payload = 0;
  bool outside = false;
  double ta = 0, tb = 0;
};

/// @brief Faces, in link order: face = 2 * axis + (1 on the positive side).
enum Face : int { kFaceNegX = 0, kFacePosX, kFaceNegY, kFacePosY, kFaceNegZ, kFacePosZ };

class SpatialIndex {
 public:
  /// @brief A link that leads nowhere: across the face is outside the octree's domain.
  static constexpr uint32_t kNullLink = 0xffffffffu;
  static constexpr int kLinkIndexBits = 27;
  static constexpr uint32_t kLinkIndexMask = (1u << kLinkIndexBits) - 1;
  /// @brief Node indices are < kMaxNodes, so that no link equals kNullLink.
  static constexpr uint32_t kMaxNodes = kLinkIndexMask;
  /// @brief Levels 0..kMaxLevels-1 fit the 5-bit level of a link.
  static constexpr int kMaxLevels = 32;
  /// @brief Payload of the leaves flagged "outside".
  static constexpr uint32_t kOutsidePayload = 0xffffffffu;

  /// @brief 32 bytes. `child` is the first child's index for an inner node (always >= 1),
  /// kLeafTag for a leaf of the cut, kOutsideTag for a leaf outside the layout.
  struct Node {
    uint32_t child = 0;
    uint32_t payload = 0;
    uint32_t links[6] = {};
  };
  static constexpr uint32_t kOutsideTag = 0xfffffffeu;
  static constexpr uint32_t kLeafTag = 0xffffffffu;

  /// @brief Rebuilds the index from the leaves of a cut (any order), reusing the previous
  /// build's storage. Throws Error(Errc::invalid_argument) on an invalid cut (see the file
  /// comment), Error(Errc::resource) beyond kMaxNodes nodes. O(number of nodes).
  void build(const GridLayout& layout, std::span<const CutLeaf> leaves);

  /// @brief Calls visit(const LeafVisit&) -> bool for the leaves that the ray org + t dir
  /// crosses for t in [t0, t1], front to back; returning false stops the walk. See the file
  /// comment for the exact semantics of boundaries, ties and degenerate rays.
  template <class F>
  void traverse(const Vec3d& org, const Vec3d& dir, double t0, double t1, F&& visit) const;

  /// @brief Whether build() has run.
  bool empty() const { return nodes_.empty(); }
  uint32_t node_count() const { return uint32_t(nodes_.size()); }
  /// @brief Leaves of the cut (not counting the "outside" leaves).
  uint32_t cut_leaf_count() const { return cut_leaves_; }
  uint32_t outside_leaf_count() const { return outside_leaves_; }
  int levels() const { return levels_; }
  /// @brief Edge of the domain cube, M 2^(levels-1), in finest voxels.
  double domain_size() const { return scale_[0]; }
  /// @brief Edge S_l of a node at a level, in finest voxels.
  double node_size(int level) const { return scale_[level]; }

  const Node& node(uint32_t i) const { return nodes_[i]; }
  bool is_inner(uint32_t i) const { return nodes_[i].child < kOutsideTag; }
  bool is_leaf(uint32_t i) const { return !is_inner(i); }
  bool is_outside(uint32_t i) const { return nodes_[i].child == kOutsideTag; }
  /// @brief First of the 8 children of an inner node.
  uint32_t first_child(uint32_t i) const { return nodes_[i].child; }
  uint32_t payload(uint32_t i) const { return nodes_[i].payload; }
  /// @brief The brick of a node, kept from the build (traverse() tracks it instead).
  const BrickKey& key(uint32_t i) const { return keys_[i]; }
  /// @brief The node's box in finest voxels, computed from its key.
  Box3d box(uint32_t i) const;
  uint32_t link(uint32_t i, int face) const { return nodes_[i].links[face]; }
  static constexpr uint32_t link_index(uint32_t link) { return link & kLinkIndexMask; }
  static constexpr int link_level(uint32_t link) { return int(link >> kLinkIndexBits); }
  static constexpr uint32_t make_link(uint32_t index, int level) {
    return (uint32_t(level) << kLinkIndexBits) | index;
  }

  /// @brief Bytes held (capacity, so what a frame's build reuses), scratch included.
  size_t bytes() const;

 private:
  /// Build scratch: an open-addressing hash table from an inner node's key code to what the
  /// cut says of its 8 children (2 bits each: nothing, leaf, inner) and their payloads, so
  /// that laying out an inner node's children costs one probe.
  struct Family {
    uint64_t code;
    uint32_t kinds;
    uint32_t payload[8];
  };
  void table_reset(size_t expected);
  Family* table_find(uint64_t code);
  Family* table_insert(uint64_t code, bool& inserted);
  void table_grow();
  void compute_links();

  /// Crossing parameter of the plane x_axis = plane: the one formula every decision uses.
  static double plane_t(double plane, double o, double d) { return (plane - o) / d; }

  std::vector<Node> nodes_;
  std::vector<BrickKey> keys_;
  std::vector<Family> table_;
  std::vector<Family> table_spare_;
  int table_shift_ = 64;
  size_t table_used_ = 0;
  uint32_t cut_leaves_ = 0, outside_leaves_ = 0;
  int levels_ = 0;
  uint64_t max_steps_ = 0;
  double scale_[kMaxLevels + 1] = {};
};

static_assert(sizeof(SpatialIndex::Node) == 32, "two nodes per cache line");

template <class F>
void SpatialIndex::traverse(const Vec3d& org, const Vec3d& dir, double t0, double t1, F&& visit) const {
  if (nodes_.empty()) return;
  // Step 1: clip [t0, t1] to the domain cube, with the plane formula of every later step.
  const double domain = scale_[0];
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(org[a]) || !std::isfinite(dir[a])) return;
    if (dir[a] == 0.0) {
      if (org[a] < 0.0 || org[a] > domain) return;
      continue;
    }
    double tn = plane_t(0.0, org[a], dir[a]), tf = plane_t(domain, org[a], dir[a]);
    if (dir[a] < 0.0) std::swap(tn, tf);
    t0 = std::max(t0, tn);
    t1 = std::min(t1, tf);
  }
  if (!(t0 <= t1)) return;  // a miss, an empty or NaN interval
  const bool single_point = t0 == t1;

  // Step 2: walk. (n, level, c) is the current node; entry_axis is the axis of the face the
  // walk entered through (-1 at the start), whose side the descent takes without arithmetic.
  uint32_t n = 0;
  int level = 0;
  uint32_t c[3] = {0, 0, 0};
  int entry_axis = -1;
  double ta = t0;
  for (uint64_t steps = 0; steps < max_steps_; ++steps) {
    // Step 2a: descend to the leaf holding the ray just after ta, comparing with the
    // children's common corner (the box centre) by crossing parameters.
    while (nodes_[n].child < kOutsideTag) {
      const double half = scale_[level + 1];
      uint32_t bits = 0;
      for (int a = 0; a < 3; ++a) {
        bool upper;
        if (a == entry_axis) {
          upper = dir[a] < 0.0;  // entered through the upper face when moving down
        } else {
          const double centre = double(2 * c[a] + 1) * half;
          if (dir[a] > 0.0) upper = plane_t(centre, org[a], dir[a]) <= ta;
          else if (dir[a] < 0.0) upper = plane_t(centre, org[a], dir[a]) > ta;
          else upper = org[a] >= centre;
        }
        c[a] = 2 * c[a] + uint32_t(upper);
        bits |= uint32_t(upper) << a;
      }
      n = nodes_[n].child + bits;
      ++level;
    }

    // Step 2b: the exit face: smallest crossing of the far planes; ties go to the lowest axis.
    const Node& leaf = nodes_[n];
    const double size = scale_[level];
    int exit_axis = -1;
    double te = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
      if (dir[a] == 0.0) continue;
      const double far_plane = double(dir[a] > 0.0 ? c[a] + 1 : c[a]) * size;
      const double t = plane_t(far_plane, org[a], dir[a]);
      if (t < te) {
        te = t;
        exit_axis = a;
      }
    }
    const double tb = std::max(ta, std::min(te, t1));

    // Step 2c: report pieces of positive length (or the single point).
    if (tb > ta || single_point) {
      const LeafVisit v{n, BrickKey{uint32_t(level), c[0], c[1], c[2]}, leaf.payload, leaf.child == kOutsideTag, ta, tb};
      if (!visit(v)) return;
    }
    if (single_point || !(te < t1)) return;

    // Step 2d: follow the link; the neighbour's coordinates follow from ours in closed form
    // (it is at our level or a coarser leaf that contains our neighbour at our level).
    const uint32_t link = leaf.links[2 * exit_axis + (dir[exit_axis] > 0.0 ? 1 : 0)];
    if (link == kNullLink) return;
    const int next_level = link_level(link);
    const int shift = level - next_level;
    c[exit_axis] = dir[exit_axis] > 0.0 ? c[exit_axis] + 1 : c[exit_axis] - 1;
    c[0] >>= shift;
    c[1] >>= shift;
    c[2] >>= shift;
    n = link_index(link);
    level = next_level;
    entry_axis = exit_axis;
    ta = tb;
  }
}

}  // namespace brickyard::gobbetti
