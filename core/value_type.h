#pragma once
/// @file value_type.h
/// @brief Voxel value types (u8, u16, f32): names, sizes, limits, and a compile-time map.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace brickyard {

enum class ValueType : uint8_t { u8 = 1, u16 = 2, f32 = 3 };

/// @brief Bytes per voxel.
constexpr size_t size_of(ValueType t) {
  switch (t) {
    case ValueType::u8: return 1;
    case ValueType::u16: return 2;
    case ValueType::f32: return 4;
  }
  return 0;
}

/// @brief "u8", "u16" or "f32".
std::string_view to_string(ValueType t);
/// @brief Parses "u8", "u16", "f32" (also "uint8", "uint16", "float", "float32").
std::optional<ValueType> parse_value_type(std::string_view s);
/// @brief Throws Error(invalid_argument) naming the field and the accepted names.
ValueType value_type_from_string(std::string_view s, std::string_view field = "type");

/// @brief Whether stored integers are a quantisation of a real range (true for u8 and u16).
constexpr bool is_integer(ValueType t) { return t != ValueType::f32; }

/// @brief Largest representable integer for u8/u16 (used as the top of the quantisation).
constexpr double integer_max(ValueType t) {
  return t == ValueType::u8 ? 255.0 : (t == ValueType::u16 ? 65535.0 : 0.0);
}

template <typename T> struct ValueTypeOf;
template <> struct ValueTypeOf<uint8_t> { static constexpr ValueType value = ValueType::u8; };
template <> struct ValueTypeOf<uint16_t> { static constexpr ValueType value = ValueType::u16; };
template <> struct ValueTypeOf<float> { static constexpr ValueType value = ValueType::f32; };

/// @brief Calls f with a value of the C++ type that stores t (uint8_t, uint16_t, float), so
/// that type-generic code is instantiated once per type and dispatched once per call.
template <typename F>
decltype(auto) dispatch_value_type(ValueType t, F&& f) {
  switch (t) {
    case ValueType::u8: return f(uint8_t{});
    case ValueType::u16: return f(uint16_t{});
    case ValueType::f32: break;
  }
  return f(float{});
}

/// @brief Widens [lo, hi] to cover every value in `values` (stored as `type`, native order).
void extend_range(std::span<const std::byte> values, ValueType type, double& lo, double& hi);

}  // namespace brickyard
