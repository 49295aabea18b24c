// CLOCK (second chance): a circular buffer with a reference bit per entry; the hand clears set
// bits and evicts the first entry whose bit is clear.

#include <vector>

#include <absl/container/flat_hash_map.h>

#include "cache/policies/policies.h"

namespace brickyard::policy_detail {
namespace {

class Clock final : public Policy {
 public:
  std::string_view name() const override { return "clock"; }
  void on_hit(uint64_t id, uint64_t) override {
    if (auto it = index_.find(id); it != index_.end()) ring_[it->second].referenced = true;
  }
  void on_insert(uint64_t id, uint64_t, uint64_t) override {
    uint32_t i;
    if (!free_.empty()) {
      i = free_.back();
      free_.pop_back();
    } else {
      i = uint32_t(ring_.size());
      ring_.emplace_back();
    }
    ring_[i] = {id, false, true};
    index_[id] = i;
  }
  void on_remove(uint64_t id) override {
    if (auto it = index_.find(id); it != index_.end()) release(it->second);
  }
  std::optional<uint64_t> evict(EvictableFn evictable) override {
    if (index_.empty()) return std::nullopt;
    for (size_t steps = 0; steps < 2 * ring_.size() + 1; ++steps) {
      hand_ = (hand_ + 1) % ring_.size();
      Slot& s = ring_[hand_];
      if (!s.used) continue;
      if (s.referenced) {
        s.referenced = false;
      } else if (evictable(s.id)) {
        const uint64_t id = s.id;
        release(uint32_t(hand_));
        return id;
      }
    }
    return std::nullopt;
  }
  double metadata_bytes_per_entry() const override { return double(sizeof(Slot)) + 16.0 / 0.875; }

 private:
  struct Slot {
    uint64_t id = 0;
    bool referenced = false;
    bool used = false;
  };
  void release(uint32_t i) {
    index_.erase(ring_[i].id);
    ring_[i].used = false;
    free_.push_back(i);
  }
  std::vector<Slot> ring_;
  std::vector<uint32_t> free_;
  absl::flat_hash_map<uint64_t, uint32_t> index_;
  size_t hand_ = 0;
};

}  // namespace

std::unique_ptr<Policy> make_clock(uint64_t) { return std::make_unique<Clock>(); }

}  // namespace brickyard::policy_detail
