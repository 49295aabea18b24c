#include "cache/host_cache.h"

#include <algorithm>

#include <absl/container/flat_hash_map.h>
#include <fmt/format.h>

#include "core/error.h"
#include "core/units.h"

namespace brickyard {

struct alignas(64) HostCache::Shard {
  mutable std::mutex mutex;
  absl::flat_hash_map<uint64_t, PageBuffer> map;
  std::unique_ptr<Policy> policy;
  uint64_t budget = 0, bytes = 0, peak = 0;
  SlotCounters counters;
};

namespace {
uint64_t mix(uint64_t k) {
  k ^= k >> 31;
  k *= 0x9e3779b97f4a7c15ull;
  k ^= k >> 29;
  return k;
}
}  // namespace

HostCache::HostCache(uint64_t budget, uint64_t entry_bytes, const std::string& policy) : budget_(budget) {
  if (budget < entry_bytes) {
    const auto [given, page] = format_bytes_apart(budget, entry_bytes);
    throw Error(Errc::invalid_argument, fmt::format("the L2 budget of {} is smaller than one decoded page ({}){}", given, page,
                                                    budget == 0 ? ": the L2 holds at least one, it cannot be turned off" : ""))
        .with_field("l2_bytes");
  }
  uint32_t n = 1;
  while (n < 16 && budget / (uint64_t(n) * 2) >= 16 * entry_bytes) n *= 2;
  for (uint32_t s = 0; s < n; ++s) {
    auto shard = std::make_unique<Shard>();
    shard->budget = budget / n;
    shard->policy = make_policy(policy, shard->budget);
    if (shard->policy->needs_future())
      throw Error(Errc::invalid_argument, fmt::format("policy '{}' needs future accesses: use it with cachebench", policy))
          .with_field("l2_policy");
    shards_.push_back(std::move(shard));
  }
}

HostCache::~HostCache() = default;

HostCache::Shard& HostCache::shard_of(uint64_t key) const { return *shards_[mix(key) & (shards_.size() - 1)]; }

PageBuffer HostCache::find(uint64_t key) {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  auto it = s.map.find(key);
  if (it == s.map.end()) {
    ++s.counters.misses;
    return nullptr;
  }
  ++s.counters.hits;
  s.policy->on_hit(key, kNoNextAccess);
  return it->second;
}

bool HostCache::contains(uint64_t key) const {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  return s.map.contains(key);
}

bool HostCache::insert(uint64_t key, PageBuffer data) {
  Shard& s = shard_of(key);
  const uint64_t size = data->size();
  std::lock_guard lock(s.mutex);
  if (s.map.contains(key)) {
    ++s.counters.races;
    return true;
  }
  if (size > s.budget) return false;
  s.policy->on_miss(key);
  while (s.bytes + size > s.budget) {
    auto victim = s.policy->evict({});
    if (!victim) {
      ++s.counters.failed_evictions;
      return false;
    }
    auto it = s.map.find(*victim);
    s.bytes -= it->second->size();
    s.map.erase(it);
    ++s.counters.evictions;
  }
  s.map.emplace(key, std::move(data));
  s.policy->on_insert(key, size, kNoNextAccess);
  s.bytes += size;
  s.peak = std::max(s.peak, s.bytes);
  ++s.counters.inserts;
  return true;
}

uint64_t HostCache::resident_bytes() const {
  uint64_t n = 0;
  for (const auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    n += s->bytes;
  }
  return n;
}

uint64_t HostCache::peak_bytes() const {
  // Shard peaks may not coincide in time: their sum bounds the true peak from above.
  uint64_t n = 0;
  for (const auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    n += s->peak;
  }
  return n;
}

SlotCounters HostCache::counters() const {
  SlotCounters total;
  for (const auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    total += s->counters;
  }
  return total;
}

double HostCache::metadata_bytes_per_entry() const {
  std::lock_guard lock(shards_[0]->mutex);
  return shards_[0]->policy->metadata_bytes_per_entry() + 24.0 / 0.875 + 16.0;  // map slot + control block share
}

}  // namespace brickyard
