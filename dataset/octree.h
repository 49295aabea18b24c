#pragma once
/// @file octree.h
/// @brief The typed view of an octree volume (Knoll et al., "Interactive isosurface ray tracing
/// of large octree volumes"), stored beside a grid's bricks: its geometry and the layout of its
/// pages (RecordKind::octree_page), which back ends read through the cache.
///
/// Geometry. The finest grid of dims N is covered by an octree of depth D, 2^D >= max(N). A
/// node at depth d covers 2^(D - d) finest voxels per axis and holds the 8 voxels of level
/// s = D - 1 - d (s halvings from the finest, the grid's mip levels: dims ceil(N / 2^s), each
/// voxel the 2x filter of 8 of level s - 1), indices 2c + {0, 1}^3 for node coordinates c.
/// Interior nodes (depths 0 .. D - 2) hold these coarser scalars always, so any depth is a
/// level of detail; cap nodes (depth D - 1) hold the 8 finest scalars and nothing else.
///
/// Scalar o of a node is the average over child o's whole region, so a child whose region is
/// one value (within the build's tolerance) is not stored: the parent marks it consolidated and
/// its scalar is that value at every finer level. Children outside the volume are neither
/// stored nor consolidated.
///
/// Min/max. A node's range covers every trilinear cell of its region at its own level and at
/// every finer level, forward neighbours included (voxels 2c .. 2c + 2 of each level's block),
/// so culling by it is conservative at any depth a traversal stops at.
///
/// Pages. Nodes are paged in subtrees: a cap page is rooted at depth rc = max(0, D - 4) and
/// holds the interior levels rc .. D - 2 and the caps (16^3 finest voxels); upper pages are
/// rooted at rc - 3, rc - 6, ... and 0, three interior levels each (fewer for the top page).
/// A page's id is BrickKey{root depth, root coordinates}.code(): big-endian in LMDB, so keys
/// run depth-major, then in Morton order. A decoded page (native byte order, little-endian in
/// the record) is: an OctreePageHeader; per interior level, its OctreeNode array, then their
/// scalars (8 per node, the dataset's value type); then the caps' scalars (8 per cap). Nodes of
/// a level are stored in Morton order of their coordinates, the children of one node together.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "core/brick_key.h"
#include "core/math.h"
#include "core/value_type.h"

namespace brickyard {

/// @brief One interior node: 16 bytes, stored as is.
struct OctreeNode {
  float min = 0, max = 0;     ///< range of the node's cells at its level and every finer one
  uint32_t first_child = 0;   ///< index of its first stored child in the next level (or the caps)
  uint8_t child_mask = 0;     ///< children stored, bit x + 2y + 4z
  uint8_t const_mask = 0;     ///< children consolidated: their region is the parent's scalar
  uint16_t reserved = 0;

  /// @brief Index of stored child `octant` in the next level's array (child_mask has its bit).
  uint32_t child_index(int octant) const {
    return first_child + uint32_t(__builtin_popcount(unsigned(child_mask) & ((1u << octant) - 1u)));
  }
  friend bool operator==(const OctreeNode&, const OctreeNode&) = default;
};
static_assert(sizeof(OctreeNode) == 16, "octree nodes are part of the on-disk format");

inline constexpr uint32_t kOctreePageMagic = 0x504f5942;  // "BYOP" in file order
inline constexpr int kOctreeCapPageDepths = 4;   ///< levels of a cap page, caps included
inline constexpr int kOctreeUpperPageDepths = 3; ///< interior levels of an upper page
inline constexpr int kOctreeMaxDepth = 19;       ///< root coordinates fit BrickKey's 19 bits

/// @brief The start of every decoded page: 32 bytes.
struct OctreePageHeader {
  uint32_t magic = kOctreePageMagic;
  uint8_t root_depth = 0;
  uint8_t levels = 0;   ///< interior levels in the page
  uint8_t has_caps = 0; ///< the page ends with the caps (depth D - 1)
  uint8_t value_type = 0;
  uint32_t nodes[4] = {0, 0, 0, 0};  ///< per interior level
  uint32_t caps = 0;
  uint32_t reserved = 0;
};
static_assert(sizeof(OctreePageHeader) == 32, "the octree page header is part of the on-disk format");

/// @brief The octree's geometry: depths, levels and pages, derived from the grid's dims.
struct OctreeLayout {
  Vec3s dims{0};  ///< the finest grid
  int depth = 0;  ///< D
  ValueType type = ValueType::u8;
  size_t max_page_bytes = 0;  ///< page_bytes(), computed once by make()

  /// @brief The layout over a grid; Error(invalid_argument) for an empty grid or one deeper
  /// than kOctreeMaxDepth.
  static OctreeLayout make(const Vec3s& dims, ValueType type);

  int cap_depth() const { return depth - 1; }
  /// @brief The voxel level held by nodes of a depth: halvings from the finest.
  int level_of_depth(int d) const { return depth - 1 - d; }
  /// @brief Voxels of a level (s halvings from the finest), ceil(dims / 2^s).
  Vec3s level_dims(int s) const;
  /// @brief Nodes at a depth, per axis: ceil(level_dims(level_of_depth(d)) / 2).
  Vec3s nodes_at(int d) const;
  /// @brief The depth of cap pages' roots, max(0, D - 4).
  int cap_page_root() const { return std::max(0, depth - kOctreeCapPageDepths); }
  /// @brief The root depth of the page holding nodes of depth d (caps included).
  int page_root(int d) const;
  /// @brief Whether depth d is a page root.
  bool is_page_root(int d) const { return page_root(d) == d; }
  /// @brief The interior levels of a page rooted at depth r.
  int page_levels(int r) const;
  /// @brief The id of the page rooted at depth r with root coordinates c.
  static uint64_t page_id(int r, const Vec3s& c) { return BrickKey{uint32_t(r), uint32_t(c.x), uint32_t(c.y), uint32_t(c.z)}.code(); }
  /// @brief The decoded size of every page (the largest a page can be).
  size_t page_bytes() const { return max_page_bytes; }
  /// @brief The largest page, computed.
  size_t largest_page_bytes() const;
  /// @brief The decoded bytes of a page with these counts.
  size_t page_bytes(std::span<const uint32_t> nodes_per_level, uint32_t caps) const;
  size_t scalar_bytes() const { return 8 * size_of(type); }
};

/// @brief A decoded page, read in place. Pointers point into the page's bytes.
template <typename T>
struct OctreePage {
  const OctreePageHeader* header = nullptr;
  std::array<const OctreeNode*, 4> nodes{};  ///< per interior level
  std::array<const T*, 4> scalars{};        ///< per interior level, 8 per node
  const T* caps = nullptr;                  ///< 8 per cap

  /// @brief The page in `bytes`; Error(corrupt) when its header does not fit them or the layout.
  static OctreePage view(std::span<const std::byte> bytes, const OctreeLayout& layout);
  const T* node_scalars(int level, uint32_t i) const { return scalars[size_t(level)] + 8 * size_t(i); }
  const T* cap_scalars(uint32_t i) const { return caps + 8 * size_t(i); }
};

/// @brief What `brickyard info` and the note report: sizes against the raw grid.
struct OctreeSummary {
  int depth = 0;
  uint64_t pages = 0;
  uint64_t interior_nodes = 0, caps = 0;
  uint64_t consolidated = 0;   ///< children consolidated (subtrees not stored)
  uint64_t bytes = 0;          ///< nodes and scalars as laid out (the octree's size)
  uint64_t stored_bytes = 0;   ///< page records on disk (LZ4)
  uint64_t raw_bytes = 0;      ///< the finest grid, dims x value size
  double tolerance = 0;        ///< consolidation tolerance (0: lossless)
  double max_error = 0;        ///< the largest |stored - source| over the finest voxels
  bool clamped = false;        ///< values were clamped into [clamp_lo, clamp_hi]
  double clamp_lo = 0, clamp_hi = 0;
  uint64_t page_bytes = 0;     ///< decoded size of every page
};

/// @brief A stored page and its root node's range: the top of the min/max tree, which every
/// back end holds whole (16 bytes a page), so a page whose range misses the isovalues is never
/// fetched. Stored in the `octree` database beside the pages, sorted by id.
struct OctreePageRange {
  uint64_t id = 0;
  float min = 0, max = 0;
  friend bool operator==(const OctreePageRange&, const OctreePageRange&) = default;
};
static_assert(sizeof(OctreePageRange) == 16, "page ranges are part of the on-disk format");

/// @brief An octree volume as back ends see it. The page table is the opener's (the store's).
class OctreeView {
 public:
  OctreeView(const OctreeLayout& layout, const OctreeSummary& summary, std::span<const OctreePageRange> pages)
      : layout_(layout), summary_(summary), pages_(pages) {}
  const OctreeLayout& layout() const { return layout_; }
  const OctreeSummary& summary() const { return summary_; }
  size_t page_bytes() const { return size_t(summary_.page_bytes); }
  uint64_t root_page() const { return OctreeLayout::page_id(0, Vec3s(0)); }
  /// @brief Every stored page with its root's range, by id.
  std::span<const OctreePageRange> pages() const { return pages_; }
  /// @brief A page's entry; null when the octree stores no such page.
  const OctreePageRange* page(uint64_t id) const;

 private:
  OctreeLayout layout_;
  OctreeSummary summary_;
  std::span<const OctreePageRange> pages_;
};

/// @brief "octree page depth 4 (1, 0, 3)", for messages.
std::string describe_octree_page(uint64_t id);

}  // namespace brickyard
