#pragma once
/// @file tet.h
/// @brief The typed view of a tetrahedral dataset: its cluster table (bounds, value range and
/// counts of every cluster, loaded whole when the dataset opens) and the layout of a decoded
/// cluster page (RecordKind::tet_cluster, id = the cluster's index in the table).
///
/// A decoded page is, in native byte order: u32 vertex count V, u32 tet count T, u32 time
/// steps S, u32 position sets P (1, or S for moving vertices), then P x V positions (3 floats
/// each, world coordinates), S x V scalars (float, step-major), and T tetrahedra of 4 u32
/// vertex indices local to the cluster, each positively oriented; then, in stores imported
/// with --bvh, the cluster's BVH (dataset/tet_bvh.h). Every page of a dataset is decoded into
/// the same number of bytes (the largest cluster's); the bytes past a smaller cluster's end
/// are zero.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/math.h"

namespace brickyard {

/// @brief One cluster of the table: 40 bytes, stored as is (little-endian).
struct TetCluster {
  float lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};  ///< bounds of its vertices in every step, world coordinates
  float min = 0, max = 0;                       ///< range of its scalars over every step
  uint32_t tets = 0, vertices = 0;

  Box3d bounds() const { return {Vec3d(lo[0], lo[1], lo[2]), Vec3d(hi[0], hi[1], hi[2])}; }
  friend bool operator==(const TetCluster&, const TetCluster&) = default;
};
static_assert(sizeof(TetCluster) == 40, "cluster records are part of the on-disk format");

/// @brief A decoded cluster page, read in place (pointers into the page's bytes).
struct TetClusterPage {
  uint32_t vertex_count = 0, tet_count = 0, steps = 1, position_sets = 1;
  const float* positions = nullptr;  ///< 3 per vertex (step 0's)
  const float* values = nullptr;     ///< 1 per vertex (step 0's)
  const uint32_t* corners = nullptr; ///< 4 per tetrahedron, local vertex indices
  /// The page's bytes after its tetrahedra: a stored BVH (dataset/tet_bvh.h), or zeros.
  std::span<const std::byte> tail;

  /// @brief The positions of time step `step` (step 0's when the vertices do not move).
  const float* positions_at(uint32_t step) const {
    return positions + size_t(position_sets > 1 ? step : 0) * 3 * vertex_count;
  }
  const float* values_at(uint32_t step) const { return values + size_t(step) * vertex_count; }

  /// @brief Bytes a page of V vertices, T tetrahedra, S steps and P position sets needs
  /// (SIZE_MAX when that does not fit in a size_t: counts read from a damaged page or table).
  static size_t bytes(uint32_t vertices, uint32_t tets, uint32_t steps = 1, uint32_t position_sets = 1);
  /// @brief Lays a cluster out as a page: `positions` P x V x 3, `values` S x V (step-major).
  static std::vector<std::byte> encode(std::span<const float> positions, std::span<const float> values,
                                       std::span<const uint32_t> corners, uint32_t steps = 1);
  /// @brief A page's contents. @throws Error(corrupt) when its counts do not fit its bytes
  /// (indices are checked when a page is encoded; a stored page's checksum covers them).
  static TetClusterPage view(std::span<const std::byte> page);
};

/// @brief A cluster's scalar range in one time step.
struct TetStepRange {
  float min = 0, max = 0;
  friend bool operator==(const TetStepRange&, const TetStepRange&) = default;
};

/// @brief A tetrahedral dataset as back ends see it. The tables are the opener's (the store's):
/// valid while the dataset that handed them out is open.
class TetView {
 public:
  /// @param step_ranges  clusters x steps ranges (cluster-major); empty for one step, where a
  ///                     cluster's own range is its step's.
  TetView(std::span<const TetCluster> clusters, size_t page_bytes, int steps = 1,
          std::span<const TetStepRange> step_ranges = {})
      : clusters_(clusters), page_bytes_(page_bytes), steps_(steps), step_ranges_(step_ranges) {}
  std::span<const TetCluster> clusters() const { return clusters_; }
  /// @brief The size of every decoded cluster page.
  size_t page_bytes() const { return page_bytes_; }
  int time_steps() const { return steps_; }
  /// @brief The scalar range of cluster `c` in time step `step`.
  TetStepRange range(size_t c, int step) const {
    if (step_ranges_.empty()) return {clusters_[c].min, clusters_[c].max};
    return step_ranges_[c * size_t(steps_) + size_t(step)];
  }
  uint64_t tet_count() const;

 private:
  std::span<const TetCluster> clusters_;
  size_t page_bytes_ = 0;
  int steps_ = 1;
  std::span<const TetStepRange> step_ranges_;
};

}  // namespace brickyard
