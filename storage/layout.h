#pragma once
/// @file layout.h
/// @brief Geometry of a multiresolution brick store: levels, their voxel and brick grids, and
/// the node table that summarises every brick.
///
/// Level `levels - 1` is the finest (the source grid); each coarser level halves every
/// dimension (rounding up) until one brick covers the whole volume at level 0. Coarse voxel i
/// of a level k steps above the finest is the box-filtered average of the 2^k finest voxels
/// starting at i * 2^k, so it is centred at finest coordinate (i + 0.5) * 2^k - 0.5.

#include <cstdint>
#include <vector>

#include "core/brick_key.h"
#include "core/error.h"
#include "core/math.h"

namespace brickyard {

struct StoreLayout {
  Vec3s dims{0};       ///< finest level, in voxels
  int brick_size = 32; ///< M
  int levels = 0;

  /// @brief The layout for a volume: as many levels as it takes for one brick to cover level 0.
  static StoreLayout make(const Vec3s& dims, int brick_size);

  int finest() const { return levels - 1; }
  /// @brief Halving steps from the finest level: 0 at the finest level.
  int steps(int level) const { return finest() - level; }
  Vec3s level_dims(int level) const;
  Vec3s level_bricks(int level) const;
  int64_t brick_count(int level) const { return volume(level_bricks(level)); }
  int64_t total_bricks() const;
  bool contains(const BrickKey& k) const;
  /// @brief Row-major position of a brick within its level: (z * ny + y) * nx + x.
  int64_t linear_index(const BrickKey& k) const;
  BrickKey key_at(int level, int64_t linear) const;
};

/// @brief Node flags.
enum NodeFlag : uint32_t {
  kNodeConstant = 1u << 0,     ///< every voxel of the brick (apron included) has one value: no payload
  kNodeEmpty = 1u << 1,        ///< constant and equal to the store's background
  kNodeHasChildren = 1u << 2,  ///< not at the finest level
  kNodeFinest = 1u << 3,       ///< at the finest level
};

/// @brief One node of the brick octree: the value range over the node's trilinear cells
/// (voxels [b*M, (b+1)*M] clamped to the level, so the forward neighbours are included and
/// the range is conservative for isosurfaces), flags, and the constant value. 16 bytes, stored
/// as is in the `nodes` database.
struct NodeRecord {
  float min = 0, max = 0;
  float constant = 0;
  uint32_t flags = 0;

  bool is_constant() const { return flags & kNodeConstant; }
  bool is_empty() const { return flags & kNodeEmpty; }
  bool has_payload() const { return !is_constant(); }
  friend bool operator==(const NodeRecord&, const NodeRecord&) = default;
};
static_assert(sizeof(NodeRecord) == 16, "node records are part of the on-disk format");

/// @brief Every node of a store, by level, in row-major brick order: O(1) lookup by key.
/// Immutable after loading, so any number of threads may read it.
class NodeTable {
 public:
  NodeTable() = default;
  explicit NodeTable(const StoreLayout& layout);

  const StoreLayout& layout() const { return layout_; }
  const NodeRecord& at(const BrickKey& k) const { return levels_[k.level][size_t(layout_.linear_index(k))]; }
  NodeRecord& at(const BrickKey& k) { return levels_[k.level][size_t(layout_.linear_index(k))]; }
  const std::vector<NodeRecord>& level(int l) const { return levels_[size_t(l)]; }
  std::vector<NodeRecord>& level(int l) { return levels_[size_t(l)]; }
  size_t bytes() const;

 private:
  StoreLayout layout_;
  std::vector<std::vector<NodeRecord>> levels_;
};

}  // namespace brickyard
