#pragma once
/// @file replay.h
/// @brief Offline replay of a trace against one policy and capacity: the cache-policy
/// benchmark behind `brickyard cachebench`.
///
/// Demand and blocking accesses are the requests: hits and misses (and bytes) count them. A
/// prefetch fill inserts a brick without counting a request; a demand hit on a prefetched,
/// not yet used brick makes that prefetch useful. An object larger than the whole cache is a
/// miss that bypasses it.
///
/// Sizes that change (text and oracleGeneral traces may give one object several): an object's
/// size is its latest, as in libCacheSim. A request at another size than the cached copy's is a
/// miss; the copy is dropped (its bytes freed, the policy's on_remove()) and the object
/// inserted again at the new size, so no request is ever served by a copy of another size. A
/// fill at another size replaces the copy the same way. OPT's future (next_demand_access)
/// follows the same rule: a copy whose next access is at another size is never used again.
/// With sizes that vary, OPT (Belady) is a strong heuristic rather than a proven bound.

#include <cstdint>
#include <string>
#include <vector>

#include "cache/trace.h"

namespace brickyard {

struct ReplayResult {
  std::string policy;
  uint64_t capacity = 0;  ///< bytes
  uint64_t requests = 0, misses = 0;
  uint64_t bytes_requested = 0, bytes_missed = 0;
  uint64_t evictions = 0;
  uint64_t failed_evictions = 0;  ///< the policy found nothing it could evict (lru-frame's protected frame)
  // Prefetch, from prefetch-request and prefetch-fill records:
  uint64_t prefetches = 0;        ///< fills of bricks that were not resident
  uint64_t prefetches_used = 0;   ///< ... later hit by a demand access while still resident
  uint64_t prefetch_wasted_bytes = 0;  ///< ... evicted before any demand access used them
  uint64_t late_prefetches = 0;   ///< demand misses on a brick whose prefetch was requested but not yet filled
  uint64_t demand_hits_on_prefetched = 0;
  std::vector<double> miss_ratio_windows;  ///< per window of frames (or of 1% of the requests)
  double metadata_bytes_per_entry = 0;
  double seconds = 0;

  double miss_ratio() const { return requests ? double(misses) / double(requests) : 0.0; }
  double byte_miss_ratio() const { return bytes_requested ? double(bytes_missed) / double(bytes_requested) : 0.0; }
  double requests_per_second() const { return seconds > 0 ? double(requests) / seconds : 0.0; }
  /// Fraction of filled prefetches later used.
  double prefetch_accuracy() const { return prefetches ? double(prefetches_used) / double(prefetches) : 0.0; }
  /// Fraction of the would-be misses that prefetching turned into hits.
  double prefetch_coverage() const {
    const double would_miss = double(misses + demand_hits_on_prefetched);
    return would_miss > 0 ? double(demand_hits_on_prefetched) / would_miss : 0.0;
  }
};

/// @brief Replays `trace` through `policy` with `capacity` bytes. `next` (from
/// next_demand_access) is needed by OPT and may be empty for other policies.
ReplayResult replay(const Trace& trace, const std::vector<uint64_t>& next, const std::string& policy, uint64_t capacity,
                    uint32_t window_frames = 0);

}  // namespace brickyard
