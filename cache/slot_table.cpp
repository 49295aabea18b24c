#include "cache/slot_table.h"

#include <absl/container/flat_hash_map.h>
#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

struct alignas(64) SlotTable::Shard {
  mutable std::mutex mutex;
  absl::flat_hash_map<uint64_t, uint32_t> map;  // published and reserved keys
  std::vector<uint32_t> free;
  std::unique_ptr<Policy> policy;
  SlotCounters counters;
  uint32_t reserved = 0;
};

namespace {
uint32_t shards_for(uint32_t slots) {
  // At least 16 slots per shard, so that per-shard replacement stays close to global.
  uint32_t s = 1;
  while (s < 64 && s * 2 * 16 <= slots) s *= 2;
  return s;
}
uint64_t mix(uint64_t k) {
  k ^= k >> 33;
  k *= 0xff51afd7ed558ccdull;
  k ^= k >> 33;
  return k;
}
}  // namespace

SlotTable::SlotTable(uint32_t slots, const std::string& policy)
    : slots_(slots), pins_(new std::atomic<int32_t>[slots]), keys_(slots, 0) {
  if (slots == 0) throw Error(Errc::invalid_argument, "a pool needs at least one slot").with_field("slots");
  const uint32_t n = shards_for(slots);
  for (uint32_t s = 0; s < n; ++s) {
    auto shard = std::make_unique<Shard>();
    const uint32_t owned = slots / n + (s < slots % n ? 1 : 0);
    shard->policy = make_policy(policy, owned);
    if (shard->policy->needs_future())
      throw Error(Errc::invalid_argument, fmt::format("policy '{}' needs future accesses: use it with cachebench", policy))
          .with_field("policy");
    shards_.push_back(std::move(shard));
  }
  for (uint32_t i = slots; i-- > 0;) {
    pins_[i].store(0, std::memory_order_relaxed);
    shards_[i % n]->free.push_back(i);
  }
}

SlotTable::~SlotTable() = default;

SlotTable::Shard& SlotTable::shard_of(uint64_t key) const { return *shards_[mix(key) & (shards_.size() - 1)]; }

uint32_t SlotTable::lookup_and_pin(uint64_t key) {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  auto it = s.map.find(key);
  if (it == s.map.end() || pins_[it->second].load(std::memory_order_relaxed) < 0) {  // absent or still loading
    ++s.counters.misses;
    return kNoSlot;
  }
  pins_[it->second].fetch_add(1, std::memory_order_acquire);
  s.policy->on_hit(key, kNoNextAccess);
  ++s.counters.hits;
  return it->second;
}

bool SlotTable::contains(uint64_t key) {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  return s.map.contains(key);
}

void SlotTable::touch(uint64_t key) {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  if (s.map.contains(key)) s.policy->on_hit(key, kNoNextAccess);
}

uint32_t SlotTable::reserve(uint64_t key, std::optional<uint64_t>* evicted) {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  if (s.map.contains(key)) {
    ++s.counters.races;
    return kNoSlot;
  }
  uint32_t slot = kNoSlot;
  if (!s.free.empty()) {
    slot = s.free.back();
    s.free.pop_back();
  } else {
    struct Ctx {
      const SlotTable* table;
      const Shard* shard;
    } ctx{this, &s};
    // Evictable: published (pins >= 0) and unpinned. Reserved slots carry pins = -1.
    EvictableFn evictable{[](const void* c, uint64_t id) {
                            const auto* x = static_cast<const Ctx*>(c);
                            const uint32_t i = x->shard->map.at(id);
                            return x->table->pins_[i].load(std::memory_order_acquire) == 0;
                          },
                          &ctx};
    s.policy->on_miss(key);
    auto victim = s.policy->evict(evictable);
    if (!victim) {
      ++s.counters.failed_evictions;
      return kNoSlot;
    }
    auto it = s.map.find(*victim);
    slot = it->second;
    s.map.erase(it);
    ++s.counters.evictions;
    if (evicted) *evicted = *victim;
  }
  keys_[slot] = key;
  pins_[slot].store(-1, std::memory_order_relaxed);  // reserved: invisible to lookups, not evictable
  s.map[key] = slot;
  ++s.reserved;
  return slot;
}

void SlotTable::publish(uint32_t slot, uint32_t pin) {
  Shard& s = shard_of(keys_[slot]);
  std::lock_guard lock(s.mutex);
  pins_[slot].store(int32_t(pin), std::memory_order_release);
  s.policy->on_insert(keys_[slot], 1, kNoNextAccess);
  ++s.counters.inserts;
  --s.reserved;
}

void SlotTable::abandon(uint32_t slot) {
  Shard& s = shard_of(keys_[slot]);
  std::lock_guard lock(s.mutex);
  s.map.erase(keys_[slot]);
  pins_[slot].store(0, std::memory_order_relaxed);
  s.free.push_back(slot);
  --s.reserved;
}

void SlotTable::frame(uint64_t frame) {
  for (auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    s->policy->on_frame(frame);
  }
}

uint32_t SlotTable::resident() const {
  uint32_t n = 0;
  for (const auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    n += uint32_t(s->map.size()) - s->reserved;
  }
  return n;
}

SlotCounters SlotTable::counters() const {
  SlotCounters total;
  for (const auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    total += s->counters;
  }
  return total;
}

double SlotTable::metadata_bytes_per_entry() const {
  std::lock_guard lock(shards_[0]->mutex);
  return shards_[0]->policy->metadata_bytes_per_entry() + 16.0 / 0.875 + sizeof(int32_t) + sizeof(uint64_t);
}

}  // namespace brickyard
