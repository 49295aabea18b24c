#pragma once
/// @file dataset.h
/// @brief A dataset as every back end sees it: a generic part (kind, world box, value range,
/// time steps, provenance) and typed views asked for by kind (the grid's layout and node table,
/// an octree volume beside a grid, a tetrahedral mesh's cluster table).
///
/// Whoever opens a dataset (a store, session/) builds its Dataset and owns what the views point
/// to: a Dataset and its views are valid while that opener is. Immutable after construction,
/// so any number of threads may read it.

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/math.h"
#include "dataset/grid.h"
#include "dataset/octree.h"
#include "dataset/tet.h"

namespace brickyard {

/// @brief What a dataset is made of; recorded in the store's manifest (`kind`).
enum class DataKind : uint8_t {
  structured,   ///< a grid of voxels, stored as multiresolution bricks
  tetrahedral,  ///< a tetrahedral mesh with per-vertex scalars, stored as clusters
};
std::string_view to_string(DataKind k);
/// @brief "structured" or "tetrahedral"; Error(invalid_argument) naming `field` otherwise.
DataKind data_kind_from_string(std::string_view s, std::string_view field = "kind");

/// @brief The generic part of a dataset.
struct DatasetInfo {
  std::string name;        ///< where it was opened from (a store's directory), named in errors
  DataKind kind = DataKind::structured;
  Box3d world;             ///< bounding box in world coordinates
  double min_value = 0, max_value = 0;  ///< value range in stored units (the scene's `values: stored`)
  int time_steps = 1;
  /// The length errors in depth are reported in: a grid's smallest voxel spacing, a mesh's
  /// mean edge length.
  double unit_length = 1;
  /// Provenance as JSON text (kind, path, field and parameters): the reference renderer's
  /// analytic truth reads the field a store was made from here.
  std::string source = "{}";
};

/// @brief A dataset: its generic part and the typed views its kind has.
class Dataset {
 public:
  Dataset(DatasetInfo info, std::optional<GridView> grid, std::optional<TetView> tets = std::nullopt,
          std::optional<OctreeView> octree = std::nullopt)
      : info_(std::move(info)), grid_(std::move(grid)), tets_(std::move(tets)), octree_(std::move(octree)) {}

  const DatasetInfo& info() const { return info_; }
  DataKind kind() const { return info_.kind; }

  bool has_grid() const { return grid_.has_value(); }
  bool has_tets() const { return tets_.has_value(); }
  bool has_octree() const { return octree_.has_value(); }
  /// @brief The grid view. @throws Error(unsupported) naming the dataset and its kind when it
  /// has none, so a back end built for grids is refused before its first frame.
  const GridView& grid() const;
  /// @brief The tetrahedral mesh's view. @throws Error(unsupported) when the dataset has none.
  const TetView& tets() const;
  /// @brief The octree volume's view. @throws Error(unsupported) naming the dataset, with the
  /// command that builds one, when the grid has none.
  const OctreeView& octree() const;

 private:
  DatasetInfo info_;
  std::optional<GridView> grid_;
  std::optional<TetView> tets_;
  std::optional<OctreeView> octree_;
};

}  // namespace brickyard
