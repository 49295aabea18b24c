#include "core/value_type.h"

#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

std::string_view to_string(ValueType t) {
  switch (t) {
    case ValueType::u8: return "u8";
    case ValueType::u16: return "u16";
    case ValueType::f32: return "f32";
  }
  return "?";
}

std::optional<ValueType> parse_value_type(std::string_view s) {
  if (s == "u8" || s == "uint8") return ValueType::u8;
  if (s == "u16" || s == "uint16") return ValueType::u16;
  if (s == "f32" || s == "float" || s == "float32") return ValueType::f32;
  return std::nullopt;
}

ValueType value_type_from_string(std::string_view s, std::string_view field) {
  if (auto t = parse_value_type(s)) return *t;
  throw Error(Errc::invalid_argument, fmt::format("unknown value type '{}' (expected u8, u16 or f32)", s))
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

}  // namespace brickyard
