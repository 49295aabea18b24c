#pragma once
/// @file octree_walk.h
/// @brief Descent of an octree volume from its root to the node holding one voxel of one
/// level, across pages: the primitive of the single-ray mode, of verification and of tests.
///
/// `GetPage` is `const std::byte*(uint64_t page_id)`: a decoded page (the cache's, or a test's
/// map), or null when it is not resident; the walk then reports the depth it reached.

#include <cstdint>

#include "dataset/octree.h"

namespace brickyard {

/// @brief Where a descent ended.
template <typename T>
struct OctreeVoxel {
  T value{};
  int depth = 0;            ///< depth of the node whose scalar `value` is
  bool exact = false;       ///< the voxel itself, or a consolidated ancestor standing for it
  uint64_t missing_page = 0;///< when !exact: the page that was not resident (0 if none was)
};

/// @brief The voxel v of level s (0: finest), v inside layout.level_dims(s).
template <typename T, typename GetPage>
OctreeVoxel<T> octree_voxel(const OctreeLayout& layout, GetPage&& get_page, int s, const Vec3s& v) {
  const int target = layout.level_of_depth(s);  // the depth whose nodes hold level s
  uint64_t page_id = OctreeLayout::page_id(0, Vec3s(0));
  const std::byte* bytes = get_page(page_id);
  OctreeVoxel<T> out;
  if (!bytes) {
    out.missing_page = page_id;
    return out;
  }
  OctreePage<T> page = OctreePage<T>::view({bytes, layout.page_bytes()}, layout);
  int root = 0;        // depth of the page's root
  int level = 0;       // interior level within the page
  uint32_t index = 0;  // node index within that level
  for (int t = 0;; ++t) {
    // The octant of the voxel's ancestor at depth t + 1 within the node at depth t (for t ==
    // target: the voxel's slot among the node's 8).
    const int shift = target - t;
    const int octant = int((v.x >> shift) & 1) | int(((v.y >> shift) & 1) << 1) | int(((v.z >> shift) & 1) << 2);
    const bool cap = t == layout.cap_depth();
    const T* scalars = cap ? page.cap_scalars(index) : page.node_scalars(level, index);
    if (t == target) return {scalars[octant], t, true, 0};
    const OctreeNode& node = page.nodes[size_t(level)][index];
    if (!(node.child_mask & (1u << octant))) {
      // Consolidated (its region is this scalar at every level), or outside the volume.
      return {scalars[octant], t, ((node.const_mask >> octant) & 1u) != 0, 0};
    }
    if (t + 1 == layout.cap_depth() && page.header->has_caps) {
      index = node.child_index(octant);
      continue;
    }
    if (t + 1 - root < page.header->levels) {
      index = node.child_index(octant);
      ++level;
      continue;
    }
    const int shift_child = target - (t + 1) + 1;
    const Vec3s c{v.x >> shift_child, v.y >> shift_child, v.z >> shift_child};
    page_id = OctreeLayout::page_id(t + 1, c);
    bytes = get_page(page_id);
    if (!bytes) return {scalars[octant], t, false, page_id};
    page = OctreePage<T>::view({bytes, layout.page_bytes()}, layout);
    root = t + 1, level = 0, index = 0;
  }
}

}  // namespace brickyard
