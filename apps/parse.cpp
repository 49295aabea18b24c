#include "apps/parse.h"

#include <charconv>
#include <cctype>
#include <cmath>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard::cli {

Vec3s parse_size(std::string_view text, std::string_view option) {
  std::vector<int64_t> parts;
  size_t start = 0;
  while (true) {
    const size_t end = text.find_first_of(",x", start);
    const std::string_view part = text.substr(start, end == std::string_view::npos ? std::string_view::npos : end - start);
    int64_t v = 0;
    auto [ptr, ec] = std::from_chars(part.data(), part.data() + part.size(), v);
    if (part.empty() || ec != std::errc() || ptr != part.data() + part.size())
      throw Error(Errc::invalid_argument,
                  fmt::format("'{}' is not a size: expected N or NX,NY,NZ with positive integers", text))
          .with_field(option);
    if (v < 1)
      throw Error(Errc::invalid_argument, fmt::format("'{}': every dimension must be at least 1", text)).with_field(option);
    parts.push_back(v);
    if (end == std::string_view::npos) break;
    start = end + 1;
  }
  if (parts.size() == 1) return Vec3s(parts[0]);
  if (parts.size() == 3) return {parts[0], parts[1], parts[2]};
  throw Error(Errc::invalid_argument, fmt::format("'{}' has {} dimensions; give 1 or 3", text, parts.size()))
      .with_field(option);
}

namespace {
std::vector<double> parse_numbers(std::string_view text, std::string_view option, std::string_view what) {
  std::vector<double> out;
  size_t start = 0;
  while (true) {
    const size_t end = text.find(',', start);
    const std::string_view part = text.substr(start, end == std::string_view::npos ? std::string_view::npos : end - start);
    double v = 0;
    auto [ptr, ec] = std::from_chars(part.data(), part.data() + part.size(), v);
    if (part.empty() || ec != std::errc() || ptr != part.data() + part.size() || !std::isfinite(v))
      throw Error(Errc::invalid_argument, fmt::format("'{}' is not {}", text, what)).with_field(option);
    out.push_back(v);
    if (end == std::string_view::npos) break;
    start = end + 1;
  }
  return out;
}
}  // namespace

double parse_number(std::string_view text, std::string_view option) {
  const auto v = parse_numbers(text, option, "a number");
  if (v.size() != 1) throw Error(Errc::invalid_argument, fmt::format("'{}' is not a number", text)).with_field(option);
  return v[0];
}

Vec3d parse_vec3(std::string_view text, std::string_view option) {
  const auto v = parse_numbers(text, option, "X,Y,Z");
  if (v.size() != 3) throw Error(Errc::invalid_argument, fmt::format("'{}' is not X,Y,Z", text)).with_field(option);
  return {v[0], v[1], v[2]};
}

std::pair<double, double> parse_range(std::string_view text, std::string_view option) {
  const auto v = parse_numbers(text, option, "LO,HI");
  if (v.size() != 2 || v[0] > v[1])
    throw Error(Errc::invalid_argument, fmt::format("'{}' is not LO,HI with LO <= HI", text)).with_field(option);
  return {v[0], v[1]};
}

std::vector<std::string> split_list(const std::string& s, char sep) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    const size_t end = s.find(sep, start);
    out.push_back(s.substr(start, end == std::string::npos ? std::string::npos : end - start));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return out;
}

std::vector<int64_t> parse_int_list(std::string_view text, size_t count, std::string_view option) {
  const auto v = parse_numbers(text, option, fmt::format("{} integers", count));
  std::vector<int64_t> out;
  for (double d : v) {
    if (d != std::floor(d))
      throw Error(Errc::invalid_argument, fmt::format("'{}' holds a non-integer", text)).with_field(option);
    out.push_back(int64_t(d));
  }
  if (out.size() != count)
    throw Error(Errc::invalid_argument, fmt::format("'{}' has {} numbers; give {}", text, out.size(), count)).with_field(option);
  return out;
}

std::pair<std::string, double> parse_assignment(std::string_view text, std::string_view option) {
  const size_t eq = text.find('=');
  if (eq == std::string_view::npos || eq == 0)
    throw Error(Errc::invalid_argument, fmt::format("'{}' is not NAME=VALUE", text)).with_field(option);
  const std::string_view value = text.substr(eq + 1);
  double v = 0;
  auto [ptr, ec] = std::from_chars(value.data(), value.data() + value.size(), v);
  if (value.empty() || ec != std::errc() || ptr != value.data() + value.size() || !std::isfinite(v))
    throw Error(Errc::invalid_argument, fmt::format("'{}': '{}' is not a finite number", text, value)).with_field(option);
  return {std::string(text.substr(0, eq)), v};
}

}  // namespace brickyard::cli
