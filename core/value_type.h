#pragma once
/// @file value_type.h
/// @brief Voxel value types: the five a store holds natively (u8, i8, u16, i16, f32), the
/// element types files carry (those and u32, i32, f64, converted on import), names, sizes,
/// limits, and a compile-time map.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace brickyard {

/// The values are on disk (brick headers, octree pages): never renumber them.
enum class ValueType : uint8_t { u8 = 1, u16 = 2, f32 = 3, i8 = 4, i16 = 5 };

/// @brief Bytes per voxel.
constexpr size_t size_of(ValueType t) {
  switch (t) {
    case ValueType::u8: case ValueType::i8: return 1;
    case ValueType::u16: case ValueType::i16: return 2;
    case ValueType::f32: return 4;
  }
  return 0;
}

/// @brief Whether `code` (a brick or page header's byte) names a ValueType.
constexpr bool is_value_type_code(uint8_t code) { return code >= 1 && code <= 5; }

/// @brief "u8", "i8", "u16", "i16" or "f32".
std::string_view to_string(ValueType t);
/// @brief Parses "u8", "i8", "u16", "i16", "f32" (also "uint8", "int8", "uint16", "int16",
/// "float", "float32").
std::optional<ValueType> parse_value_type(std::string_view s);
/// @brief Throws Error(invalid_argument) naming the field and the accepted names.
ValueType value_type_from_string(std::string_view s, std::string_view field = "type");

/// @brief Whether stored values are integers (u8, i8, u16, i16): a procedural field is then
/// quantised onto [integer_min, integer_max].
constexpr bool is_integer(ValueType t) { return t != ValueType::f32; }
constexpr bool is_signed(ValueType t) { return t == ValueType::i8 || t == ValueType::i16 || t == ValueType::f32; }

/// @brief Smallest and largest representable integer of an integer type (0 for f32).
constexpr double integer_min(ValueType t) {
  return t == ValueType::i8 ? -128.0 : (t == ValueType::i16 ? -32768.0 : 0.0);
}
constexpr double integer_max(ValueType t) {
  switch (t) {
    case ValueType::u8: return 255.0;
    case ValueType::i8: return 127.0;
    case ValueType::u16: return 65535.0;
    case ValueType::i16: return 32767.0;
    case ValueType::f32: break;
  }
  return 0.0;
}
/// @brief How many distinct values an integer type has (256 or 65536; 0 for f32).
constexpr size_t integer_count(ValueType t) {
  return is_integer(t) ? size_t(integer_max(t) - integer_min(t)) + 1 : 0;
}

template <typename T> struct ValueTypeOf;
template <> struct ValueTypeOf<uint8_t> { static constexpr ValueType value = ValueType::u8; };
template <> struct ValueTypeOf<int8_t> { static constexpr ValueType value = ValueType::i8; };
template <> struct ValueTypeOf<uint16_t> { static constexpr ValueType value = ValueType::u16; };
template <> struct ValueTypeOf<int16_t> { static constexpr ValueType value = ValueType::i16; };
template <> struct ValueTypeOf<float> { static constexpr ValueType value = ValueType::f32; };

/// @brief Calls f with a value of the C++ type that stores t (uint8_t, int8_t, uint16_t,
/// int16_t, float), so that type-generic code is instantiated once per type and dispatched once
/// per call.
template <typename F>
decltype(auto) dispatch_value_type(ValueType t, F&& f) {
  switch (t) {
    case ValueType::u8: return f(uint8_t{});
    case ValueType::i8: return f(int8_t{});
    case ValueType::u16: return f(uint16_t{});
    case ValueType::i16: return f(int16_t{});
    case ValueType::f32: break;
  }
  return f(float{});
}

/// @brief Widens [lo, hi] to cover every value in `values` (stored as `type`, native order).
void extend_range(std::span<const std::byte> values, ValueType type, double& lo, double& hi);

/// @brief The element types of files: the stored ones, and u32, i32 and f64, which import
/// converts to f32 (exactly, or with the error it reports).
enum class ElementType : uint8_t { u8, i8, u16, i16, u32, i32, f32, f64 };

constexpr size_t size_of(ElementType t) {
  switch (t) {
    case ElementType::u8: case ElementType::i8: return 1;
    case ElementType::u16: case ElementType::i16: return 2;
    case ElementType::u32: case ElementType::i32: case ElementType::f32: return 4;
    case ElementType::f64: return 8;
  }
  return 0;
}
std::string_view to_string(ElementType t);
/// @brief The value type a store holds this element type as: itself where native, else f32.
ValueType stored_type(ElementType t);
/// @brief The element type of a stored value type.
ElementType element_type(ValueType t);
/// @brief Whether import stores this element type as it is (no conversion).
constexpr bool is_native(ElementType t) {
  return t != ElementType::u32 && t != ElementType::i32 && t != ElementType::f64;
}
/// @brief Parses every ValueType name and "u32", "i32", "f64" (also "uint32", "int32", "double",
/// "float64").
std::optional<ElementType> parse_element_type(std::string_view s);
/// @brief Throws Error(invalid_argument) naming the field and the accepted names.
ElementType element_type_from_string(std::string_view s, std::string_view field = "type");

}  // namespace brickyard
