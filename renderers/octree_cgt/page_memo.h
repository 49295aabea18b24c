#pragma once
/// @file page_memo.h
/// @brief The octree pages one tile of octree_cgt has fetched through the cache, pinned and
/// parsed, with an index to find them again: each descent asks for its path's pages again.

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "cache/page_cache.h"
#include "dataset/octree.h"
#include "renderers/common/frame.h"

namespace brickyard::octree_cgt {

/// The pages a tile has fetched, pinned and parsed, until a ray starts with more than
/// `capacity` held (never during a ray: its nodes point into them). A page that cannot be
/// read is null: the octree walk stands its parent's scalars in for it (octree_walk.h), the
/// descent leaves its subtree empty.
template <typename T>
class PageMemo {
 public:
  PageMemo(PageCache& cache, const OctreeLayout& layout, size_t capacity, RayCounters& counters)
      : cache_(cache), layout_(layout), page_bytes_(layout.page_bytes()), capacity_(capacity), counters_(counters) {}
  const OctreePage<T>* page(uint64_t id) {
    // A direct-mapped index over the entries (each descent asks for its path's pages again).
    int16_t& slot = index_[size_t((id * 0x9e3779b97f4a7c15ull) >> 57)];
    if (slot >= 0 && size_t(slot) < entries_.size() && entries_[size_t(slot)]->id == id) return &entries_[size_t(slot)]->view;
    for (size_t i = 0; i < entries_.size(); ++i)
      if (entries_[i]->id == id) {
        if (i < size_t(INT16_MAX)) slot = int16_t(i);
        return &entries_[i]->view;
      }
    ++counters_.lookups;
    ++counters_.bricks;  // a page visit
    auto e = std::make_unique<Entry>();
    e->id = id;
    e->handle = cache_.fetch_or_failed({RecordKind::octree_page, id});
    if (e->handle.failed()) return nullptr;  // unreadable: the cache reports it, the tracer draws around it
    e->view = OctreePage<T>::view({e->handle.bytes(), page_bytes_}, layout_);
    entries_.push_back(std::move(e));
    if (entries_.size() - 1 < size_t(INT16_MAX)) slot = int16_t(entries_.size() - 1);
    return &entries_.back()->view;
  }
  /// For octree_scalars().
  const OctreePage<T>* operator()(uint64_t id) { return page(id); }
  void begin_ray() {
    if (entries_.size() >= capacity_) entries_.clear(), index_.fill(-1), ++generation_;
  }
  /// Changes whenever pages are let go: pointers into them from before are stale.
  uint64_t generation() const { return generation_; }

 private:
  struct Entry {
    uint64_t id = 0;
    PageHandle handle;
    OctreePage<T> view;
  };
  PageCache& cache_;
  const OctreeLayout& layout_;
  size_t page_bytes_, capacity_;
  RayCounters& counters_;
  std::vector<std::unique_ptr<Entry>> entries_;
  std::array<int16_t, 128> index_ = make_index();
  uint64_t generation_ = 0;
  static std::array<int16_t, 128> make_index() {
    std::array<int16_t, 128> a;
    a.fill(-1);
    return a;
  }
};

}  // namespace brickyard::octree_cgt
