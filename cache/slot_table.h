#pragma once
/// @file slot_table.h
/// @brief Residency bookkeeping for a fixed number of slots (the L1 brick pool, the node
/// pool): which key occupies which slot, pins, and a replacement policy, sharded by key.
///
/// The hit path writes nothing shared except the slot's pin. Each shard keeps a fixed-size
/// open-addressing index (it never rehashes: the shard's slot count is fixed) that readers
/// probe optimistically under a sequence counter, as a seqlock. Hits reach the policy through
/// small per-thread rings that are drained under the shard's lock, when a ring fills or before
/// any eviction (lossy only if a drain is skipped while a ring wraps, as in Caffeine's read
/// buffers). Counters are striped per thread.
///
/// Concurrency contract:
/// - `mutex` of a shard guards its policy, free list, reserved set, and every write to its
///   index and to `keys_` of its slots. Writers make `seq` odd for the duration of a change.
/// - A reader pins a slot by incrementing its pin, then re-reads `seq`: if it changed, it
///   unpins and retries. A writer makes `seq` odd before it reads pins to choose a victim.
///   Both sides use sequentially consistent operations, so either the writer sees the pin or
///   the reader sees the change (the Dekker pattern): a pinned slot is never evicted.
/// - Slot data may be written only by the thread that reserved the slot, between reserve()
///   and publish(); readers reach it only through a pinned lookup.

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cache/policy.h"

namespace brickyard {

inline constexpr uint32_t kNoSlot = UINT32_MAX;

struct SlotCounters {
  uint64_t hits = 0, misses = 0, inserts = 0, evictions = 0, failed_evictions = 0, races = 0;
  SlotCounters& operator+=(const SlotCounters& o) {
    hits += o.hits;
    misses += o.misses;
    inserts += o.inserts;
    evictions += o.evictions;
    failed_evictions += o.failed_evictions;
    races += o.races;
    return *this;
  }
};

class SlotTable {
 public:
  /// @throws Error(invalid_argument) for no slots, an unknown policy or one that needs the future.
  SlotTable(uint32_t slots, const std::string& policy);
  ~SlotTable();

  uint32_t capacity() const { return slots_; }
  uint32_t shard_count() const { return uint32_t(shards_.size()); }

  /// @brief The slot holding `key`, pinned, or kNoSlot. Counts a hit or a miss.
  uint32_t lookup_and_pin(uint64_t key);
  /// @brief Whether `key` is resident (published), without pinning or counting.
  bool contains(uint64_t key) const;
  /// @brief Whether `key` is resident or reserved (being placed by another thread), under the
  /// shard's lock: a failed reserve() of a key for which this is false found nothing to evict.
  bool resident_or_reserved(uint64_t key) const;
  void unpin(uint32_t slot) { pins_[slot].value.fetch_sub(1, std::memory_order_release); }
  /// @brief A use without a pin (feedback): the policy hears of it like a hit.
  void touch(uint64_t key);

  /// @brief Reserves a slot for `key`, evicting an unpinned victim when none is free. kNoSlot
  /// when the key is resident or reserved already (a race, counted) or when nothing can be
  /// evicted (a failed eviction, counted). The evicted key is reported through `evicted`.
  uint32_t reserve(uint64_t key, std::optional<uint64_t>* evicted = nullptr);
  /// @brief Makes a reserved slot visible to lookups, pinned `pin` times.
  void publish(uint32_t slot, uint32_t pin = 0);
  /// @brief Gives a reserved slot back unpublished.
  void abandon(uint32_t slot);

  void frame(uint64_t frame);

  uint64_t key_of(uint32_t slot) const { return keys_[slot]; }
  uint32_t pins(uint32_t slot) const { return uint32_t(pins_[slot].value.load(std::memory_order_acquire)); }
  uint32_t resident() const;
  SlotCounters counters() const;
  double metadata_bytes_per_entry() const;

 private:
  struct Shard;
  struct alignas(64) Pin {
    std::atomic<int32_t> value{0};
  };
  struct alignas(64) CounterStripe {
    std::atomic<uint64_t> hits{0}, misses{0};
  };
  Shard& shard_of(uint64_t key) const;
  void drain_hits(Shard& s);  // caller holds s.mutex
  template <typename Ring>
  void drain_ring(Shard& s, Ring& ring);
  void record_hit(Shard& s, uint64_t key);

  uint32_t slots_;
  std::vector<std::unique_ptr<Shard>> shards_;
  std::unique_ptr<Pin[]> pins_;
  std::vector<uint64_t> keys_;  // written under the owning shard's mutex
  static constexpr size_t kCounterStripes = 16;
  mutable CounterStripe counters_[kCounterStripes];
};

}  // namespace brickyard
