#pragma once
/// @file flight.h
/// @brief A renderer-shaped workload for the cache: a camera flies a path and, each frame, the
/// brick octree is refined the way a level-of-detail renderer refines it (view frustum,
/// projected voxel size), and the chosen bricks are looked up front to back. It produces the
/// realistic traces the cache-policy benchmarks replay, before any renderer exists.

#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "cache/brick_cache.h"
#include "cache/page_cache.h"
#include "core/camera.h"
#include "dataset/tet.h"

namespace brickyard {

struct FlightOptions {
  double lod_ratio = 1.0;       ///< refine while a voxel projects to more than this many pixels
  /// Meshes: only clusters whose range (in `time_step`) meets [values_lo, values_hi], as a
  /// scene asks for the clusters an isovalue or a transfer function can see.
  double values_lo = -std::numeric_limits<double>::infinity(), values_hi = std::numeric_limits<double>::infinity();
  int time_step = 0;
  bool wait_for_loads = true;   ///< let the loader finish between frames (deterministic traces)
  int frames = 0;               ///< 0: the path's own frame count
};

struct FlightFrame {
  int frame = 0;
  uint64_t nodes_visited = 0;  ///< octree nodes tested
  uint64_t bricks_used = 0;    ///< bricks the frame looked up
  uint64_t hits = 0;           ///< of those, resident (or constant)
  uint64_t requests = 0;       ///< distinct requests the frame made
  uint64_t uploads = 0;
  double seconds = 0;
};

/// @brief Flies `path` through the cache's grid; calls `on_frame` after each frame. Bricks'
/// boxes and their level of detail come from the grid view (GridView::brick_world_box,
/// GridView::brick_voxel_pixels), as the level-of-detail back ends take them.
std::vector<FlightFrame> fly(BrickCache& cache, const CameraPath& path, const FlightOptions& options,
                             const std::function<void(const FlightFrame&)>& on_frame = {});

}  // namespace brickyard

namespace brickyard {

/// @brief The same flight over a tetrahedral mesh's cluster table: each frame, the clusters
/// whose bounds the view may see and whose value range meets the options' are looked up front
/// to back (nearest first), through the page cache, as a tetrahedral back end asks for them.
/// FlightFrame's bricks are clusters here; nodes_visited counts the cluster-table entries tested.
std::vector<FlightFrame> fly_clusters(PageCache& cache, const TetView& tets, const Box3d& world, const CameraPath& path,
                                      const FlightOptions& options,
                                      const std::function<void(const FlightFrame&)>& on_frame = {});

}  // namespace brickyard
