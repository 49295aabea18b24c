#pragma once
// Parsers for command-line values, shared by the subcommands. Errors name the option.

#include <string>
#include <string_view>
#include <utility>

#include "core/math.h"

namespace brickyard::cli {

/// @brief "N" -> (N, N, N); "X,Y,Z" or "XxYxZ" -> (X, Y, Z). Each at least 1.
Vec3s parse_size(std::string_view text, std::string_view option);
/// @brief "name=value" with a finite numeric value.
std::pair<std::string, double> parse_assignment(std::string_view text, std::string_view option);

}  // namespace brickyard::cli
