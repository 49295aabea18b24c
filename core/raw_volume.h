#pragma once
/// @file raw_volume.h
/// @brief The JSON sidecar that describes a raw voxel file (FILE.raw -> FILE.raw.json):
/// dims, value type, byte order, geometry, value range, provenance and checksum. Written by
/// `brickyard generate`, read by the raw importer so that a raw file needs no extra flags.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/math.h"
#include "core/value_type.h"

namespace brickyard {

inline constexpr int kRawSidecarVersion = 1;

struct RawVolumeInfo {
  Vec3s dims{0};
  ValueType type = ValueType::f32;
  bool little_endian = true;
  Vec3d spacing{1.0};  ///< distance between neighbouring samples along each axis
  Vec3d origin{0.0};   ///< position of sample (0, 0, 0)
  /// Smallest and largest stored value, in stored units (0..255 for u8).
  double min_value = 0.0, max_value = 0.0;
  /// For u8/u16 made by quantising real values: stored s means lo + s / max * (hi - lo).
  std::optional<std::pair<double, double>> quantization;
  std::string source;  ///< what produced the data ("field marschner-lobb", a file name)
  std::vector<std::pair<std::string, double>> source_params;
  uint64_t bytes = 0;                ///< size of the raw file
  std::optional<uint64_t> xxh3_64;   ///< XXH3-64 of the raw file's bytes

  int64_t voxel_count() const { return volume(dims); }
};

/// @brief Why `spacing` cannot place a grid in space (an axis zero, negative or not finite),
/// or empty when it can.
std::string spacing_problem(const Vec3d& spacing);

/// @brief Bytes of a dims grid of type t, or nullopt when the count overflows 64 bits or a
/// dimension is below 1.
std::optional<uint64_t> checked_grid_bytes(const Vec3s& dims, ValueType t);

/// @brief Sidecar path for a raw file: "vol.raw" -> "vol.raw.json".
std::string raw_sidecar_path(const std::string& raw_path);
/// @brief Writes the sidecar atomically (temporary file, then rename).
void write_raw_sidecar(const std::string& sidecar_path, const RawVolumeInfo& info);
/// @brief Reads and validates a sidecar; errors name the file and the offending key.
RawVolumeInfo read_raw_sidecar(const std::string& sidecar_path);

/// @brief Writes a whole file atomically: to PATH.partial, flushed, then renamed over PATH.
void write_file_atomically(const std::string& path, const std::string& contents);

}  // namespace brickyard
