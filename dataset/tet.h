#pragma once
/// @file tet.h
/// @brief The typed view of a tetrahedral dataset: its cluster table (bounds, value range and
/// counts of every cluster, loaded whole when the dataset opens) and the layout of a decoded
/// cluster page (RecordKind::tet_cluster, id = the cluster's index in the table).
///
/// A decoded page is, in native byte order: u32 vertex count V, u32 tet count T, then V
/// positions (3 floats each, world coordinates), V scalars (float), and T tetrahedra of 4 u32
/// vertex indices local to the cluster. Every page of a dataset is decoded into the same
/// number of bytes (the largest cluster's); the bytes past a smaller cluster's end are zero.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/math.h"

namespace brickyard {

/// @brief One cluster of the table: 40 bytes, stored as is (little-endian).
struct TetCluster {
  float lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};  ///< bounds of its vertices, world coordinates
  float min = 0, max = 0;                       ///< range of its scalars
  uint32_t tets = 0, vertices = 0;

  Box3d bounds() const { return {Vec3d(lo[0], lo[1], lo[2]), Vec3d(hi[0], hi[1], hi[2])}; }
  friend bool operator==(const TetCluster&, const TetCluster&) = default;
};
static_assert(sizeof(TetCluster) == 40, "cluster records are part of the on-disk format");

/// @brief A decoded cluster page, read in place (pointers into the page's bytes).
struct TetClusterPage {
  uint32_t vertex_count = 0, tet_count = 0;
  const float* positions = nullptr;  ///< 3 per vertex
  const float* values = nullptr;     ///< 1 per vertex
  const uint32_t* corners = nullptr; ///< 4 per tetrahedron, local vertex indices

  /// @brief Bytes a page of V vertices and T tetrahedra needs.
  static size_t bytes(uint32_t vertices, uint32_t tets);
  /// @brief Lays a cluster out as a page (bytes(V, T) of them).
  static std::vector<std::byte> encode(std::span<const float> positions, std::span<const float> values,
                                       std::span<const uint32_t> corners);
  /// @brief A page's contents. @throws Error(corrupt) when its counts do not fit its bytes
  /// (indices are checked when a page is encoded; a stored page's checksum covers them).
  static TetClusterPage view(std::span<const std::byte> page);
};

/// @brief A tetrahedral dataset as back ends see it. The table is the opener's (the store's):
/// valid while the dataset that handed it out is open.
class TetView {
 public:
  TetView(std::span<const TetCluster> clusters, size_t page_bytes) : clusters_(clusters), page_bytes_(page_bytes) {}
  std::span<const TetCluster> clusters() const { return clusters_; }
  /// @brief The size of every decoded cluster page.
  size_t page_bytes() const { return page_bytes_; }
  uint64_t tet_count() const;

 private:
  std::span<const TetCluster> clusters_;
  size_t page_bytes_ = 0;
};

}  // namespace brickyard
