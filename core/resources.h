#pragma once
/// @file resources.h
/// @brief What the machine has free (disk at a path, memory for this process), and the check a
/// long command makes before it starts: what it will need against what is there, refused with a
/// message that names the need, what is free, and the option that lowers it.
///
/// The measurement and the decision are apart: resource_shortfall() is a pure function of the
/// numbers (tests give it their own), check_resources() measures and applies it. Two environment
/// variables lower what the measurement reports, never raise it: BRICKYARD_AVAILABLE_MEMORY and
/// BRICKYARD_AVAILABLE_DISK (byte counts such as 4GiB), for a machine shared with other work and
/// for tests that must not depend on the machine they run on.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "core/error.h"

namespace brickyard {

/// @brief Bytes of one resource a command will hold (memory) or write (disk) at most.
struct ResourceNeed {
  uint64_t bytes = 0;  ///< 0: nothing to check
  std::string why;     ///< what the bytes are, for the message: "34 slices of the finest level ..."
  std::string lower;   ///< what lowers the need: "a smaller --size or --brick-size"
};

struct ResourceNeeds {
  std::string task;       ///< who needs it: "import of 8192x8192x8192 u8"
  ResourceNeed memory;
  ResourceNeed disk;
  std::string disk_path;  ///< where the disk bytes go (it need not exist yet)
};

/// @brief What is free; nullopt where it could not be measured (that resource is not checked).
struct ResourcesAvailable {
  std::optional<uint64_t> memory;
  std::optional<uint64_t> disk;
};

/// @brief The error a command is refused with (Errc::resource, naming disk_path when the disk
/// is short), or nullopt when every need fits what is available.
std::optional<Error> resource_shortfall(const ResourceNeeds& needs, const ResourcesAvailable& available);

/// @brief Measures what `needs` asks about (free_disk(disk_path), available_memory()) and throws
/// resource_shortfall()'s error, if any.
void check_resources(const ResourceNeeds& needs);

/// @brief Bytes an unprivileged user may still write on the file system holding `path` (or, when
/// it does not exist yet, its nearest existing parent), lowered by BRICKYARD_AVAILABLE_DISK.
std::optional<uint64_t> free_disk(const std::string& path);

/// @brief Memory this process can still allocate: the least of the kernel's MemAvailable, the
/// cgroup's limit less its usage (cgroup v2 and v1) and RLIMIT_AS less the address space in use,
/// lowered by BRICKYARD_AVAILABLE_MEMORY.
std::optional<uint64_t> available_memory();

/// @brief MemAvailable of /proc/meminfo text, in bytes.
std::optional<uint64_t> meminfo_available(std::string_view meminfo);
/// @brief A cgroup limit file's content ("max" or a byte count) less the usage file's content,
/// of which `reclaimable` bytes (inactive page cache) count as free; nullopt for no limit or
/// text that is not a number.
std::optional<uint64_t> cgroup_headroom(std::string_view limit, std::string_view usage, uint64_t reclaimable = 0);

/// @brief A byte count in double precision clamped into uint64_t, for estimates whose products
/// may exceed 2^64 (a grid of 10^7 voxels a side).
uint64_t saturating_bytes(double bytes);

}  // namespace brickyard
