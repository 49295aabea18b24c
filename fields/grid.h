#pragma once
/// @file grid.h
/// @brief Sampling a field onto a grid, slab by slab, in u8, u16 or f32, and writing it as a
/// raw file with its JSON sidecar.
///
/// Grids are vertex-centred on the field's domain: sample (i, j, k) lies at
/// origin + (i, j, k) * spacing with spacing = extent / (n - 1), so the first and last samples
/// sit on the domain faces (a 1-sample axis samples the domain centre). Memory stays bounded
/// by one slab however large the grid: a 2048^3 field streams through a few tens of MB.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <string>

#include "core/math.h"
#include "core/raw_volume.h"
#include "core/value_type.h"
#include "fields/field.h"

namespace brickyard {

class Progress;

/// @brief Maps a real value to the stored type: the integer types scale [r.lo, r.hi] onto
/// [integer_min, integer_max] with round-to-nearest and clamping; f32 converts.
template <typename T>
inline T quantize(double v, const ValueRange& r) {
  if constexpr (std::is_same_v<T, float>) {
    return static_cast<float>(v);
  } else {
    constexpr double top = integer_max(ValueTypeOf<T>::value) - integer_min(ValueTypeOf<T>::value);
    double s = (v - r.lo) / (r.hi - r.lo) * top;
    s = s > 0.0 ? s : 0.0;  // also maps NaN to the bottom
    s = s < top ? s : top;  // branch-free min/max, so row loops vectorise
    // Rounded while still non-negative, then shifted: the same rounding for signed types.
    return static_cast<T>(int32_t(s + 0.5) + int32_t(integer_min(ValueTypeOf<T>::value)));
  }
}

/// @brief Inverse of quantize for integer types (the value a stored integer stands for).
double dequantize(double stored, ValueType type, const ValueRange& r);

class GridSampler {
 public:
  /// @throws Error(invalid_argument) if a dimension is below 1 or the byte size overflows.
  GridSampler(const Field& field, const Vec3s& dims, ValueType type);

  const Field& field() const { return field_; }
  const Vec3s& dims() const { return dims_; }
  ValueType type() const { return type_; }
  Vec3d origin() const { return field_.domain().lo + offset_; }
  Vec3d spacing() const { return spacing_; }
  /// @brief Field coordinates of sample (i, j, k).
  Vec3d position(int64_t i, int64_t j, int64_t k) const {
    return origin() + Vec3d(double(i), double(j), double(k)) * spacing_;
  }
  /// @brief Whether integer samples are the field's values themselves: an integer-valued
  /// field (Field::integer_valued()) whose range the integer type holds.
  bool stores_values_as_is() const;
  /// @brief The real range integer types quantise: the field's range, or the type's own
  /// range when stores_values_as_is() (stored s means s).
  ValueRange quantization() const;
  size_t slice_bytes() const { return size_t(dims_.x) * size_t(dims_.y) * size_of(type_); }

  /// @brief Fills z-slices [z0, z1) into out (exactly (z1 - z0) * slice_bytes() bytes),
  /// x fastest. Parallel over rows (TBB); the result does not depend on the thread count.
  void sample_slab(int64_t z0, int64_t z1, std::span<std::byte> out) const;

 private:
  const Field& field_;
  Vec3s dims_;
  ValueType type_;
  Vec3d spacing_, offset_;
};

/// @brief Streams the grid through `sink` in z-order, slab_slices slices at a time
/// (0: chosen so a slab is about 32 MiB). sink(z0, z1, bytes) owns nothing after it returns.
void stream_grid(const GridSampler& sampler, int64_t slab_slices,
                 const std::function<void(int64_t z0, int64_t z1, std::span<const std::byte>)>& sink,
                 Progress* progress = nullptr);

/// @brief Samples the grid into a raw file plus sidecar (PATH.json). The raw file is written to
/// PATH.partial and renamed only when complete; the sidecar carries min/max and XXH3-64.
RawVolumeInfo write_raw_grid(const GridSampler& sampler, const std::string& path, Progress* progress = nullptr);

}  // namespace brickyard
