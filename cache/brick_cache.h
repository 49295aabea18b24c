#pragma once
/// @file brick_cache.h
/// @brief Grid bricks through the page cache, in a grid's own terms: BrickKey addresses,
/// constant nodes answered from the node table without a page, handles that carry a node's
/// value range. A thin typed view: every page lives in the PageCache below it (RecordKind::
/// brick, id BrickKey::code()), which owns residency, loading, budgets and statistics.
///
/// Thread safety and lifetimes are the PageCache's (page_cache.h): every member may be called
/// from any thread; the PageCache and the GridView must outlive this view, and handles must
/// be released before the PageCache is destroyed.

#include <optional>
#include <string>
#include <vector>

#include "cache/page_cache.h"
#include "core/brick_key.h"
#include "dataset/grid.h"

namespace brickyard {

/// @brief A brick as a renderer sees it. Resident handles pin their slot until released.
class BrickHandle {
 public:
  enum class State : uint8_t { miss, resident, constant, failed };

  BrickHandle() = default;
  BrickHandle(BrickHandle&& o) noexcept { *this = std::move(o); }
  BrickHandle& operator=(BrickHandle&& o) noexcept {
    page_ = std::move(o.page_);
    key_ = o.key_;
    state_ = o.state_;
    min_ = o.min_, max_ = o.max_, constant_ = o.constant_;
    o.state_ = State::miss;
    return *this;
  }
  BrickHandle(const BrickHandle&) = delete;
  BrickHandle& operator=(const BrickHandle&) = delete;

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
  uint32_t slot() const { return page_.slot(); }
  /// @brief Decoded voxels with aprons, (M + 2A)^3, x fastest.
  const std::byte* bytes() const { return page_.bytes(); }
  template <typename T>
  const T* voxels() const { return reinterpret_cast<const T*>(page_.bytes()); }
  /// @brief The node's value range (its trilinear cells) and, for constant nodes, the value.
  float min() const { return min_; }
  float max() const { return max_; }
  float constant_value() const { return constant_; }
  /// @brief Why a failed handle failed (corrupt brick, key outside the store).
  const std::string& error() const { return page_.error(); }

  void release() {
    page_.release();
    if (state_ == State::resident) state_ = State::miss;
  }

 private:
  friend class BrickCache;
  PageHandle page_;
  BrickKey key_{};
  State state_ = State::miss;
  float min_ = 0, max_ = 0, constant_ = 0;
};

struct BrickRequest {
  BrickKey key;
  float priority = 0;
};

class BrickCache {
 public:
  /// @throws Error(invalid_argument) when the page cache holds no bricks.
  BrickCache(PageCache& pages, const GridView& grid);

  PageCache& pages() const { return pages_; }
  const GridView& grid() const { return grid_; }
  const GridLayout& layout() const { return grid_.layout(); }
  const NodeTable& nodes() const { return grid_.nodes(); }
  const BrickShape& shape() const { return grid_.shape(); }
  uint32_t pool_slots() const { return pages_.pool_slots(RecordKind::brick); }
  const CacheConfig& config() const { return pages_.config(); }
  /// @brief Slot data in the pool (for renderers that address the pool directly).
  const std::byte* slot_data(uint32_t slot) const { return pages_.slot_data(RecordKind::brick, slot); }

  /// @brief Non-blocking access. A miss queues a request unless request_on_miss is false.
  BrickHandle lookup(const BrickKey& key, float priority = 0, bool request_on_miss = true);
  /// @brief Blocking access for tools, tests and the reference renderer. Throws the load's
  /// Error for a corrupt brick or a key outside the store.
  BrickHandle fetch(const BrickKey& key);
  /// @brief fetch() that answers a brick which cannot be read with a failed handle instead of
  /// throwing (PageCache::fetch_or_failed): renderers draw around it and report it.
  BrickHandle fetch_or_failed(const BrickKey& key);
  /// @brief Asks for a brick without looking it up (prefetch, refinement requests); constant
  /// nodes and keys outside the grid are not asked for.
  void request(const BrickKey& key, float priority);

  /// @brief Usage feedback: the brick was used this frame (protects it under lru-frame).
  void mark_used(const BrickKey& key) { pages_.mark_used(page_key(key)); }
  /// @brief Visibility feedback, readable through visibility() once the frame has ended.
  void mark_visible(const BrickKey& key, bool visible) { pages_.mark_visible(page_key(key), visible); }
  /// @brief Visibility as of the last finished frame that marked the key.
  std::optional<bool> visibility(const BrickKey& key) const { return pages_.visibility(page_key(key)); }

  // The page cache's frame, loader and statistics (for the callers of a grid's cache).
  void frame_begin() { pages_.frame_begin(); }
  FrameReport frame_end() { return pages_.frame_end(); }
  uint64_t frame() const { return pages_.frame(); }
  /// @brief The brick requests of the last finished frame, merged, highest priority first.
  std::vector<BrickRequest> frame_requests() const;
  void wait_idle() { pages_.wait_idle(); }
  CacheStats stats() const { return pages_.stats(RecordKind::brick); }

  static PageKey page_key(const BrickKey& key) { return {RecordKind::brick, key.code()}; }

 private:
  static void set_node(BrickHandle& h, const BrickKey& key, const NodeRecord& node, BrickHandle::State state);

  PageCache& pages_;
  const GridView grid_;  // a copy: small, and it points into the dataset only for the node table
};

}  // namespace brickyard
