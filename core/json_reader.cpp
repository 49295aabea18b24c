#include "core/json_reader.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>

#include <fmt/format.h>

#include "core/atomic_file.h"

namespace brickyard {

std::string json_error_message(const nlohmann::json::exception& e) {
  std::string_view what = e.what();
  if (what.starts_with("[json.exception.")) {
    if (const size_t end = what.find("] "); end != std::string_view::npos) what.remove_prefix(end + 2);
  }
  return fmt::format("not valid JSON: {}", what);
}

nlohmann::json read_json_file(const std::string& path) {
  check_readable_file(path);
  std::ifstream in(path);
  if (!in) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  try {
    return nlohmann::json::parse(in, nullptr, true, /*ignore_comments=*/true);
  } catch (const nlohmann::json::exception& e) {
    throw Error(Errc::format, json_error_message(e)).with_file(path);
  }
}

namespace {
std::string_view type_name(const nlohmann::json& j) {
  if (j.is_object()) return "an object";
  if (j.is_array()) return "an array";
  if (j.is_string()) return "a string";
  if (j.is_boolean()) return "a boolean";
  if (j.is_number()) return "a number";
  return "null";
}
}  // namespace

std::string json_found(const nlohmann::json& v) {
  if (v.is_number()) return v.dump();
  return std::string(type_name(v));
}

JsonObjectReader::JsonObjectReader(const nlohmann::json& object, std::string file, std::string where)
    : object_(object), file_(std::move(file)), where_(std::move(where)) {
  if (!object_.is_object())
    throw Error(Errc::format, fmt::format("expected an object, found {}", type_name(object_)))
        .with_file(file_)
        .with_field(where_.empty() ? "(top level)" : where_);
}

std::string JsonObjectReader::path(std::string_view key) const {
  return where_.empty() ? std::string(key) : fmt::format("{}.{}", where_, key);
}

Error JsonObjectReader::error(std::string_view key, std::string_view message) const {
  Error e(Errc::format, std::string(message));
  e.with_file(file_).with_field(path(key));
  return e;
}

bool JsonObjectReader::has(std::string_view key) const { return object_.contains(key); }

const nlohmann::json* JsonObjectReader::get(std::string_view key) {
  read_.emplace(key);  // asked for, present or not: a known key
  auto it = object_.find(key);
  return it == object_.end() ? nullptr : &*it;
}

const nlohmann::json& JsonObjectReader::require(std::string_view key) {
  const nlohmann::json* j = get(key);
  if (!j) throw error(key, "missing required key");
  return *j;
}

double JsonObjectReader::number(std::string_view key, double fallback, double lo, double hi) {
  const nlohmann::json* j = get(key);
  if (!j) return fallback;
  if (!j->is_number()) throw error(key, fmt::format("expected a number, found {}", type_name(*j)));
  const double v = j->get<double>();
  if (!std::isfinite(v) || v < lo || v > hi) throw error(key, fmt::format("{} is outside [{}, {}]", v, lo, hi));
  return v;
}

double JsonObjectReader::required_number(std::string_view key, double lo, double hi) {
  require(key);
  return number(key, 0.0, lo, hi);
}

int64_t JsonObjectReader::integer(std::string_view key, int64_t fallback, int64_t lo, int64_t hi) {
  const nlohmann::json* j = get(key);
  if (!j) return fallback;
  if (!j->is_number_integer()) throw error(key, fmt::format("expected an integer, found {}", type_name(*j)));
  const auto v = json_exact<int64_t>(*j);  // not 2^64 - 1 wrapped to -1
  if (!v || *v < lo || *v > hi) throw error(key, fmt::format("{} is outside [{}, {}]", j->dump(), lo, hi));
  return *v;
}

bool JsonObjectReader::boolean(std::string_view key, bool fallback) {
  const nlohmann::json* j = get(key);
  if (!j) return fallback;
  if (!j->is_boolean()) throw error(key, fmt::format("expected true or false, found {}", type_name(*j)));
  return j->get<bool>();
}

std::string JsonObjectReader::string(std::string_view key, std::string_view fallback) {
  const nlohmann::json* j = get(key);
  if (!j) return std::string(fallback);
  if (!j->is_string()) throw error(key, fmt::format("expected a string, found {}", type_name(*j)));
  return j->get<std::string>();
}

std::string JsonObjectReader::string(std::string_view key) {
  require(key);
  return string(key, "");
}

std::string JsonObjectReader::choice(std::string_view key, std::string_view fallback,
                                     std::initializer_list<std::string_view> choices) {
  const std::string v = string(key, fallback);
  for (std::string_view c : choices)
    if (v == c) return v;
  std::string known;
  for (std::string_view c : choices) known += fmt::format("{}'{}'", known.empty() ? "" : ", ", c);
  throw error(key, fmt::format("'{}' is not one of {}", v, known));
}

Vec3d json_vec3(const JsonObjectReader& reader, std::string_view key, const nlohmann::json& j) {
  if (!j.is_array() || j.size() != 3) throw reader.error(key, "expected [x, y, z]");
  Vec3d v;
  for (int a = 0; a < 3; ++a) {
    if (!j[size_t(a)].is_number()) throw reader.error(key, "expected [x, y, z] of numbers");
    v[a] = j[size_t(a)].get<double>();
    if (!std::isfinite(v[a])) throw reader.error(key, "components must be finite");
  }
  return v;
}

Vec3d JsonObjectReader::vec3(std::string_view key, const Vec3d& fallback) {
  const nlohmann::json* j = get(key);
  return j ? json_vec3(*this, key, *j) : fallback;
}

Vec3d JsonObjectReader::vec3(std::string_view key) { return json_vec3(*this, key, require(key)); }

JsonObjectReader JsonObjectReader::object(std::string_view key) {
  return JsonObjectReader(require(key), file_, path(key));
}

void JsonObjectReader::finish(std::initializer_list<std::string_view> also_known) const {
  for (auto it = object_.begin(); it != object_.end(); ++it) {
    if (read_.count(it.key())) continue;
    bool known = false;
    for (std::string_view k : also_known) known |= (k == it.key());
    if (known) continue;
    std::string names;
    for (const auto& k : read_) names += fmt::format("{}'{}'", names.empty() ? "" : ", ", k);
    for (std::string_view k : also_known) names += fmt::format("{}'{}'", names.empty() ? "" : ", ", k);
    throw error(it.key(), fmt::format("unknown key{}", names.empty() ? std::string() : " (known keys: " + names + ")"));
  }
}

}  // namespace brickyard
