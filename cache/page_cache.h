#pragma once
/// @file page_cache.h
/// @brief The one cache every renderer reaches data through, over records of any kind (grid
/// bricks, octree pages, tetrahedral clusters), each addressed by (record kind, 64-bit id):
/// - L1, per kind a fixed pool of slots of the kind's page size, which renderers read from;
/// - L2, per kind decoded pages in host memory under a byte budget;
/// - L3, the PageSource behind it (a store), of which the cache knows nothing else.
///
/// Two ways in. A GPU-style renderer calls lookup() from its render threads: a hit is a pinned
/// handle, a miss is recorded as a request that worker threads serve asynchronously (L2, else
/// read and decode from L3), uploading into the pool within a per-frame budget; frame_begin()
/// and frame_end() bracket each frame. A CPU-style tool calls fetch(), which blocks (a stall)
/// until the page is resident. Typed access (BrickCache for grid bricks) sits on top, in the
/// caller's own terms.
///
/// Thread safety: every member may be called from any thread, except that frame_begin() and
/// frame_end() must not overlap each other. lookup(), fetch(), request() and the marks take
/// only per-shard or per-stripe locks. Handles must be released before the cache is destroyed.
/// Requests are data (STYLE.md 7): render threads append them to striped per-frame lists that
/// the loader drains, and frame_requests() shows exactly what the last frame asked for.
///
/// Lifetime: the PageSource must outlive the cache. close() stops its loader (requests in
/// flight finish or are dropped, nothing half-inserted) and writes its trace, throwing when it
/// cannot; destroying a cache not closed does the same but must swallow that error, so a
/// caller that reports the trace written calls close() first.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cache/host_cache.h"
#include "cache/slot_table.h"
#include "cache/trace.h"
#include "core/pool_memory.h"
#include "dataset/pages.h"

namespace brickyard {

/// @brief Budgets of one record kind, for sources with more than one.
struct KindBudget {
  uint32_t l1_slots = 0;  ///< 0: as many as fit in l1_bytes
  uint64_t l1_bytes = 0;
  uint64_t l2_bytes = 0;
};

struct CacheConfig {
  uint32_t l1_slots = 0;                      ///< L1 pool slots; 0: as many as fit in l1_bytes
  uint64_t l1_bytes = uint64_t(256) << 20;    ///< used when l1_slots is 0
  uint64_t l2_bytes = uint64_t(1) << 30;
  std::string l1_policy = "lru";
  std::string l2_policy = "lru";
  int loader_threads = 2;
  uint32_t upload_pages_per_frame = 0;  ///< pages (of every kind together) uploaded per frame; 0: unlimited
  uint64_t upload_bytes_per_frame = 0;   ///< 0: unlimited
  /// Record every access to this file (brickyard format), written by PageCache::close(). The
  /// cache refuses, when it is made, a path it could not write then (check_writable).
  std::string trace_path;
  /// The part of the L1 budget that a back end's own brick pool holds beside this cache's L1
  /// (share_l1_budget), 0 where the budget leaves it nothing; unset: not shared, the cache's L1
  /// is the whole budget.
  std::optional<uint64_t> backend_pool_bytes;
  /// A source of one record kind gives it the budgets above. A source of several gives each
  /// kind listed here its own budget, and shares l1_bytes and l2_bytes equally among the rest
  /// (l1_slots, when set, applies to each of them).
  std::map<RecordKind, KindBudget> kinds;
};

class PageCache;

/// @brief A page as a renderer sees it. Resident handles pin their slot until released.
class PageHandle {
 public:
  enum class State : uint8_t { miss, resident, failed };

  PageHandle() = default;
  PageHandle(PageHandle&& o) noexcept { *this = std::move(o); }
  PageHandle& operator=(PageHandle&& o) noexcept;
  PageHandle(const PageHandle&) = delete;
  PageHandle& operator=(const PageHandle&) = delete;
  ~PageHandle() { release(); }

  State state() const { return state_; }
  bool resident() const { return state_ == State::resident; }
  bool failed() const { return state_ == State::failed; }
  const PageKey& key() const { return key_; }
  /// @brief Pool slot (kNoSlot for a blocking fetch that found the pool pinned full and holds
  /// a private copy instead).
  uint32_t slot() const { return slot_; }
  /// @brief The decoded page (the kind's page size).
  const std::byte* bytes() const { return data_; }
  /// @brief Why a failed handle failed (corrupt record, key outside the source); "" otherwise.
  const std::string& error() const;
  void release();

 private:
  friend class PageCache;
  friend class BrickCache;
  // Laid out for the hit path, which fills cache_, data_, key_, slot_ and state_ only: the error
  // is shared and the private copy is null unless the handle needs them.
  PageCache* cache_ = nullptr;
  const std::byte* data_ = nullptr;
  PageKey key_{};
  uint32_t slot_ = kNoSlot;
  State state_ = State::miss;
  PageBuffer owned_;  // a private copy when the pool had no free slot
  std::shared_ptr<const std::string> error_;
};

struct CacheLevelStats {
  uint64_t hits = 0, misses = 0, inserts = 0, evictions = 0, failed_evictions = 0;
  uint64_t resident = 0, capacity = 0;  ///< slots (L1), bytes (L2), records (L3)
  double metadata_bytes_per_entry = 0;
  CacheLevelStats& operator+=(const CacheLevelStats& o);
};

/// @brief Statistics of the whole cache, or of one record kind (stats(kind)); the loader's
/// queue figures (requests, merged, dropped, queue length, deferred uploads, latency) are the
/// whole cache's in both.
struct CacheStats {
  CacheLevelStats l1, l2, l3;
  uint64_t l1_pool_bytes = 0;   ///< the pools' fixed allocation
  uint64_t l2_peak_bytes = 0;   ///< never above the L2 budget (the sum of the kinds' peaks)
  uint64_t l3_bytes_read = 0;   ///< stored (compressed) record bytes read from the source
  uint64_t l3_bytes_decoded = 0;
  double l3_decode_seconds = 0;
  uint64_t constant_hits = 0;   ///< lookups a kind's directory answered with no page (constant bricks)
  uint64_t requests = 0, merged_requests = 0, dropped_requests = 0, queue_length = 0;
  uint64_t uploads = 0, deferred_uploads = 0;
  /// Decoded pages waiting in the loader for an upload budget or an unpinned slot, and the
  /// bytes of those L2 no longer holds (evicted meanwhile): memory beside both budgets, at
  /// most one frame's upload budget (past it a page waits only as L2's).
  uint64_t waiting_pages = 0, waiting_bytes_beside_l2 = 0;
  /// Waiting pages dropped because L2 evicted them before the budget let them up (a renewed
  /// request loads them again).
  uint64_t expired_waiting_pages = 0;
  uint64_t stalls = 0;          ///< blocking fetches that had to wait for a load
  uint64_t failed_keys = 0;     ///< pages that failed to load (each counted once, never retried)
  double latency_p50_ms = 0, latency_p99_ms = 0;  ///< request to resident in L1
  uint64_t frames = 0;
  /// Each kind's own figures, when the source holds more than one (whole-cache stats only).
  std::map<RecordKind, CacheStats> kinds;
  std::string to_json() const;
};

/// @brief What one frame did, returned by frame_end().
struct FrameReport {
  uint64_t frame = 0;
  uint64_t requests = 0;         ///< distinct requests made during the frame
  uint64_t dropped = 0;          ///< pending requests not renewed this frame, dropped
  uint64_t uploads = 0;          ///< pages uploaded into L1 during the frame
  uint64_t upload_bytes = 0;
  uint64_t lookups = 0, hits = 0;
};

struct PageRequest {
  PageKey key;
  float priority = 0;
};

class PageCache {
 public:
  /// @throws Error(invalid_argument) for budgets smaller than one page, unknown policies, a
  /// source without pages; Error(not_found) or Error(io) for a trace path that cannot be
  /// written (check_writable).
  PageCache(const PageSource& source, const CacheConfig& config);
  /// @brief Stops and writes as close() does, if close() was not called; a failure to write
  /// the trace is lost here.
  ~PageCache();
  PageCache(const PageCache&) = delete;
  PageCache& operator=(const PageCache&) = delete;

  const CacheConfig& config() const { return config_; }
  /// @brief Whether the source holds pages of this kind.
  bool holds(RecordKind kind) const { return kinds_[size_t(kind)] != nullptr; }
  /// @brief The kinds held, in RecordKind order.
  std::vector<RecordKind> kinds() const;
  /// @brief Decoded page size of a kind held (0 for one not held).
  size_t page_bytes(RecordKind kind) const { return holds(kind) ? kinds_[size_t(kind)]->page_bytes : 0; }
  uint32_t pool_slots(RecordKind kind) const { return holds(kind) ? kinds_[size_t(kind)]->slots.capacity() : 0; }
  /// @brief A slot's page in a kind's pool (for renderers that address the pool directly).
  const std::byte* slot_data(RecordKind kind, uint32_t slot) const {
    const Kind& k = *kinds_[size_t(kind)];
    return k.pool.get() + size_t(slot) * k.page_bytes;
  }

  /// @brief Non-blocking access. A miss queues a request unless request_on_miss is false.
  PageHandle lookup(const PageKey& key, float priority = 0, bool request_on_miss = true) {
    PageHandle h;
    lookup_into(h, key, priority, request_on_miss);
    return h;
  }
  /// @brief lookup() into a handle the caller holds (released first, then filled in place):
  /// the typed views' hit path builds their handle around it without a second one.
  void lookup_into(PageHandle& out, const PageKey& key, float priority = 0, bool request_on_miss = true);
  /// @brief Blocking access for tools, tests and reference renderers. Throws the load's
  /// Error for a corrupt record or a key outside the source.
  PageHandle fetch(const PageKey& key);
  /// @brief fetch() that answers a page which cannot be read (corrupt, missing, unreadable)
  /// with a failed handle (its error()) instead of throwing: for renderers, which draw around
  /// such a page and report it (failed_pages()). Other errors (a kind the source does not
  /// hold) still throw.
  PageHandle fetch_or_failed(const PageKey& key);
  /// @brief Asks for a page without looking it up (prefetch, refinement requests).
  void request(const PageKey& key, float priority);
  /// @brief Whether a page is resident in L1 now (no pin, nothing counted).
  bool resident(const PageKey& key) const;

  /// @brief Usage feedback: the page was used this frame (protects it under lru-frame).
  void mark_used(const PageKey& key);
  /// @brief Visibility feedback, readable through visibility() once the frame has ended.
  void mark_visible(const PageKey& key, bool visible);
  /// @brief Visibility as of the last finished frame that marked the key.
  std::optional<bool> visibility(const PageKey& key) const;
  /// @brief A lookup a kind's directory answered without a page (a constant brick): counted
  /// as a hit, and as a constant hit.
  void count_constant_hit(RecordKind kind);

  void frame_begin();
  FrameReport frame_end();
  uint64_t frame() const;
  /// @brief The requests of the last finished frame, merged, highest priority first.
  std::vector<PageRequest> frame_requests() const;

  /// @brief Hands staged requests to the loader and waits until it has served all of them
  /// (uploads deferred by the budget, or for want of an unpinned slot, wait for a later
  /// frame_begin()).
  void wait_idle();
  /// @brief Ends the cache's use: stops the loader and writes the trace (trace_path), if one
  /// is recorded. Afterwards the cache loads nothing asynchronously and records nothing
  /// (wait_idle() returns at once, fetch() still loads); stats() and the destructor remain.
  /// Must not overlap any other call. A second call does nothing. @throws Error(io) naming the
  /// trace file, which is then not written (the destructor does not try again).
  void close();
  CacheStats stats() const;
  CacheStats stats(RecordKind kind) const;
  /// @brief The pages that could not be read so far, each once, in key order, with the error
  /// of their load (which names the source and the key).
  struct FailedPage {
    PageKey key;
    std::string error;
  };
  std::vector<FailedPage> failed_pages() const;

 private:
  friend class PageHandle;
  /// One record kind's levels: its L1 pool and slot table, its L2, its L3 counters.
  struct Kind {
    Kind(RecordKind kind, size_t page_bytes, uint32_t slots, uint64_t l2_bytes, const CacheConfig& config);
    RecordKind kind;
    size_t page_bytes;
    SlotTable slots;
    PoolArray<std::byte> pool;
    HostCache l2;
    std::atomic<uint64_t> l3_reads{0}, l3_bytes_read{0}, l3_bytes_decoded{0}, l3_decode_ns{0};
    std::atomic<uint64_t> uploads{0}, stalls{0};
  };
  struct Impl;
  void unpin(RecordKind kind, uint32_t slot) { kinds_[size_t(kind)]->slots.unpin(slot); }
  PageHandle resident_handle(const PageKey& key, uint32_t slot);
  static void set_failed(PageHandle& h, const PageKey& key, std::string error);
  void worker_loop();
  /// Stops and joins the loader threads (again: nothing).
  void stop_loader();
  /// Reads and decodes a page from the source, counts it and keeps it in L2. Throws the
  /// read's Error, naming the source.
  PageBuffer load_from_source(PageReader& reader, Kind& kind, const PageKey& key);
  /// Collects the requests staged in every stripe.
  std::vector<PageRequest> take_staged();
  /// Merges requests into the loader queue; the caller holds the queue mutex.
  void enqueue_locked(const std::vector<PageRequest>& batch);
  /// Uploads loaded pages into their pools while this frame's budget allows.
  void drain_ready();
  /// Whether nothing is queued or in flight; the caller holds the queue mutex.
  bool idle_locked() const;
  /// Wakes wait_idle() when idle_locked().
  void notify_if_idle_locked();
  CacheStats kind_stats(const Kind& k) const;
  void add_queue_stats(CacheStats& s) const;

  const PageSource& source_;
  CacheConfig config_;
  // One per record kind the source holds (null for the others); fixed after construction, so
  // the hit path reads it without a lock.
  std::array<std::unique_ptr<Kind>, kRecordKinds> kinds_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace brickyard
