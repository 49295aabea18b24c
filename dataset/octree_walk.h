#pragma once
/// @file octree_walk.h
/// @brief Descent of an octree volume from its root to the node holding one voxel of one
/// level, across pages: the primitive of the single-ray mode, of verification and of tests.
///
/// `GetPage(uint64_t page_id)` returns a decoded page's bytes (the cache's, or a test's map) or a
/// `const OctreePage<T>*` already parsed, or null when it is not resident; the walk then reports
/// the depth it reached.

#include <cstdint>
#include <type_traits>

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

/// @brief The 8 scalars of the node at depth d and coordinates c (the voxels 2c + {0,1}^3 of
/// its level), or, where a consolidated ancestor stands for it, the one value of its region.
template <typename T>
struct OctreeScalars {
  const T* scalars = nullptr;  ///< into a page: valid while that page is
  T constant{};                ///< when scalars is null and exact: every voxel of the node
  int depth = 0;               ///< where the descent ended
  bool exact = false;          ///< the node's own scalars, or a consolidated ancestor's value
  uint64_t missing_page = 0;   ///< when !exact: the page that was not resident (0 if none)

  T operator[](int octant) const { return scalars ? scalars[octant] : constant; }
};

namespace detail {
template <typename T, typename P>
OctreePage<T> as_octree_page(P p, const OctreeLayout& layout) {
  if constexpr (std::is_same_v<P, const OctreePage<T>*>) return *p;
  else return OctreePage<T>::view({p, layout.page_bytes()}, layout);
}
}  // namespace detail

/// @brief A node with a record, where a descent may start: an ancestor already found (a
/// renderer's path to its current node) makes a neighbour's descent short.
template <typename T>
struct OctreeWalkStart {
  OctreePage<T> page;   ///< the page holding the node
  int root = 0;         ///< depth of the page's root
  int level = 0;        ///< interior level of the node within the page
  uint32_t index = 0;   ///< node index within that level
  int depth = 0;        ///< the node's depth (interior: below the caps)
};

/// @brief octree_scalars() from `at`, an interior node that is an ancestor of (target, c) or
/// the node itself.
template <typename T, typename GetPage>
OctreeScalars<T> octree_scalars_below(const OctreeLayout& layout, GetPage&& get_page, const OctreeWalkStart<T>& at, int target,
                                      const Vec3s& c) {
  OctreePage<T> page = at.page;
  int root = at.root, level = at.level;
  uint32_t index = at.index;
  for (int t = at.depth;; ++t) {
    const bool cap = t == layout.cap_depth();
    const T* scalars = cap ? page.cap_scalars(index) : page.node_scalars(level, index);
    if (t == target) return {scalars, T{}, t, true, 0};
    // The octant of c's ancestor at depth t + 1 within the node at depth t.
    const int shift = target - t - 1;
    const int octant = int((c.x >> shift) & 1) | int(((c.y >> shift) & 1) << 1) | int(((c.z >> shift) & 1) << 2);
    const OctreeNode& node = page.nodes[size_t(level)][index];
    if (!(node.child_mask & (1u << octant))) {
      // Consolidated (its region is this scalar at every level), or outside the volume.
      return {nullptr, scalars[octant], t, ((node.const_mask >> octant) & 1u) != 0, 0};
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
    const uint64_t page_id = OctreeLayout::page_id(t + 1, {c.x >> shift, c.y >> shift, c.z >> shift});
    auto bytes = get_page(page_id);
    if (!bytes) return {nullptr, scalars[octant], t, false, page_id};
    page = detail::as_octree_page<T>(bytes, layout);
    root = t + 1, level = 0, index = 0;
  }
}

template <typename T, typename GetPage>
OctreeScalars<T> octree_scalars(const OctreeLayout& layout, GetPage&& get_page, int target, const Vec3s& c) {
  const uint64_t page_id = OctreeLayout::page_id(0, Vec3s(0));
  auto bytes = get_page(page_id);
  if (!bytes) {
    OctreeScalars<T> out;
    out.missing_page = page_id;
    return out;
  }
  return octree_scalars_below<T>(layout, get_page, {detail::as_octree_page<T>(bytes, layout), 0, 0, 0, 0}, target, c);
}

/// @brief The voxel v of level s (0: finest), v inside layout.level_dims(s).
template <typename T, typename GetPage>
OctreeVoxel<T> octree_voxel(const OctreeLayout& layout, GetPage&& get_page, int s, const Vec3s& v) {
  const OctreeScalars<T> n = octree_scalars<T>(layout, get_page, layout.level_of_depth(s), {v.x >> 1, v.y >> 1, v.z >> 1});
  const int octant = int(v.x & 1) | int((v.y & 1) << 1) | int((v.z & 1) << 2);
  return {n[octant], n.depth, n.exact, n.missing_page};
}

}  // namespace brickyard
