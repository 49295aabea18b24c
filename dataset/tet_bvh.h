#pragma once
/// @file tet_bvh.h
/// @brief tet_bvh's implicit 4D min/max BVH (Wald, Friedrich, Knoll and Hansen): every node
/// bounds its tets in {x, y, z, value}, so that one test culls a subtree in space (the ray's
/// box test) or in value (the implicit test: no isovalue between its min and max). Built per
/// cluster when the cluster first arrives, or stored after its page's tetrahedra by the
/// importer (`import --bvh`), and once over the cluster table. Here, beside the page layout,
/// because both the importer and the back end need it.
///
/// A stored BVH (step 0's), from the first 8-byte boundary after the tetrahedra: u32 magic
/// "TBV1", u32 build method (0 BIH, 1 SAH), u32 leaf size, u32 node count N, u32 slot count
/// L, u32 tets left out; N nodes; L u32 tet indices (leaf slots); L pairs of floats (each
/// slot's value range).
///
/// Node layout: lo and hi as 4-float vectors (x, y, z, value), then the right child (inner)
/// or the first item (leaf), the item count (0 for inner nodes) and the split axis, 40 bytes.
/// The left child of an inner node is the next node.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "dataset/tet.h"

namespace brickyard::tet_bvh {

struct alignas(8) BvhNode {
  float lo[4], hi[4];  ///< x, y, z, value
  uint32_t index = 0;  ///< inner: right child; leaf: first item in BoxBvh::order
  uint16_t count = 0;  ///< items of a leaf; 0 for an inner node
  uint16_t axis = 0;   ///< inner: the split axis (the near child first along it)
  bool leaf() const { return count != 0; }
};
static_assert(sizeof(BvhNode) == 40);

enum class BuildMethod : uint8_t {
  bih,  ///< spatial median of the node's box along its longest axis (BIH-style, fast)
  sah,  ///< binned surface-area heuristic (slower to build, fewer tests)
};

/// @brief An item's {x, y, z, value} bounds.
struct Bounds4 {
  float lo[4], hi[4];
};

/// @brief A BVH over boxes: nodes and the items in leaf order.
struct BoxBvh {
  std::vector<BvhNode> nodes;
  std::vector<uint32_t> order;
  size_t bytes() const { return nodes.size() * sizeof(BvhNode) + order.size() * sizeof(uint32_t); }
};
/// @brief Builds over `items`; leaves hold at most `leaf_size` items.
BoxBvh build_bvh(const std::vector<Bounds4>& items, BuildMethod method, uint32_t leaf_size);
/// @brief Recomputes every node's bounds, children before parents, from `slot_bounds`: the
/// bounds of the item in each leaf slot (slot s holds item bvh.order[s]). The topology stays;
/// for bounds that only grew or moved a little, traversal stays about as fast as a rebuild's.
void refit_bvh(BoxBvh& bvh, const Bounds4* slot_bounds);

/// @brief A cluster's BVH for one time step, with each leaf slot's tet and its value range
/// (the leaf tests a tet's own range before it extracts the tet's isopolygon).
struct ClusterBvh {
  BoxBvh bvh;
  std::vector<float> tet_range;  ///< min, max per leaf slot
  uint32_t skipped = 0;          ///< tets left out: not positively oriented, or not finite
  size_t bytes() const { return bvh.bytes() + tet_range.size() * sizeof(float); }

  uint32_t step = 0;             ///< the time step the bounds are for

  static ClusterBvh build(const TetClusterPage& page, uint32_t step, BuildMethod method, uint32_t leaf_size);
  /// @brief The BVH stored in the page, when it holds one built by `method` with leaves of
  /// `leaf_size` (else nothing). @throws Error(corrupt) when the stored one does not fit the
  /// page (its counts, children or tet indices).
  static std::optional<ClusterBvh> stored(const TetClusterPage& page, BuildMethod method, uint32_t leaf_size);
  /// @brief This BVH as the bytes to append to its page (padding to 8 bytes first, given the
  /// page's current size).
  std::vector<std::byte> encode(size_t page_size, BuildMethod method, uint32_t leaf_size) const;
  /// @brief This BVH's topology with its bounds refitted to `step` (moved vertices, new
  /// values); nothing when the set of valid tets differs at that step (a rebuild is needed).
  std::optional<ClusterBvh> refit(const TetClusterPage& page, uint32_t step) const;
};

}  // namespace brickyard::tet_bvh
