#pragma once
/// @file manifest.h
/// @brief A store's manifest: what the data is (dims, type, geometry, value range,
/// histogram), how it is stored (brick format, codec, levels), where it came from and how it
/// was built, and whether the build completed. Stored as JSON in the `manifest` database.
///
/// `complete` is written true only in the very last transaction of a build, so a store whose
/// build was interrupted at any moment never claims to be complete.

#include <cstdint>
#include <string>
#include <vector>

#include "core/math.h"
#include "storage/brick_codec.h"
#include "storage/layout.h"

namespace brickyard {

inline constexpr int kStoreFormatVersion = 1;

struct Histogram {
  double lo = 0, hi = 0;          ///< bins split [lo, hi] evenly; values outside are clamped into the end bins
  std::vector<uint64_t> counts;   ///< 256 bins over the finest level
  uint64_t total() const;
  /// @brief Value below which a fraction q of the voxels lie (bin-resolution).
  double quantile(double q) const;
};

struct LevelStats {
  int64_t bricks = 0;    ///< nodes at this level
  int64_t constant = 0;  ///< constant nodes (no payload), empty ones included
  int64_t empty = 0;     ///< constant at the background value
  uint64_t raw_bytes = 0;     ///< decoded bytes of the stored bricks (aprons included)
  uint64_t stored_bytes = 0;  ///< record bytes of the stored bricks (headers included)
};

struct Manifest {
  int format_version = kStoreFormatVersion;
  bool complete = false;
  Vec3s dims{0};
  Vec3d spacing{1.0};
  Vec3d origin{0.0};
  BrickFormat format;
  int levels = 0;
  double min_value = 0, max_value = 0;  ///< over the finest level, in stored units
  double background = 0;
  Histogram histogram;
  std::vector<LevelStats> stats;
  /// JSON objects, kept as canonical text so the JSON library stays inside storage/*.cpp.
  std::string source = "{}";  ///< provenance: kind, path, size, checksum, parameters
  std::string build = "{}";   ///< build parameters (downsampling, tolerance, clamp, ...)

  StoreLayout layout() const;
  /// @brief Canonical JSON (sorted keys, 2-space indent).
  std::string to_json() const;
  /// @brief Parses and validates; errors name `path` and the key at fault. A newer
  /// format_version is Error(unsupported).
  static Manifest from_json(const std::string& text, const std::string& path);
};

}  // namespace brickyard
