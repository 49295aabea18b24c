#pragma once
/// @file manifest.h
/// @brief A store's manifest: what the data is (dims, type, geometry, value range,
/// histogram), how it is stored (brick format, codec, levels), where it came from and how it
/// was built, and whether the build completed. Stored as JSON in the `manifest` database.
///
/// `complete` is written true only in the very last transaction of a build, so a store whose
/// build was interrupted at any moment never claims to be complete.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/math.h"
#include "dataset/dataset.h"
#include "dataset/grid.h"
#include "dataset/octree.h"
#include "storage/brick_codec.h"

namespace brickyard {

/// Version 1: grid stores (a manifest without `kind` is one). Version 2 adds tetrahedral
/// stores; version 3 grids of several time steps, whose record and node-table keys carry the
/// step. Single-step grids are still written as version 1 and meshes as version 2, so older
/// builds keep reading them, and refuse what they cannot read.
inline constexpr int kStoreFormatVersion = 3;
inline constexpr int kGridStoreFormatVersion = 1;
inline constexpr int kMeshStoreFormatVersion = 2;
inline constexpr int kTimeSeriesGridFormatVersion = 3;

struct Histogram {
  double lo = 0, hi = 0;          ///< bins split [lo, hi] evenly; values outside are clamped into the end bins
  std::vector<uint64_t> counts;   ///< 256 bins over the finest level
  uint64_t total() const;
  /// @brief Value below which a fraction q of the voxels lie (bin-resolution).
  double quantile(double q) const;
};

/// @brief One time step's value range over its finest level, in stored units.
struct StepValueRange {
  double min = 0, max = 0;
  friend bool operator==(const StepValueRange&, const StepValueRange&) = default;
};

struct LevelStats {
  int64_t bricks = 0;    ///< nodes at this level
  int64_t constant = 0;  ///< constant nodes (no payload), empty ones included
  int64_t empty = 0;     ///< constant at the background value
  uint64_t raw_bytes = 0;     ///< decoded bytes of the stored bricks (aprons included)
  uint64_t stored_bytes = 0;  ///< record bytes of the stored bricks (headers included)
};

/// @brief What a tetrahedral store's manifest says of its mesh (the cluster table has the rest).
struct MeshSummary {
  Box3d bounds;              ///< every vertex, world coordinates
  uint64_t clusters = 0, tets = 0, vertices = 0;
  uint64_t page_bytes = 0;   ///< the decoded size of every cluster page (the largest cluster's)
  bool moving = false;       ///< vertices move: pages hold positions for every time step
  /// Cluster pages' position sets: one, or one per time step.
  uint32_t position_sets(int time_steps) const { return moving ? uint32_t(time_steps) : 1u; }
};

struct Manifest {
  int format_version = kGridStoreFormatVersion;
  bool complete = false;
  DataKind kind = DataKind::structured;
  int time_steps = 1;
  MeshSummary mesh;  ///< tetrahedral stores only
  // Grid stores only: dims through stats.
  Vec3s dims{0};
  Vec3d spacing{1.0};
  Vec3d origin{0.0};
  BrickFormat format;
  int levels = 0;
  double min_value = 0, max_value = 0;  ///< over the finest level (of every step), in stored units
  /// A grid of several time steps: each step's value range (its finest level), in step order.
  std::vector<StepValueRange> step_ranges;
  double background = 0;
  Histogram histogram;               ///< every step's voxels
  std::vector<LevelStats> stats;     ///< summed over the steps
  /// An octree volume beside the bricks (`octree` database), written by build-octree; absent
  /// until one is complete.
  std::optional<OctreeSummary> octree;
  /// JSON objects, kept as canonical text so the JSON library stays inside storage/*.cpp.
  std::string source = "{}";  ///< provenance: kind, path, size, checksum, parameters
  std::string build = "{}";   ///< build parameters (downsampling, tolerance, clamp, ...)

  GridLayout layout() const;
  /// @brief Canonical JSON (sorted keys, 2-space indent).
  std::string to_json() const;
  /// @brief Parses and validates; errors name `path` and the key at fault. A newer
  /// format_version is Error(unsupported).
  static Manifest from_json(const std::string& text, const std::string& path);
};

}  // namespace brickyard
