#pragma once
/// @file slot_table.h
/// @brief Residency bookkeeping for a fixed number of slots (the L1 brick pool, the node
/// pool): which key occupies which slot, pins, and a replacement policy, sharded by key.
///
/// Concurrency: keys map to one of S shards (S a power of two, at most 64). Slots are dealt
/// to shards round-robin, so each shard owns capacity/S slots and a policy of its own. A
/// shard's mutex guards its map, its free list, its policy, its counters and the `key`/`state`
/// of its slots; it is held for a lookup or a slot reservation, never while voxels are copied.
/// `pins` is atomic: taken under the shard lock (so an evictor holding the lock sees it) and
/// dropped without it (a pin only ever goes to zero outside the lock, which cannot un-see an
/// eviction decision). Data of a slot may be written only by the thread that reserved it,
/// between reserve() and publish(); readers reach it only through a pinned lookup.

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
  /// @throws Error(invalid_argument) for an unknown policy or a policy that needs the future.
  SlotTable(uint32_t slots, const std::string& policy);
  ~SlotTable();

  uint32_t capacity() const { return slots_; }
  uint32_t shard_count() const { return uint32_t(shards_.size()); }

  /// @brief The slot holding `key`, pinned, or kNoSlot. Counts a hit or a miss and tells
  /// the policy.
  uint32_t lookup_and_pin(uint64_t key);
  /// @brief Like lookup_and_pin but silent: no counters (for internal checks).
  bool contains(uint64_t key);
  void unpin(uint32_t slot) { pins_[slot].fetch_sub(1, std::memory_order_release); }
  /// @brief Marks a use without pinning (feedback): tells the policy, counts nothing.
  void touch(uint64_t key);

  /// @brief Reserves a slot for `key`, evicting an unpinned victim when none is free. Returns
  /// kNoSlot when the key is already resident or reserved (a race, counted) or when every
  /// slot of the shard is pinned or protected (a failed eviction, counted). The evicted key,
  /// if any, is reported through `evicted`.
  uint32_t reserve(uint64_t key, std::optional<uint64_t>* evicted = nullptr);
  /// @brief Makes a reserved slot visible to lookups (its data is complete), pinned `pin` times.
  void publish(uint32_t slot, uint32_t pin = 0);
  /// @brief Gives a reserved slot back unpublished (the load failed).
  void abandon(uint32_t slot);

  /// @brief New frame: tells every shard's policy.
  void frame(uint64_t frame);

  uint64_t key_of(uint32_t slot) const { return keys_[slot]; }
  uint32_t pins(uint32_t slot) const { return uint32_t(pins_[slot].load(std::memory_order_acquire)); }
  /// @brief Resident (published) slots right now.
  uint32_t resident() const;
  SlotCounters counters() const;
  double metadata_bytes_per_entry() const;

 private:
  struct Shard;
  Shard& shard_of(uint64_t key) const;

  uint32_t slots_;
  std::vector<std::unique_ptr<Shard>> shards_;
  std::unique_ptr<std::atomic<int32_t>[]> pins_;
  std::vector<uint64_t> keys_;  // guarded by the owning shard's mutex
};

}  // namespace brickyard
