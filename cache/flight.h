#pragma once
/// @file flight.h
/// @brief A renderer-shaped workload for the cache: a camera flies a path and, each frame, the
/// brick octree is refined the way a level-of-detail renderer refines it (view frustum,
/// projected voxel size), and the chosen bricks are looked up front to back. It produces the
/// realistic traces the cache-policy benchmarks replay, before any renderer exists.

#include <cstdint>
#include <functional>
#include <vector>

#include "cache/brick_cache.h"
#include "core/camera.h"

namespace brickyard {

struct FlightOptions {
  double lod_ratio = 1.0;       ///< refine while a voxel projects to more than this many pixels
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

/// @brief World-space box of a brick of the store (voxel centres, from origin and spacing).
Box3d brick_world_box(const StoreLayout& layout, const Manifest& manifest, const BrickKey& key);

/// @brief Pixels that one voxel of the brick's level covers, seen by `cam` at the nearest point
/// of the brick's world box (the level-of-detail measure of refinement).
double brick_voxel_pixels(const StoreLayout& layout, const Manifest& manifest, const Camera& cam, const BrickKey& key,
                          const Box3d& world_box, int height);

/// @brief Flies `path` through the cache's store; calls `on_frame` after each frame.
std::vector<FlightFrame> fly(BrickCache& cache, const CameraPath& path, const FlightOptions& options,
                             const std::function<void(const FlightFrame&)>& on_frame = {});

}  // namespace brickyard
