#pragma once
/// @file policy.h
/// @brief Replacement policies, pluggable by name, shared by the live cache levels (L1 slots,
/// L2 bytes) and the offline trace replay (`brickyard cachebench`).
///
/// A policy only orders resident entries; the cache owns the data, the pins and the
/// accounting. Sizes are in the cache's unit (1 per slot for L1, bytes for L2). The protocol,
/// for one access to id:
///   hit:  on_hit(id)
///   miss: on_miss(id); then evict() until the entry fits; then on_insert(id, size)
///   a resident id requested at a new size (replay): on_remove(id), then as a miss
/// evict() returns the victim and forgets it (ghost lists may remember its id). A policy is not
/// thread-safe: each cache shard owns one and calls it under the shard's lock.
///
/// Adding a policy: one file in cache/policies/ with a class deriving from Policy and a
/// factory, plus one line in the table in cache/policy.cpp.

#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace brickyard {

/// @brief Next access time (replay order) of an entry, for OPT; kNoNextAccess when it is
/// never accessed again or unknown.
inline constexpr uint64_t kNoNextAccess = std::numeric_limits<uint64_t>::max();

/// @brief Whether the cache lets an entry go (false while it is pinned). A plain function
/// pointer with a context: this sits in the eviction loop.
struct EvictableFn {
  bool (*fn)(const void* ctx, uint64_t id) = nullptr;
  const void* ctx = nullptr;
  bool operator()(uint64_t id) const { return fn == nullptr || fn(ctx, id); }
};

class Policy {
 public:
  virtual ~Policy() = default;
  virtual std::string_view name() const = 0;

  virtual void on_hit(uint64_t id, uint64_t next_access) = 0;
  /// @brief A miss on id is about to be served (before any eviction): ghost-list policies
  /// (ARC, S3-FIFO) adapt here.
  virtual void on_miss(uint64_t id) { (void)id; }
  virtual void on_insert(uint64_t id, uint64_t size, uint64_t next_access) = 0;
  /// @brief The cache dropped a resident entry itself (invalidation), not through evict().
  virtual void on_remove(uint64_t id) = 0;
  /// @brief Chooses and forgets a victim among the entries evictable() allows; nullopt when
  /// every resident entry is pinned (or protected, for lru-frame).
  virtual std::optional<uint64_t> evict(EvictableFn evictable) = 0;
  /// @brief A new frame begins (per-frame timestamps).
  virtual void on_frame(uint64_t frame) { (void)frame; }
  /// @brief Bookkeeping bytes per resident entry (lists, maps, ghosts), for reports.
  virtual double metadata_bytes_per_entry() const = 0;
  /// @brief Whether the policy needs next-access times (OPT: offline replay only).
  virtual bool needs_future() const { return false; }
};

struct PolicyInfo {
  std::string name;
  std::string description;
};

/// @brief Every policy, in a stable order.
std::vector<PolicyInfo> policy_catalog();
std::vector<std::string> policy_names();
/// @brief Creates a policy for a cache of `capacity` units. Unknown names are
/// Error(invalid_argument) listing the known ones.
std::unique_ptr<Policy> make_policy(std::string_view name, uint64_t capacity);

}  // namespace brickyard
