#include "core/resources.h"

#include <sys/resource.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <vector>

#include <fmt/format.h>

#include "core/units.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

std::string read_small_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return {};
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::optional<uint64_t> parse_uint(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.remove_suffix(1);
  uint64_t v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || ec != std::errc() || ptr != text.data() + text.size()) return std::nullopt;
  return v;
}

/// The number after `key` at the start of a line ("MemAvailable:  123 kB", "inactive_file 456").
std::optional<uint64_t> line_value(std::string_view text, std::string_view key) {
  for (size_t at = 0; at < text.size();) {
    const size_t end = std::min(text.find('\n', at), text.size());
    std::string_view line = text.substr(at, end - at);
    at = end + 1;
    if (line.substr(0, key.size()) != key) continue;
    line.remove_prefix(key.size());
    if (!line.empty() && line.front() != ' ' && line.front() != '\t' && line.front() != ':') continue;  // a longer key
    if (!line.empty() && line.front() == ':') line.remove_prefix(1);
    while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
    const size_t digits = line.find_first_not_of("0123456789");
    const auto v = parse_uint(line.substr(0, digits));
    if (!v) return std::nullopt;
    const std::string_view unit = digits == std::string_view::npos ? std::string_view() : line.substr(digits);
    return unit.find("kB") != std::string_view::npos ? *v * 1024 : *v;
  }
  return std::nullopt;
}

std::optional<uint64_t> lowered_by_environment(std::optional<uint64_t> measured, const char* variable) {
  const char* text = std::getenv(variable);
  if (!text || !*text) return measured;
  const uint64_t cap = parse_bytes(text, variable, true);
  return measured ? std::min(*measured, cap) : cap;
}

void take_least(std::optional<uint64_t>& least, std::optional<uint64_t> v) {
  if (v) least = least ? std::min(*least, *v) : *v;
}

/// Headroom of this process's cgroup and of each cgroup above it: a limit anywhere up the tree
/// applies. Page cache counts towards a cgroup's usage, but the kernel reclaims it before it
/// refuses memory, so the inactive part is counted as free.
std::optional<uint64_t> cgroup_memory_headroom() {
  std::optional<uint64_t> least;
  const std::string self = read_small_file("/proc/self/cgroup");
  for (size_t at = 0; at < self.size();) {
    const size_t end = std::min(self.find('\n', at), self.size());
    const std::string line = self.substr(at, end - at);
    at = end + 1;
    const size_t c1 = line.find(':'), c2 = c1 == std::string::npos ? c1 : line.find(':', c1 + 1);
    if (c2 == std::string::npos) continue;
    const std::string controllers = line.substr(c1 + 1, c2 - c1 - 1);
    fs::path group = line.substr(c2 + 1);
    const bool v2 = line.substr(0, c1) == "0" && controllers.empty();
    const bool v1 = controllers.find("memory") != std::string::npos;
    if (!v2 && !v1) continue;
    const fs::path root = v2 ? "/sys/fs/cgroup" : "/sys/fs/cgroup/memory";
    for (fs::path g = group.relative_path();; g = g.parent_path()) {
      const fs::path dir = root / g;
      const std::string memory_stat = read_small_file((dir / "memory.stat").string());
      const uint64_t reclaimable = line_value(memory_stat, v2 ? "inactive_file" : "total_inactive_file").value_or(0);
      take_least(least, cgroup_headroom(read_small_file((dir / (v2 ? "memory.max" : "memory.limit_in_bytes")).string()),
                                        read_small_file((dir / (v2 ? "memory.current" : "memory.usage_in_bytes")).string()),
                                        reclaimable));
      if (g.empty()) break;
    }
  }
  return least;
}

std::optional<uint64_t> address_space_headroom() {
  rlimit limit{};
  if (::getrlimit(RLIMIT_AS, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return std::nullopt;
  const auto used = line_value(read_small_file("/proc/self/status"), "VmSize");
  if (!used) return std::nullopt;
  return uint64_t(limit.rlim_cur) > *used ? uint64_t(limit.rlim_cur) - *used : 0;
}

}  // namespace

uint64_t saturating_bytes(double bytes) {
  if (!(bytes > 0)) return 0;
  if (bytes >= 18446744073709549568.0) return std::numeric_limits<uint64_t>::max();  // the largest double below 2^64
  return uint64_t(std::ceil(bytes));
}

std::optional<uint64_t> meminfo_available(std::string_view meminfo) { return line_value(meminfo, "MemAvailable"); }

std::optional<uint64_t> cgroup_headroom(std::string_view limit, std::string_view usage, uint64_t reclaimable) {
  const auto max = parse_uint(limit);  // "max" (no limit) is not a number
  const auto used = parse_uint(usage);
  if (!max || !used) return std::nullopt;
  const uint64_t held = *used > reclaimable ? *used - reclaimable : 0;
  return *max > held ? *max - held : 0;
}

std::optional<uint64_t> free_disk(const std::string& path) {
  std::error_code ec;
  fs::path p = fs::absolute(path, ec);
  if (ec) p = path;
  while (!p.empty() && !fs::exists(p, ec) && p != p.parent_path()) p = p.parent_path();
  std::optional<uint64_t> measured;
  struct statvfs s {};
  if (!p.empty() && ::statvfs(p.c_str(), &s) == 0) measured = uint64_t(s.f_bavail) * uint64_t(s.f_frsize);
  return lowered_by_environment(measured, "BRICKYARD_AVAILABLE_DISK");
}

std::optional<uint64_t> available_memory() {
  std::optional<uint64_t> least = meminfo_available(read_small_file("/proc/meminfo"));
  take_least(least, cgroup_memory_headroom());
  take_least(least, address_space_headroom());
  return lowered_by_environment(least, "BRICKYARD_AVAILABLE_MEMORY");
}

std::optional<Error> resource_shortfall(const ResourceNeeds& needs, const ResourcesAvailable& available) {
  const bool disk_short = needs.disk.bytes > 0 && available.disk && needs.disk.bytes > *available.disk;
  const bool memory_short = needs.memory.bytes > 0 && available.memory && needs.memory.bytes > *available.memory;
  if (!disk_short && !memory_short) return std::nullopt;
  std::vector<std::string> shortfalls, lower;
  if (disk_short) {
    const auto [need, have] = format_bytes_apart(needs.disk.bytes, *available.disk);
    shortfalls.push_back(fmt::format("up to {} of disk{}, but {} is free there", need,
                                     needs.disk.why.empty() ? "" : " (" + needs.disk.why + ")", have));
    if (!needs.disk.lower.empty()) lower.push_back(needs.disk.lower);
  }
  if (memory_short) {
    const auto [need, have] = format_bytes_apart(needs.memory.bytes, *available.memory);
    shortfalls.push_back(fmt::format("about {} of memory{}, but {} is available", need,
                                     needs.memory.why.empty() ? "" : " (" + needs.memory.why + ")", have));
    if (!needs.memory.lower.empty() && (lower.empty() || lower.front() != needs.memory.lower))
      lower.push_back(needs.memory.lower);
  }
  std::string message = needs.task + " needs ";
  for (size_t i = 0; i < shortfalls.size(); ++i) message += (i ? ", and " : "") + shortfalls[i];
  for (const std::string& l : lower) message += "; " + l;
  Error e(Errc::resource, message);
  if (disk_short && !needs.disk_path.empty()) e.with_file(needs.disk_path);
  return e;
}

void check_resources(const ResourceNeeds& needs) {
  ResourcesAvailable available;
  if (needs.disk.bytes > 0) available.disk = free_disk(needs.disk_path);
  if (needs.memory.bytes > 0) available.memory = available_memory();
  if (auto e = resource_shortfall(needs, available)) throw *e;
}

}  // namespace brickyard
