#pragma once
/// @file brick_cache.h
/// @brief The cache every renderer reaches data through: L1, a fixed pool of decoded-brick
/// slots that renderers sample from; L2, decoded bricks in host memory under a byte budget;
/// L3, the store's compressed records.
///
/// Two ways in. A GPU-style renderer calls lookup() from its render threads: a hit is a pinned
/// handle, a miss is recorded as a request that worker threads serve asynchronously (L2, else
/// read and decode from L3), uploading into the pool within a per-frame budget; frame_begin()
/// and frame_end() bracket each frame. A CPU-style tool calls fetch(), which blocks (a stall)
/// until the brick is resident. Constant nodes never occupy a slot: their handle carries the
/// value.
///
/// Thread safety: every member may be called from any thread, except that frame_begin() and
/// frame_end() must not overlap each other. lookup(), fetch(), request() and the marks take
/// only per-shard or per-stripe locks. Handles must be released before the cache is destroyed.
/// Requests are data (STYLE.md 7): render threads append them to striped per-frame lists that
/// the loader drains, and frame_requests() shows exactly what the last frame asked for.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cache/host_cache.h"
#include "cache/slot_table.h"
#include "cache/trace.h"
#include "core/brick_key.h"
#include "storage/brick_store.h"

namespace brickyard {

struct CacheConfig {
  uint32_t l1_slots = 0;                      ///< L1 pool slots; 0: as many as fit in l1_bytes
  uint64_t l1_bytes = uint64_t(256) << 20;    ///< used when l1_slots is 0
  uint64_t l2_bytes = uint64_t(1) << 30;
  std::string l1_policy = "lru";
  std::string l2_policy = "lru";
  int loader_threads = 2;
  uint32_t upload_bricks_per_frame = 0;  ///< 0: unlimited
  uint64_t upload_bytes_per_frame = 0;   ///< 0: unlimited
  std::string trace_path;                ///< record every access to this file (brickyard format)
  /// The part of the L1 budget that a back end's own brick pool holds beside this cache's L1
  /// (share_l1_budget); 0: none, the cache's L1 is the whole budget.
  uint64_t backend_pool_bytes = 0;
};

class BrickCache;

/// @brief A brick as a renderer sees it. Resident handles pin their slot until released.
class BrickHandle {
 public:
  enum class State : uint8_t { miss, resident, constant, failed };

  BrickHandle() = default;
  BrickHandle(BrickHandle&& o) noexcept { *this = std::move(o); }
  BrickHandle& operator=(BrickHandle&& o) noexcept;
  BrickHandle(const BrickHandle&) = delete;
  BrickHandle& operator=(const BrickHandle&) = delete;
  ~BrickHandle() { release(); }

  State state() const { return state_; }
  /// @brief Whether the voxels (or the constant value) are available.
  bool ready() const { return state_ == State::resident || state_ == State::constant; }
  bool resident() const { return state_ == State::resident; }
  bool constant() const { return state_ == State::constant; }
  bool failed() const { return state_ == State::failed; }

  const BrickKey& key() const { return key_; }
  int level() const { return int(key_.level); }
  /// @brief Pool slot (kNoSlot for constant nodes and for blocking fetches that found the pool
  /// pinned full and hold a private copy instead).
  uint32_t slot() const { return slot_; }
  /// @brief Decoded voxels with aprons, (M + 2A)^3, x fastest.
  const std::byte* bytes() const { return data_; }
  template <typename T>
  const T* voxels() const { return reinterpret_cast<const T*>(data_); }
  /// @brief The node's value range (its trilinear cells) and, for constant nodes, the value.
  float min() const { return min_; }
  float max() const { return max_; }
  float constant_value() const { return constant_; }
  /// @brief Why a failed handle failed (corrupt brick, key outside the store).
  const std::string& error() const { return error_; }

  void release();

 private:
  friend class BrickCache;
  BrickCache* cache_ = nullptr;
  State state_ = State::miss;
  BrickKey key_{};
  uint32_t slot_ = kNoSlot;
  const std::byte* data_ = nullptr;
  BrickBuffer owned_;  // a private copy when the pool had no free slot
  float min_ = 0, max_ = 0, constant_ = 0;
  std::string error_;
};

struct CacheLevelStats {
  uint64_t hits = 0, misses = 0, inserts = 0, evictions = 0, failed_evictions = 0;
  uint64_t resident = 0, capacity = 0;  ///< slots (L1), bytes (L2), records (L3)
  double metadata_bytes_per_entry = 0;
};

struct CacheStats {
  CacheLevelStats l1, l2, l3;
  uint64_t l1_pool_bytes = 0;   ///< the pool's fixed allocation
  uint64_t l2_peak_bytes = 0;   ///< never above the L2 budget
  uint64_t l3_bytes_read = 0;   ///< compressed record bytes read from the store
  uint64_t l3_bytes_decoded = 0;
  double l3_decode_seconds = 0;
  uint64_t constant_hits = 0;
  uint64_t requests = 0, merged_requests = 0, dropped_requests = 0, queue_length = 0;
  uint64_t uploads = 0, deferred_uploads = 0;
  uint64_t stalls = 0;          ///< blocking fetches that had to wait for a load
  uint64_t failed_keys = 0;     ///< bricks that failed to load (each counted once, never retried)
  double latency_p50_ms = 0, latency_p99_ms = 0;  ///< request to resident in L1
  uint64_t frames = 0;
  std::string to_json() const;
};

/// @brief What one frame did, returned by frame_end().
struct FrameReport {
  uint64_t frame = 0;
  uint64_t requests = 0;         ///< distinct requests made during the frame
  uint64_t dropped = 0;          ///< pending requests not renewed this frame, dropped
  uint64_t uploads = 0;          ///< bricks uploaded into L1 during the frame
  uint64_t upload_bytes = 0;
  uint64_t lookups = 0, hits = 0;
};

struct BrickRequest {
  BrickKey key;
  float priority = 0;
};

class BrickCache {
 public:
  /// @throws Error(invalid_argument) for budgets smaller than one brick, unknown policies.
  BrickCache(const BrickStore& store, const CacheConfig& config);
  /// @brief Stops the loader (requests in flight finish or are dropped, nothing half-inserted)
  /// and writes the trace, if one was recorded.
  ~BrickCache();

  const BrickStore& store() const { return store_; }
  const BrickFormat& format() const { return store_.format(); }
  const StoreLayout& layout() const { return store_.layout(); }
  const NodeTable& nodes() const { return store_.nodes(); }
  uint32_t pool_slots() const { return slots_.capacity(); }
  const CacheConfig& config() const { return config_; }
  /// @brief Slot data in the pool (for renderers that address the pool directly).
  const std::byte* slot_data(uint32_t slot) const { return pool_.get() + size_t(slot) * brick_bytes_; }

  /// @brief Non-blocking access. A miss queues a request unless request_on_miss is false.
  BrickHandle lookup(const BrickKey& key, float priority = 0, bool request_on_miss = true);
  /// @brief Blocking access for tools, tests and the reference renderer. Throws the load's
  /// Error for a corrupt brick or a key outside the store.
  BrickHandle fetch(const BrickKey& key);
  /// @brief Asks for a brick without looking it up (prefetch, refinement requests).
  void request(const BrickKey& key, float priority);

  /// @brief Usage feedback: the brick was used this frame (protects it under lru-frame).
  void mark_used(const BrickKey& key);
  /// @brief Visibility feedback, readable through visibility() once the frame has ended.
  void mark_visible(const BrickKey& key, bool visible);
  /// @brief Visibility as of the last finished frame that marked the key.
  std::optional<bool> visibility(const BrickKey& key) const;

  void frame_begin();
  FrameReport frame_end();
  uint64_t frame() const;
  /// @brief The requests of the last finished frame, merged, highest priority first.
  std::vector<BrickRequest> frame_requests() const;

  /// @brief Hands staged requests to the loader and waits until it has served all of them
  /// (uploads deferred by the budget, or for want of an unpinned slot, wait for a later
  /// frame_begin()).
  void wait_idle();
  CacheStats stats() const;

 private:
  friend class BrickHandle;
  struct Impl;
  void unpin(uint32_t slot) { slots_.unpin(slot); }
  BrickHandle make_handle(const BrickKey& key, BrickHandle::State state) const;
  BrickHandle resident_handle(const BrickKey& key, uint32_t slot);
  void worker_loop();
  /// Reads and decodes a brick from the store, counts it and keeps it in L2. Throws the
  /// decode's Error, naming the store.
  BrickBuffer load_from_store(const lmdb::ReadTxn& txn, const BrickKey& key);
  /// Collects the requests staged in every stripe.
  std::vector<BrickRequest> take_staged();
  /// Merges requests into the loader queue; the caller holds the queue mutex.
  void enqueue_locked(const std::vector<BrickRequest>& batch);
  /// Uploads loaded bricks into the pool while this frame's budget allows.
  void drain_ready();
  /// Whether nothing is queued or in flight; the caller holds the queue mutex.
  bool idle_locked() const;
  /// Wakes wait_idle() when idle_locked().
  void notify_if_idle_locked();

  const BrickStore& store_;
  CacheConfig config_;
  size_t brick_bytes_;
  SlotTable slots_;
  std::unique_ptr<std::byte[]> pool_;
  HostCache l2_;
  std::unique_ptr<Impl> impl_;
};

/// @brief A fixed pool of node records (GigaVoxels' node pool), managed like the brick pool:
/// slots pinned while in use, replacement by a policy, one record of `record_bytes` per slot.
class NodePool {
 public:
  NodePool(uint32_t slots, size_t record_bytes, const std::string& policy = "lru");
  /// @brief Pinned slot of a resident record, or kNoSlot.
  uint32_t lookup(uint64_t id) { return slots_.lookup_and_pin(id); }
  /// @brief A slot for a new record (evicting an unpinned victim), writable until publish();
  /// kNoSlot when every slot is pinned or protected.
  uint32_t allocate(uint64_t id, std::optional<uint64_t>* evicted = nullptr) { return slots_.reserve(id, evicted); }
  void publish(uint32_t slot, uint32_t pins = 0) { slots_.publish(slot, pins); }
  void unpin(uint32_t slot) { slots_.unpin(slot); }
  void touch(uint64_t id) { slots_.touch(id); }
  void frame(uint64_t f) { slots_.frame(f); }
  std::byte* data(uint32_t slot) { return records_.data() + size_t(slot) * record_bytes_; }
  uint32_t capacity() const { return slots_.capacity(); }
  uint32_t resident() const { return slots_.resident(); }
  uint64_t key_of(uint32_t slot) const { return slots_.key_of(slot); }
  SlotCounters counters() const { return slots_.counters(); }

 private:
  size_t record_bytes_;
  SlotTable slots_;
  std::vector<std::byte> records_;
};

}  // namespace brickyard
