#include "cache/replay.h"

#include <algorithm>

#include <absl/container/flat_hash_map.h>
#include <absl/container/flat_hash_set.h>
#include <fmt/format.h>

#include "cache/policy.h"
#include "core/error.h"
#include "core/timing.h"

namespace brickyard {

ReplayResult replay(const Trace& trace, const std::vector<uint64_t>& next, const std::string& policy_name,
                    uint64_t capacity, uint32_t window_frames) {
  auto policy = make_policy(policy_name, capacity);
  if (policy->needs_future() && next.size() != trace.records.size())
    throw Error(Errc::internal, fmt::format("{} needs next-access times", policy_name));
  ReplayResult r;
  r.policy = policy_name;
  r.capacity = capacity;

  struct Resident {
    uint32_t size;
    bool prefetched_unused;
  };
  absl::flat_hash_map<uint64_t, Resident> resident;
  absl::flat_hash_set<uint64_t> requested;  // prefetches asked for and not yet filled
  resident.reserve(1024);
  uint64_t used = 0;

  // Windows of frames when the trace has frames, else of 1% of the records.
  const bool by_frame = trace.frames() > 1;
  const uint64_t window = by_frame ? std::max<uint32_t>(1, window_frames ? window_frames : std::max<uint32_t>(1, trace.frames() / 100))
                                   : std::max<uint64_t>(1, trace.records.size() / 100);
  uint64_t window_requests = 0, window_misses = 0, window_index = 0;
  auto close_window = [&] {
    if (window_requests) r.miss_ratio_windows.push_back(double(window_misses) / double(window_requests));
    window_requests = window_misses = 0;
  };

  // An object's size is its latest: a resident copy of another size is stale. It is dropped
  // (its bytes freed, the policy told) and the access served as a miss at the new size.
  auto drop_stale = [&](decltype(resident)::iterator it) {
    policy->on_remove(it->first);
    used -= it->second.size;
    if (it->second.prefetched_unused) r.prefetch_wasted_bytes += it->second.size;
    resident.erase(it);
  };

  // Frees room for `size`; false when the policy cannot evict enough.
  auto make_room = [&](uint64_t size) {
    while (used + size > capacity) {
      auto victim = policy->evict({});
      if (!victim) {
        ++r.failed_evictions;
        return false;
      }
      auto it = resident.find(*victim);
      used -= it->second.size;
      if (it->second.prefetched_unused) r.prefetch_wasted_bytes += it->second.size;
      resident.erase(it);
      ++r.evictions;
    }
    return true;
  };

  // Objects are (record kind, key) pairs: a trace of several kinds replays dense ids.
  const std::vector<uint64_t> ids = object_ids(trace);
  uint32_t last_frame = UINT32_MAX;
  Stopwatch watch;
  for (size_t i = 0; i < trace.records.size(); ++i) {
    const TraceRecord& record = trace.records[i];
    struct {
      uint64_t key;
      uint32_t frame, size;
      AccessKind kind;
    } const a{ids[i], record.frame, record.size, record.kind};
    const uint64_t next_access = next.empty() ? kNoNextAccess : next[i];
    if (a.frame != last_frame) {
      policy->on_frame(a.frame);
      last_frame = a.frame;
    }
    const uint64_t w = by_frame ? a.frame / window : i / window;
    if (w != window_index) {
      close_window();
      window_index = w;
    }
    switch (a.kind) {
      case AccessKind::prefetch_request:
        if (auto it = resident.find(a.key); it == resident.end() || it->second.size != a.size) requested.insert(a.key);
        continue;
      case AccessKind::prefetch_fill: {
        requested.erase(a.key);
        if (auto it = resident.find(a.key); it != resident.end()) {
          if (it->second.size == a.size) continue;
          drop_stale(it);
        }
        if (a.size > capacity) continue;
        policy->on_miss(a.key);
        if (!make_room(a.size)) continue;
        policy->on_insert(a.key, a.size, next_access);
        resident[a.key] = {a.size, true};
        used += a.size;
        ++r.prefetches;
        continue;
      }
      case AccessKind::demand:
      case AccessKind::blocking: break;
    }
    ++r.requests;
    ++window_requests;
    r.bytes_requested += a.size;
    auto it = resident.find(a.key);
    if (it != resident.end() && it->second.size == a.size) {
      if (it->second.prefetched_unused) {
        it->second.prefetched_unused = false;
        ++r.prefetches_used;
        ++r.demand_hits_on_prefetched;
      }
      policy->on_hit(a.key, next_access);
      continue;
    }
    ++r.misses;
    ++window_misses;
    r.bytes_missed += a.size;
    if (it != resident.end()) drop_stale(it);  // even when the new size bypasses the cache
    if (requested.erase(a.key)) ++r.late_prefetches;
    if (a.size > capacity) continue;  // would not fit even alone: bypass
    policy->on_miss(a.key);
    if (!make_room(a.size)) continue;
    policy->on_insert(a.key, a.size, next_access);
    resident[a.key] = {a.size, false};
    used += a.size;
  }
  r.seconds = watch.seconds();
  close_window();
  r.metadata_bytes_per_entry = policy->metadata_bytes_per_entry();
  return r;
}

}  // namespace brickyard
