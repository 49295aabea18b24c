// LRU with per-frame timestamps (GigaVoxels): entries used in the current frame are
// protected; the victim is the least recently used entry from an earlier frame. When every
// resident entry was used this frame, nothing is evicted and the caller must wait for the
// next frame (the GPU cache's "pool full" case).

#include "cache/policies/entry_list.h"
#include "cache/policies/policies.h"

namespace brickyard::policy_detail {
namespace {

class LruFrame final : public Policy {
 public:
  std::string_view name() const override { return "lru-frame"; }
  void on_frame(uint64_t frame) override { frame_ = frame; }
  void on_hit(uint64_t id, uint64_t) override {
    if (uint32_t i = list_.find(id); i != kNil) {
      list_.at(i).extra = frame_;
      list_.move_to_front(i);
    }
  }
  void on_insert(uint64_t id, uint64_t size, uint64_t) override { list_.push_front(id, size, frame_); }
  void on_remove(uint64_t id) override {
    if (uint32_t i = list_.find(id); i != kNil) list_.erase(i);
  }
  std::optional<uint64_t> evict(EvictableFn evictable) override {
    // Recency order means that once an entry of this frame is reached, all before it are too.
    for (uint32_t i = list_.tail(); i != kNil; i = list_.at(i).prev) {
      if (list_.at(i).extra == frame_) return std::nullopt;
      const uint64_t id = list_.at(i).id;
      if (!evictable(id)) continue;
      list_.erase(i);
      return id;
    }
    return std::nullopt;
  }
  double metadata_bytes_per_entry() const override { return EntryList<uint64_t>::overhead(); }

 private:
  EntryList<uint64_t> list_;  // extra: frame of last use
  uint64_t frame_ = 0;
};

}  // namespace

std::unique_ptr<Policy> make_lru_frame(uint64_t) { return std::make_unique<LruFrame>(); }

}  // namespace brickyard::policy_detail
