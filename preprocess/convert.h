#pragma once
/// @file convert.h
/// @brief Element types a store does not hold (u32, i32, f64) converted to f32 on import, with
/// what the conversion cost measured before anything is built.
///
/// Integers are exact in f32 up to 2^24 in magnitude; past that, import refuses unless the
/// user accepts the rounding (`--convert f32`), and then reports the worst error. Doubles are
/// always converted, and the largest relative error is reported. The report goes into the
/// store's manifest (its source's "conversion") and onto the import's output.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <utility>

#include "core/math.h"
#include "core/value_type.h"

namespace brickyard {

/// @brief How a source converts values it cannot store as they are.
struct ConvertOptions {
  /// Accept the rounding of integers beyond f32's 24-bit mantissa (`--convert f32`).
  bool accept_rounding = false;
};

/// @brief What converting every element of a file to f32 does to its values.
struct ConversionReport {
  ElementType from = ElementType::f32;
  uint64_t values = 0;
  uint64_t inexact = 0;      ///< finite values f32 does not hold exactly
  uint64_t nonfinite = 0;    ///< NaN and infinities (f64 only)
  uint64_t out_of_range = 0; ///< finite doubles beyond the largest float
  double max_abs_error = 0;  ///< over the finite values that fit
  double max_rel_error = 0;
  double worst_value = 0;    ///< the source value with the largest absolute error
  double min = std::numeric_limits<double>::infinity(), max = -std::numeric_limits<double>::infinity();

  bool exact() const { return inexact == 0 && out_of_range == 0; }
  void merge(const ConversionReport& o);
  /// @brief One line for the import's output: "i32 -> f32, exact (values in [...])".
  std::string summary() const;
  /// @brief The manifest's record, a JSON object.
  std::string to_json() const;
};

/// @brief Accounts for `n` elements of `from` (native byte order) in `report`.
void scan_elements(const std::byte* in, ElementType from, size_t n, ConversionReport& report);
/// @brief Converts `n` elements of `from` (native byte order) to `to`: copies a native type,
/// converts the others to f32 (a double beyond the float range becomes an infinity, which the
/// builder then treats as any non-finite voxel).
void convert_elements(const std::byte* in, ElementType from, size_t n, std::byte* out);
/// @brief Smallest and largest value of an integer element type ({0, 0} for f32 and f64).
std::pair<double, double> element_limits(ElementType t);
/// @brief slope * v + intercept for `n` elements of `from` (native byte order), as doubles: the
/// rescaling of NIfTI (scl_slope/inter), DICOM (RescaleSlope/Intercept) and CF (scale_factor/
/// add_offset).
void scale_elements(const std::byte* in, ElementType from, size_t n, double slope, double intercept, double* out);
/// @brief Stores `n` doubles as `to`: f32 rounds as convert_elements does; an integer type takes
/// each value as it is (the caller has checked that every one is whole and fits, range_fits).
void store_values(const double* values, size_t n, ValueType to, std::byte* out);
/// @brief Whether [lo, hi] lies within an integer type's range.
inline bool range_fits(double lo, double hi, ValueType t) { return lo >= integer_min(t) && hi <= integer_max(t); }
/// @brief Whether v is a finite whole number.
bool is_whole(double v);
/// @brief Reverses the bytes of each element in place (big-endian files).
void swap_element_bytes(std::span<std::byte> data, size_t element_size);

/// @brief Refuses a conversion that would change integers unless the options accept it, or a
/// double beyond the float range; the error names the file and the option that accepts it.
void check_conversion(const ConversionReport& report, const ConvertOptions& options, const std::string& file);

/// @brief Scans a whole volume slab by slab through `read` (z0, z1, element bytes in native
/// order), in parallel within each slab; `slab_bytes` bounds the memory.
ConversionReport scan_conversion(const Vec3s& dims, ElementType from,
                                 const std::function<void(int64_t z0, int64_t z1, std::span<std::byte>)>& read,
                                 size_t slab_bytes = size_t(32) << 20);

}  // namespace brickyard
