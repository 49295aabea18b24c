#pragma once
/// @file octree_builder.h
/// @brief Builds the octree volume of a grid store (dataset/octree.h) beside its bricks, in the
/// store's `octree` database, streaming: cap pages are cut from the store's bricks (the finest
/// level and the three mip levels above it) a few at a time, so memory holds a few decoded
/// bricks per thread and one summary per cap page, never the volume (the paper's build needed
/// 4x the raw size in memory).
///
/// Consolidation is bottom-up: a child whose region's finest voxels are all one value is not
/// stored (lossless, the default); with a tolerance, a child whose finest voxels are all within
/// it of one value is consolidated to that value (lossy, opt-in; the largest error is reported).
/// With a clamp range, values outside it are clamped first (lossless inside it), which
/// consolidates what lies beyond.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>

#include "dataset/octree.h"
#include "storage/store_lock.h"

namespace brickyard {

class Progress;

struct OctreeBuildOptions {
  double tolerance = 0;  ///< stored units; 0 keeps every voxel exact
  std::optional<std::pair<double, double>> clamp;
  uint64_t batch_bytes = uint64_t(32) << 20;
};

struct OctreeBuildResult {
  OctreeSummary summary;
  double seconds = 0;
};

/// @brief Builds (or rebuilds) the octree of the grid store in `dir`.
/// @throws Error naming the store: not a complete grid store, a tolerance below zero, an empty
/// or inverted clamp range. A failed build leaves the grid without an octree.
OctreeBuildResult build_octree(const std::string& dir, const OctreeBuildOptions& options, Progress* progress = nullptr);

/// @brief build_octree for a writer that already holds the store's write lock (`held`: the
/// lock of `dir`, or of the store that `dir` is being built beside).
OctreeBuildResult build_octree(const std::string& dir, const OctreeBuildOptions& options, const StoreWriteLock& held,
                               Progress* progress = nullptr);

}  // namespace brickyard
