#include "core/units.h"

#include <cctype>
#include <charconv>
#include <cmath>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

std::string format_count(double n) {
  static const char* prefixes[] = {"", "k", "M", "G", "T", "P", "E"};
  int i = 0;
  double v = n;
  while (std::fabs(v) >= 999.5 && i < 6) { v /= 1000.0; ++i; }
  if (i == 0) return fmt::format("{:.0f}", v);
  return fmt::format("{:.3g}{}", v, prefixes[i]);
}

std::string format_bytes(double bytes) {
  static const char* prefixes[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  int i = 0;
  double v = bytes;
  while (std::fabs(v) >= 1023.5 && i < 6) { v /= 1024.0; ++i; }
  if (i == 0) return fmt::format("{:.0f} B", v);
  return fmt::format("{:.3g} {}", v, prefixes[i]);
}

std::pair<std::string, std::string> format_bytes_apart(uint64_t a, uint64_t b) {
  std::string fa = format_bytes(double(a)), fb = format_bytes(double(b));
  if (a != b && fa == fb) fa = fmt::format("{} bytes", a), fb = fmt::format("{} bytes", b);
  return {fa, fb};
}

std::string format_duration(double seconds) {
  if (!std::isfinite(seconds)) return "?";
  if (seconds < 1e-3) return fmt::format("{:.1f} us", seconds * 1e6);
  if (seconds < 1.0) return fmt::format("{:.1f} ms", seconds * 1e3);
  if (seconds < 60.0) return fmt::format("{:.2f} s", seconds);
  auto total = static_cast<int64_t>(std::llround(seconds));
  int64_t h = total / 3600, m = (total / 60) % 60, s = total % 60;
  if (h > 0) return fmt::format("{}:{:02}:{:02}", h, m, s);
  return fmt::format("{}:{:02}", m, s);
}

uint64_t parse_bytes(std::string_view text, std::string_view field, bool allow_zero) {
  size_t digits = 0;
  while (digits < text.size() && (std::isdigit(static_cast<unsigned char>(text[digits])) || text[digits] == '.')) ++digits;
  double v = 0;
  auto [ptr, ec] = std::from_chars(text.data(), text.data() + digits, v);
  const std::string_view unit = text.substr(digits);
  double scale = 0;
  if (unit.empty() || unit == "B") scale = 1;
  else if (unit == "KiB" || unit == "KB" || unit == "K") scale = 1024.0;
  else if (unit == "MiB" || unit == "MB" || unit == "M") scale = 1024.0 * 1024;
  else if (unit == "GiB" || unit == "GB" || unit == "G") scale = 1024.0 * 1024 * 1024;
  else if (unit == "TiB" || unit == "TB" || unit == "T") scale = 1024.0 * 1024 * 1024 * 1024;
  if (digits == 0 || ec != std::errc() || ptr != text.data() + digits || scale == 0 || (v <= 0 && !allow_zero))
    throw Error(Errc::invalid_argument, fmt::format("'{}' is not a size such as 64MiB", text)).with_field(field);
  return uint64_t(v * scale);
}

}  // namespace brickyard
