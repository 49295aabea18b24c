#include "core/units.h"

#include <cmath>

#include <fmt/format.h>

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

}  // namespace brickyard
