#pragma once
/// @file json_reader.h
/// @brief Strict reading of JSON objects for user-written files (scenes, camera paths): every
/// key read is checked for type and range, and finish() rejects keys nobody asked for, so a
/// misspelled key is an error naming it rather than a silently ignored setting (pbrt's
/// ReportUnused). Errors name the file and the full key path ("shading.light.kind").
///
/// Includes nlohmann/json: include it from .cpp files only.

#include <initializer_list>
#include <optional>
#include <set>
#include <string>
#include <string_view>
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

}  // namespace brickyard
