#pragma once
/// @file host_cache.h
/// @brief L2: decoded pages of one record kind in host memory under a byte budget, with a
/// replacement policy.
///
/// Sharded like the slot table: each of S shards owns budget / S bytes, its map, its policy
/// and its counters, all under its mutex. Buffers are shared_ptr so that a copy into the L1
/// pool may finish after L2 has evicted the brick; the budget counts resident buffers, which
/// never exceed it. The page cache keeps one per record kind.

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cache/slot_table.h"

namespace brickyard {

using PageBuffer = std::shared_ptr<const std::vector<std::byte>>;

class HostCache {
 public:
  /// @param budget       bytes for all resident buffers
  /// @param entry_bytes  size of one decoded page (budgets smaller than one are an error)
  HostCache(uint64_t budget, uint64_t entry_bytes, const std::string& policy);
  ~HostCache();

  /// @brief The buffer for key, or null; counts a hit or miss.
  PageBuffer find(uint64_t key);
  /// @brief Inserts (evicting as needed); false when it cannot be made to fit.
  bool insert(uint64_t key, PageBuffer data);
  bool contains(uint64_t key) const;

  uint64_t budget() const { return budget_; }
  uint64_t resident_bytes() const;
  uint64_t peak_bytes() const;
  SlotCounters counters() const;
  double metadata_bytes_per_entry() const;

 private:
  struct Shard;
  Shard& shard_of(uint64_t key) const;
  uint64_t budget_;
  std::vector<std::unique_ptr<Shard>> shards_;
};

}  // namespace brickyard
