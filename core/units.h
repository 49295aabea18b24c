#pragma once
/// @file units.h
/// @brief Human-readable numbers for progress lines, reports and error messages.

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>

namespace brickyard {

/// @brief 1234567 -> "1.23M" (SI prefixes k, M, G, T, P; three significant digits).
std::string format_count(double n);
/// @brief Bytes with binary prefixes: 1536 -> "1.50 KiB".
std::string format_bytes(double bytes);
/// @brief Two byte counts for a message that compares them: format_bytes() of each, or both
/// exact ("157215 bytes", "157216 bytes") where rounding would print two different counts alike.
std::pair<std::string, std::string> format_bytes_apart(uint64_t a, uint64_t b);
/// @brief Seconds as "12.3 ms", "4.56 s", "3:07" or "1:02:03".
std::string format_duration(double seconds);
/// @brief "64MiB", "2GiB", "1048576", "512KiB" (also KB/MB/GB as binary units) as bytes;
/// Error(invalid_argument) naming `field` otherwise. A size of 0 is refused unless
/// `allow_zero` (for a budget whose user, knowing its minimum, says what it holds at least).
uint64_t parse_bytes(std::string_view text, std::string_view field, bool allow_zero = false);

}  // namespace brickyard
