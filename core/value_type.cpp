#include "core/value_type.h"

#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

std::string_view to_string(ValueType t) {
  switch (t) {
    case ValueType::u8: return "u8";
    case ValueType::i8: return "i8";
    case ValueType::u16: return "u16";
    case ValueType::i16: return "i16";
    case ValueType::f32: return "f32";
  }
  return "?";
}

std::optional<ValueType> parse_value_type(std::string_view s) {
  if (s == "u8" || s == "uint8") return ValueType::u8;
  if (s == "i8" || s == "int8") return ValueType::i8;
  if (s == "u16" || s == "uint16") return ValueType::u16;
  if (s == "i16" || s == "int16") return ValueType::i16;
  if (s == "f32" || s == "float" || s == "float32") return ValueType::f32;
  return std::nullopt;
}

ValueType value_type_from_string(std::string_view s, std::string_view field) {
  if (auto t = parse_value_type(s)) return *t;
  throw Error(Errc::invalid_argument, fmt::format("unknown value type '{}' (expected u8, i8, u16, i16 or f32)", s))
      .with_field(field);
}

void extend_range(std::span<const std::byte> values, ValueType type, double& lo, double& hi) {
  dispatch_value_type(type, [&](auto tag) {
    using T = decltype(tag);
    const T* v = reinterpret_cast<const T*>(values.data());
    const size_t n = values.size() / sizeof(T);
    if (n == 0) return;
    T mn = std::numeric_limits<T>::max(), mx = std::numeric_limits<T>::lowest();
    for (size_t i = 0; i < n; ++i) {
      mn = std::min(mn, v[i]);
      mx = std::max(mx, v[i]);
    }
    lo = std::min(lo, double(mn));
    hi = std::max(hi, double(mx));
  });
}

std::string_view to_string(ElementType t) {
  switch (t) {
    case ElementType::u8: return "u8";
    case ElementType::i8: return "i8";
    case ElementType::u16: return "u16";
    case ElementType::i16: return "i16";
    case ElementType::u32: return "u32";
    case ElementType::i32: return "i32";
    case ElementType::f32: return "f32";
    case ElementType::f64: return "f64";
  }
  return "?";
}

ValueType stored_type(ElementType t) {
  switch (t) {
    case ElementType::u8: return ValueType::u8;
    case ElementType::i8: return ValueType::i8;
    case ElementType::u16: return ValueType::u16;
    case ElementType::i16: return ValueType::i16;
    default: return ValueType::f32;
  }
}

ElementType element_type(ValueType t) {
  switch (t) {
    case ValueType::u8: return ElementType::u8;
    case ValueType::i8: return ElementType::i8;
    case ValueType::u16: return ElementType::u16;
    case ValueType::i16: return ElementType::i16;
    case ValueType::f32: break;
  }
  return ElementType::f32;
}

std::optional<ElementType> parse_element_type(std::string_view s) {
  if (auto t = parse_value_type(s)) return element_type(*t);
  if (s == "u32" || s == "uint32") return ElementType::u32;
  if (s == "i32" || s == "int32") return ElementType::i32;
  if (s == "f64" || s == "double" || s == "float64") return ElementType::f64;
  return std::nullopt;
}

ElementType element_type_from_string(std::string_view s, std::string_view field) {
  if (auto t = parse_element_type(s)) return *t;
  throw Error(Errc::invalid_argument,
              fmt::format("unknown value type '{}' (expected u8, i8, u16, i16, f32, or u32, i32, f64 to convert to f32)", s))
      .with_field(field);
}

}  // namespace brickyard
