#include "cache/slot_table.h"

#include <thread>

#include <absl/container/flat_hash_set.h>
#include <fmt/format.h>

#include "core/error.h"
#include "core/thread_stripe.h"

namespace brickyard {

namespace {
constexpr size_t kHitStripes = 4;
constexpr size_t kRing = 32;  // hits buffered per thread stripe and shard before a drain

uint64_t mix(uint64_t k) {
  k ^= k >> 33;
  k *= 0xff51afd7ed558ccdull;
  k ^= k >> 33;
  return k;
}
}  // namespace

struct alignas(64) SlotTable::Shard {
  std::mutex mutex;
  std::atomic<uint64_t> seq{0};
  // Index: keys stored as key + 1 (0 marks an empty cell), capacity a power of two >= 2x slots.
  std::unique_ptr<std::atomic<uint64_t>[]> cell_keys;
  std::unique_ptr<std::atomic<uint32_t>[]> cell_slots;
  uint64_t mask = 0;
  uint32_t published = 0;
  std::unique_ptr<Policy> policy;
  std::vector<uint32_t> free;
  absl::flat_hash_set<uint64_t> reserved;
  uint64_t inserts = 0, evictions = 0, failed_evictions = 0, races = 0;
  struct alignas(64) HitRing {  // written by one thread stripe, drained under the mutex
    std::atomic<uint64_t> next{0};
    std::atomic<uint64_t> keys[kRing];  // key + 1, 0 when drained
  };
  HitRing rings[kHitStripes];

  // --- index, readers (optimistic, no lock) ---
  std::optional<uint32_t> probe(uint64_t key) const {
    const uint64_t stored = key + 1;
    for (uint64_t pos = mix(key) & mask;; pos = (pos + 1) & mask) {
      const uint64_t k = cell_keys[pos].load(std::memory_order_acquire);
      if (k == 0) return std::nullopt;
      if (k == stored) return cell_slots[pos].load(std::memory_order_relaxed);
    }
  }
  // --- index, writers (mutex held, seq odd) ---
  void insert(uint64_t key, uint32_t slot) {
    uint64_t pos = mix(key) & mask;
    while (cell_keys[pos].load(std::memory_order_relaxed) != 0) pos = (pos + 1) & mask;
    cell_slots[pos].store(slot, std::memory_order_relaxed);
    cell_keys[pos].store(key + 1, std::memory_order_release);
    ++published;
  }
  void erase(uint64_t key) {
    uint64_t pos = mix(key) & mask;
    while (cell_keys[pos].load(std::memory_order_relaxed) != key + 1) pos = (pos + 1) & mask;
    // Backward-shift deletion keeps every probe chain unbroken without tombstones.
    uint64_t hole = pos;
    for (uint64_t next = (hole + 1) & mask;; next = (next + 1) & mask) {
      const uint64_t k = cell_keys[next].load(std::memory_order_relaxed);
      if (k == 0) break;
      const uint64_t home = mix(k - 1) & mask;
      // Move k into the hole when its home does not lie cyclically in (hole, next].
      const bool between = hole <= next ? (home > hole && home <= next) : (home > hole || home <= next);
      if (!between) {
        cell_slots[hole].store(cell_slots[next].load(std::memory_order_relaxed), std::memory_order_relaxed);
        cell_keys[hole].store(k, std::memory_order_release);
        hole = next;
      }
    }
    cell_keys[hole].store(0, std::memory_order_release);
    --published;
  }
  void begin_write() { seq.fetch_add(1, std::memory_order_seq_cst); }
  void end_write() { seq.fetch_add(1, std::memory_order_release); }
};

namespace {
uint32_t shards_for(uint32_t slots) {
  // At least 16 slots per shard, so that per-shard replacement stays close to global.
  uint32_t s = 1;
  while (s < 64 && s * 2 * 16 <= slots) s *= 2;
  return s;
}
}  // namespace

SlotTable::SlotTable(uint32_t slots, const std::string& policy) : slots_(slots), keys_(slots, 0) {
  if (slots == 0) throw Error(Errc::invalid_argument, "a pool needs at least one slot").with_field("slots");
  pins_.reset(new Pin[slots]);
  const uint32_t n = shards_for(slots);
  for (uint32_t s = 0; s < n; ++s) {
    auto shard = std::make_unique<Shard>();
    const uint32_t owned = slots / n + (s < slots % n ? 1 : 0);
    uint64_t cells = 4;
    while (cells < 2 * uint64_t(owned)) cells *= 2;
    shard->cell_keys.reset(new std::atomic<uint64_t>[cells]);
    shard->cell_slots.reset(new std::atomic<uint32_t>[cells]);
    for (uint64_t i = 0; i < cells; ++i) {
      shard->cell_keys[i].store(0, std::memory_order_relaxed);
      shard->cell_slots[i].store(0, std::memory_order_relaxed);
    }
    shard->mask = cells - 1;
    for (auto& ring : shard->rings)
      for (auto& k : ring.keys) k.store(0, std::memory_order_relaxed);
    shard->policy = make_policy(policy, owned);
    if (shard->policy->needs_future())
      throw Error(Errc::invalid_argument, fmt::format("policy '{}' needs future accesses: use it with cachebench", policy))
          .with_field("policy");
    shards_.push_back(std::move(shard));
  }
  for (uint32_t i = slots; i-- > 0;) shards_[i % n]->free.push_back(i);
}

SlotTable::~SlotTable() = default;

SlotTable::Shard& SlotTable::shard_of(uint64_t key) const { return *shards_[mix(key * 0x9e3779b97f4a7c15ull) & (shards_.size() - 1)]; }

void SlotTable::record_hit(Shard& s, uint64_t key) {
  auto& ring = s.rings[thread_stripe(kHitStripes)];
  const uint64_t i = ring.next.fetch_add(1, std::memory_order_relaxed);
  ring.keys[i % kRing].store(key + 1, std::memory_order_release);
  if (i % kRing == kRing - 1 && s.mutex.try_lock()) {
    // The policy's bookkeeping does not change the index: no seq bump needed.
    drain_ring(s, ring);
    s.mutex.unlock();
  }
}

template <typename Ring>
void SlotTable::drain_ring(Shard& s, Ring& ring) {
  for (auto& cell : ring.keys) {
    if (cell.load(std::memory_order_relaxed) == 0) continue;
    const uint64_t k = cell.exchange(0, std::memory_order_acquire);
    if (k != 0 && s.probe(k - 1)) s.policy->on_hit(k - 1, kNoNextAccess);
  }
}

void SlotTable::drain_hits(Shard& s) {
  for (auto& ring : s.rings) drain_ring(s, ring);
}

uint32_t SlotTable::lookup_and_pin(uint64_t key) {
  Shard& s = shard_of(key);
  auto& counters = counters_[thread_stripe(kCounterStripes)];
  for (int attempt = 0;; ++attempt) {
    const uint64_t before = s.seq.load(std::memory_order_acquire);
    if (before & 1) {
      if (attempt > 64) std::this_thread::yield();
      continue;  // a writer is changing the index
    }
    const std::optional<uint32_t> slot = s.probe(key);
    if (!slot) {
      if (s.seq.load(std::memory_order_acquire) != before) continue;
      counters.misses.fetch_add(1, std::memory_order_relaxed);
      return kNoSlot;
    }
    pins_[*slot].value.fetch_add(1, std::memory_order_seq_cst);
    if (s.seq.load(std::memory_order_seq_cst) != before) {
      pins_[*slot].value.fetch_sub(1, std::memory_order_release);
      continue;
    }
    counters.hits.fetch_add(1, std::memory_order_relaxed);
    record_hit(s, key);
    return *slot;
  }
}

bool SlotTable::contains(uint64_t key) const {
  Shard& s = shard_of(key);
  while (true) {
    const uint64_t before = s.seq.load(std::memory_order_acquire);
    if (before & 1) continue;
    const bool found = s.probe(key).has_value();
    if (s.seq.load(std::memory_order_acquire) == before) return found;
  }
}

bool SlotTable::resident_or_reserved(uint64_t key) const {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  return s.probe(key) || s.reserved.contains(key);
}

void SlotTable::touch(uint64_t key) { record_hit(shard_of(key), key); }

uint32_t SlotTable::reserve(uint64_t key, std::optional<uint64_t>* evicted) {
  Shard& s = shard_of(key);
  std::lock_guard lock(s.mutex);
  if (s.probe(key) || s.reserved.contains(key)) {
    ++s.races;
    return kNoSlot;
  }
  uint32_t slot = kNoSlot;
  s.begin_write();  // before reading any pin: see the contract in the header
  if (!s.free.empty()) {
    slot = s.free.back();
    s.free.pop_back();
  } else {
    drain_hits(s);  // the policy must know this frame's uses before it chooses
    struct Ctx {
      const SlotTable* table;
      const Shard* shard;
    } ctx{this, &s};
    EvictableFn evictable{[](const void* c, uint64_t id) {
                            const auto* x = static_cast<const Ctx*>(c);
                            const auto slot_of = x->shard->probe(id);
                            return slot_of && x->table->pins_[*slot_of].value.load(std::memory_order_seq_cst) == 0;
                          },
                          &ctx};
    s.policy->on_miss(key);
    auto victim = s.policy->evict(evictable);
    if (!victim) {
      ++s.failed_evictions;
      s.end_write();
      return kNoSlot;
    }
    slot = *s.probe(*victim);
    s.erase(*victim);
    ++s.evictions;
    if (evicted) *evicted = *victim;
  }
  keys_[slot] = key;
  s.reserved.insert(key);
  s.end_write();
  return slot;
}

void SlotTable::publish(uint32_t slot, uint32_t pin) {
  Shard& s = shard_of(keys_[slot]);
  std::lock_guard lock(s.mutex);
  s.begin_write();
  pins_[slot].value.store(int32_t(pin), std::memory_order_release);
  s.reserved.erase(keys_[slot]);
  s.insert(keys_[slot], slot);
  s.policy->on_insert(keys_[slot], 1, kNoNextAccess);
  ++s.inserts;
  s.end_write();
}

void SlotTable::abandon(uint32_t slot) {
  Shard& s = shard_of(keys_[slot]);
  std::lock_guard lock(s.mutex);
  s.reserved.erase(keys_[slot]);
  s.free.push_back(slot);
}

void SlotTable::frame(uint64_t frame) {
  for (auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    s->begin_write();
    drain_hits(*s);  // hits of the last frame count for it, not for the new one
    s->policy->on_frame(frame);
    s->end_write();
  }
}

uint32_t SlotTable::resident() const {
  uint32_t n = 0;
  for (const auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    n += s->published;
  }
  return n;
}

SlotCounters SlotTable::counters() const {
  SlotCounters total;
  for (const auto& c : counters_) {
    total.hits += c.hits.load(std::memory_order_relaxed);
    total.misses += c.misses.load(std::memory_order_relaxed);
  }
  for (const auto& s : shards_) {
    std::lock_guard lock(s->mutex);
    total.inserts += s->inserts;
    total.evictions += s->evictions;
    total.failed_evictions += s->failed_evictions;
    total.races += s->races;
  }
  return total;
}

double SlotTable::metadata_bytes_per_entry() const {
  std::lock_guard lock(shards_[0]->mutex);
  // Policy, two index cells per slot, the pin line and the key.
  return shards_[0]->policy->metadata_bytes_per_entry() + 2 * 12.0 + sizeof(Pin) + sizeof(uint64_t);
}

}  // namespace brickyard
