#pragma once
/// @file json_reader.h
/// @brief Strict reading of JSON objects for user-written files (scenes, camera paths): every
/// key read is checked for type and range, and finish() rejects keys nobody asked for, so a
/// misspelled key is an error naming it rather than a silently ignored setting (pbrt's
/// ReportUnused). Errors name the file and the full key path ("shading.light.kind").
///
/// Includes nlohmann/json: include it from .cpp files only.

#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/math.h"

namespace brickyard {

/// @brief Parses a JSON file (comments allowed); Error(io) or Error(format) naming the file.
nlohmann::json read_json_file(const std::string& path);

/// @brief "not valid JSON: " and what nlohmann found, without its "[json.exception.*]" tag
/// (syntax errors, and numbers too large for a double, such as 1e999).
std::string json_error_message(const nlohmann::json::exception& e);

class JsonObjectReader {
 public:
  /// @param where the key path of this object, "" for the top level ("shading" for a member).
  JsonObjectReader(const nlohmann::json& object, std::string file, std::string where = "");

  const std::string& file() const { return file_; }
  /// @brief "where.key" (or "key" at the top level).
  std::string path(std::string_view key) const;
  bool has(std::string_view key) const;
  /// @brief The raw member (marked as read); nullptr when absent.
  const nlohmann::json* get(std::string_view key);
  const nlohmann::json& require(std::string_view key);

  double number(std::string_view key, double fallback, double lo = -1e308, double hi = 1e308);
  double required_number(std::string_view key, double lo = -1e308, double hi = 1e308);
  int64_t integer(std::string_view key, int64_t fallback, int64_t lo, int64_t hi);
  bool boolean(std::string_view key, bool fallback);
  std::string string(std::string_view key, std::string_view fallback);
  std::string string(std::string_view key);  ///< required
  /// @brief A string that must be one of `choices`.
  std::string choice(std::string_view key, std::string_view fallback, std::initializer_list<std::string_view> choices);
  Vec3d vec3(std::string_view key, const Vec3d& fallback);
  Vec3d vec3(std::string_view key);  ///< required
  /// @brief A nested object's reader; throws if the member is not an object.
  JsonObjectReader object(std::string_view key);

  /// @brief Throws Error(format) naming the first key that was never read, with the known keys.
  void finish(std::initializer_list<std::string_view> also_known = {}) const;

  /// @brief Error(format) about a key of this object, naming the file and the key path.
  Error error(std::string_view key, std::string_view message) const;

 private:
  const nlohmann::json& object_;
  std::string file_, where_;
  std::set<std::string, std::less<>> read_;  // every key asked for: the known keys
};

/// @brief Reads [x, y, z] (finite numbers); `reader` and `key` name it in errors.
Vec3d json_vec3(const JsonObjectReader& reader, std::string_view key, const nlohmann::json& value);

namespace detail {
template <typename T> struct is_std_vector : std::false_type {};
template <typename U, typename A> struct is_std_vector<std::vector<U, A>> : std::true_type {};
}  // namespace detail

/// @brief `v` as a T when it holds one exactly, else nullopt; for readers of files that keep
/// their own key checks (manifests, sidecars). Integer types take JSON integers (or numbers
/// with no fraction) within their range: nlohmann's get<>() converts 1e30 to an int with
/// undefined behaviour and wraps 2^64-1 to -1. Floating-point types take finite numbers (a
/// literal beyond the double range parses as infinity, which JSON cannot write back); bool
/// only booleans; std::string only strings; std::vector<U> arrays of U.
template <typename T>
std::optional<T> json_exact(const nlohmann::json& v) {
  if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean()) return std::nullopt;
    return v.get<bool>();
  } else if constexpr (std::is_integral_v<T>) {
    using L = std::numeric_limits<T>;
    if (v.is_number_unsigned()) {
      const uint64_t u = v.get<uint64_t>();
      if (u > uint64_t(L::max())) return std::nullopt;
      return T(u);
    }
    if (v.is_number_integer()) {
      const int64_t i = v.get<int64_t>();
      if (i < 0 ? (!L::is_signed || i < int64_t(L::min())) : uint64_t(i) > uint64_t(L::max())) return std::nullopt;
      return T(i);
    }
    if (v.is_number_float()) {
      const double d = v.get<double>();
      if (!(d >= double(L::min()) && d < double(L::max()) + 1.0) || d != std::floor(d)) return std::nullopt;
      return T(d);
    }
    return std::nullopt;
  } else if constexpr (std::is_floating_point_v<T>) {
    if (!v.is_number()) return std::nullopt;
    const double d = v.get<double>();
    if (!std::isfinite(d) || std::fabs(d) > double(std::numeric_limits<T>::max())) return std::nullopt;
    return T(d);
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!v.is_string()) return std::nullopt;
    return v.get<std::string>();
  } else {
    static_assert(detail::is_std_vector<T>::value, "json_exact: bool, integers, floating point, strings and vectors of them");
    if (!v.is_array()) return std::nullopt;
    T out;
    out.reserve(v.size());
    for (const nlohmann::json& e : v) {
      auto x = json_exact<typename T::value_type>(e);
      if (!x) return std::nullopt;
      out.push_back(std::move(*x));
    }
    return out;
  }
}

/// @brief What json_exact<T> takes, for messages: "an integer in [0, 255]", "a finite number".
template <typename T>
std::string json_expected() {
  if constexpr (std::is_same_v<T, bool>) {
    return "true or false";
  } else if constexpr (std::is_same_v<T, int64_t>) {
    return "an integer";  // (its limits, 19 digits each, would say nothing to a reader)
  } else if constexpr (std::is_integral_v<T>) {
    return "an integer in [" + std::to_string(std::numeric_limits<T>::min()) + ", " +
           std::to_string(std::numeric_limits<T>::max()) + "]";
  } else if constexpr (std::is_floating_point_v<T>) {
    return "a finite number";
  } else if constexpr (std::is_same_v<T, std::string>) {
    return "a string";
  } else {
    return "an array, each element " + json_expected<typename T::value_type>();
  }
}

/// @brief What a value is, for messages: a number as written, else its kind ("a string").
std::string json_found(const nlohmann::json& v);

}  // namespace brickyard
