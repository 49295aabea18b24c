#pragma once
/// @file volume_source.h
/// @brief What the multiresolution builder reads: a volume delivered slab by slab in z, so
/// that no source ever needs the whole grid in memory.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "core/math.h"
#include "core/value_type.h"
#include "fields/field.h"

namespace brickyard {

class VolumeSource {
 public:
  virtual ~VolumeSource() = default;

  /// @brief What error messages call the source: its path, or "field fbm".
  virtual std::string name() const = 0;
  virtual Vec3s dims() const = 0;
  virtual ValueType type() const = 0;
  virtual Vec3d spacing() const { return Vec3d(1.0); }
  virtual Vec3d origin() const { return Vec3d(0.0); }
  /// @brief The value of space the source does not describe (OpenVDB's background); constant
  /// bricks at this value are flagged empty.
  virtual double background() const { return 0.0; }
  /// @brief Bounds of the stored values when known without reading the data (stored units).
  virtual std::optional<ValueRange> value_range_hint() const { return std::nullopt; }
  /// @brief Whether the data may hold NaN or infinities (f32 files may; fields never do).
  virtual bool may_contain_nonfinite() const { return type() == ValueType::f32; }
  /// @brief Fills z-slices [z0, z1) into out, x fastest; exactly (z1-z0)*nx*ny values. Calls
  /// come in increasing z; rewind() starts over at z = 0.
  virtual void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) = 0;
  virtual void rewind() {}
  /// @brief Provenance as a JSON object (kind, path, size, checksum, parameters).
  virtual std::string describe_json() const = 0;
  /// @brief Total input bytes, for throughput figures (the raw file size, or dims * type size).
  virtual uint64_t input_bytes() const { return uint64_t(volume(dims())) * size_of(type()); }
};

/// @brief How a raw file is laid out (everything the sidecar would say).
struct RawFileSpec {
  Vec3s dims{0};
  ValueType type = ValueType::u8;
  bool little_endian = true;
  uint64_t header_bytes = 0;  ///< bytes to skip before the first voxel
  Vec3d spacing{1.0};
  Vec3d origin{0.0};
  std::optional<ValueRange> range;  ///< from a sidecar, if any
  /// XXH3-64 of the file from its sidecar: then the store's record of its source is the
  /// content, so regenerating identical data does not make a complete store look stale.
  std::optional<uint64_t> xxh3_64;
  /// What generated the data, from its sidecar: {"field": NAME, "params": {...}, and for u8/u16
  /// "quantization": [lo, hi]} as JSON text ("" when unknown). Recorded in the store's source so
  /// that the reference renderer can render the analytic truth.
  std::string generator_json;
};

/// @brief A raw file, memory-mapped. Checks its size against dims, type and header first.
std::unique_ptr<VolumeSource> open_raw_source(const std::string& path, const RawFileSpec& spec);
/// @brief A procedural field sampled on the fly (no temporary file).
std::unique_ptr<VolumeSource> make_field_source(std::unique_ptr<Field> field, const Vec3s& dims, ValueType type);
/// @brief A NRRD file (raw or gzip encoding; attached or detached data).
std::unique_ptr<VolumeSource> open_nrrd_source(const std::string& path);
/// @brief Whether this build can read OpenVDB files.
bool vdb_support();
/// @brief One grid of an OpenVDB file (float, double or int32; level set or fog volume).
std::unique_ptr<VolumeSource> open_vdb_source(const std::string& path, const std::string& grid_name);

}  // namespace brickyard
