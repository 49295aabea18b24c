#pragma once
// Parsers for command-line values, shared by the subcommands. Errors name the option.

#include <initializer_list>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/math.h"
#include "core/units.h"  // parse_bytes

namespace brickyard::cli {

/// @brief "N" -> (N, N, N); "X,Y,Z" or "XxYxZ" -> (X, Y, Z). Each at least 1.
Vec3s parse_size(std::string_view text, std::string_view option);
/// @brief "X,Y,Z" finite numbers.
Vec3d parse_vec3(std::string_view text, std::string_view option);
/// @brief One finite number; throws Error naming the option otherwise.
double parse_number(std::string_view text, std::string_view option);
/// @brief "LO,HI" finite numbers with LO <= HI.
std::pair<double, double> parse_range(std::string_view text, std::string_view option);
/// @brief "a,b,,c" -> {"a", "b", "", "c"}: every item between separators, empty ones kept.
std::vector<std::string> split_list(const std::string& text, char separator = ',');
/// @brief Exactly `count` comma-separated integers.
std::vector<int64_t> parse_int_list(std::string_view text, size_t count, std::string_view option);
/// @brief "name=value" with a finite numeric value.
std::pair<std::string, double> parse_assignment(std::string_view text, std::string_view option);

/// @brief Which option of a command sets a library setting: {"l1_bytes", "--l1"}.
using OptionNames = std::initializer_list<std::pair<std::string_view, std::string_view>>;

/// @brief Calls `run`; an Error about a setting that one of the command's options sets names
/// the option the user typed instead (`--l1`, not `l1_bytes`). Other errors pass unchanged.
template <typename Run>
decltype(auto) naming_options(OptionNames option_of, Run&& run) {
  try {
    return run();
  } catch (Error& e) {
    for (const auto& [setting, option] : option_of)
      if (e.field() == setting) {
        e.with_field(option);
        break;
      }
    throw;
  }
}

}  // namespace brickyard::cli
