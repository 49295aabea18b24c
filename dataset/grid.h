#pragma once
/// @file grid.h
/// @brief The typed view of a structured dataset (a grid): the geometry of its multiresolution
/// bricks (levels, their voxel and brick grids), the shape of one brick, the node table that
/// summarises every brick, and where bricks sit in the world.
///
/// This is what back ends see of a grid. It holds no store: the store that opened the dataset
/// fills a GridView and keeps the node table it points to alive (see dataset/dataset.h).
///
/// Level `levels - 1` is the finest (the source grid); each coarser level halves every
/// dimension (rounding up) until one brick covers the whole volume at level 0. Coarse voxel i
/// of a level k steps above the finest is the box-filtered average of the 2^k finest voxels
/// starting at i * 2^k, so it is centred at finest coordinate (i + 0.5) * 2^k - 0.5.
///
/// Halving every axis alike collapses the short axes of a very anisotropic grid long before
/// the long one reaches a brick (3x3x300 has levels 2x2x150 and 1x1x75; 1000x37x51 has
/// 63x3x4 and 32x2x2): such a level no longer holds the data across its short axes, however
/// small its voxels look on screen. Level-of-detail back ends use only the levels that still
/// resolve every axis (resolving_steps, GridLayout::coarsest_resolving).

#include <cstdint>
#include <vector>

#include "core/brick_key.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/math.h"
#include "core/value_type.h"

namespace brickyard {

/// @brief Voxels a coarser level must keep across an axis to stand in for the finest level
/// there (or all the finest level has, where that is fewer). Modelled on an ellipsoid filling
/// a 1000x37x51 grid, seen along each short axis: a level with 10 and 13 voxels across them
/// loses 2-3% of the silhouette's pixels, one with 5 and 7 loses 10-24%, 3 and 4 40-70%, 2
/// all of it; a 64^3 sphere loses as much at 8^3 as 1000x37x51 at 10 across. Rendered
/// (test_stiff_lod.cpp), 800x20x26 at its coarsest allowed level, 400x10x13, loses 6 of 129.
inline constexpr int64_t kResolvingVoxels = 8;

/// @brief The most halvings (ceil(dims / 2^s) per axis, as GridLayout and OctreeLayout halve)
/// after which every axis of a grid of `dims` keeps at least min(dims, kResolvingVoxels)
/// voxels: 0 for 3x3x300 (its first halving leaves 2 across), 2 for 1000x37x51.
int resolving_steps(const Vec3s& dims);

struct GridLayout {
  Vec3s dims{0};       ///< finest level, in voxels
  int brick_size = 32; ///< M
  int levels = 0;

  /// @brief The layout for a volume: as many levels as it takes for one brick to cover level 0.
  static GridLayout make(const Vec3s& dims, int brick_size);

  int finest() const { return levels - 1; }
  /// @brief Halving steps from the finest level: 0 at the finest level.
  int steps(int level) const { return finest() - level; }
  /// @brief The coarsest level that still resolves every axis (resolving_steps): level-of-detail
  /// back ends go no coarser, whatever the footprint allows. 0 for a grid whose level 0 does.
  int coarsest_resolving() const;
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
  explicit NodeTable(const GridLayout& layout);

  const GridLayout& layout() const { return layout_; }
  const NodeRecord& at(const BrickKey& k) const { return levels_[k.level][size_t(layout_.linear_index(k))]; }
  NodeRecord& at(const BrickKey& k) { return levels_[k.level][size_t(layout_.linear_index(k))]; }
  const std::vector<NodeRecord>& level(int l) const { return levels_[size_t(l)]; }
  std::vector<NodeRecord>& level(int l) { return levels_[size_t(l)]; }
  size_t bytes() const;

 private:
  GridLayout layout_;
  std::vector<std::vector<NodeRecord>> levels_;
};

/// @brief One brick as it is decoded: M^3 interior voxels of one value type with A replicated
/// voxels on every side, (M + 2A)^3 in all, x fastest. Fixed for a whole dataset.
struct BrickShape {
  ValueType type = ValueType::u8;
  int brick_size = 32;  ///< M, the interior edge in voxels
  int apron = 1;        ///< A, replicated voxels on every side

  int edge() const { return brick_size + 2 * apron; }
  size_t voxels() const { return size_t(edge()) * size_t(edge()) * size_t(edge()); }
  size_t bytes() const { return voxels() * size_of(type); }
};

/// @brief A grid dataset as back ends see it: levels and bricks (layout), what a decoded brick
/// holds (shape), every node's summary (nodes), and the finest level's place in the world
/// (voxel i of axis a sits at origin[a] + i * spacing[a]).
///
/// The node table is the opener's (the store's): a GridView is valid while the dataset that
/// handed it out is open. Immutable, so any number of threads may read it.
class GridView {
 public:
  GridView(const NodeTable& nodes, const BrickShape& shape, const Vec3d& origin, const Vec3d& spacing)
      : nodes_(&nodes), shape_(shape), origin_(origin), spacing_(spacing) {}

  const GridLayout& layout() const { return nodes_->layout(); }
  const NodeTable& nodes() const { return *nodes_; }
  const BrickShape& shape() const { return shape_; }
  const Vec3s& dims() const { return layout().dims; }
  const Vec3d& origin() const { return origin_; }
  const Vec3d& spacing() const { return spacing_; }
  /// @brief The finest level's voxel centres, first to last, in world coordinates.
  Box3d world_box() const { return Box3d(origin_, origin_ + spacing_ * Vec3d(dims() - Vec3s(1))); }

  /// @brief World-space box of a brick (its voxel centres, from origin and spacing), clamped to
  /// the volume's last voxel.
  Box3d brick_world_box(const BrickKey& key) const;
  /// @brief Pixels one voxel of the brick's level covers, seen by `cam` at the nearest point of
  /// the brick's world box: the level-of-detail measure of refinement.
  double brick_voxel_pixels(const Camera& cam, const BrickKey& key, const Box3d& world_box, int height) const;

 private:
  const NodeTable* nodes_;
  BrickShape shape_;
  Vec3d origin_, spacing_;
};

}  // namespace brickyard
