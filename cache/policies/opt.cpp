// Belady's OPT: evict the entry whose next access is furthest in the future. It needs the
// future, so it exists for offline replay, where the trace gives every access's next access.
// A max-heap with lazy deletion: stale heap entries are skipped when they surface.

#include <queue>
#include <vector>

#include <absl/container/flat_hash_map.h>

#include "cache/policies/policies.h"

namespace brickyard::policy_detail {
namespace {

class Opt final : public Policy {
 public:
  std::string_view name() const override { return "opt"; }
  bool needs_future() const override { return true; }
  void on_hit(uint64_t id, uint64_t next) override {
    if (auto it = next_.find(id); it != next_.end()) {
      it->second = next;
      heap_.push({next, id});
    }
  }
  void on_insert(uint64_t id, uint64_t, uint64_t next) override {
    next_[id] = next;
    heap_.push({next, id});
  }
  void on_remove(uint64_t id) override { next_.erase(id); }
  std::optional<uint64_t> evict(EvictableFn evictable) override {
    std::vector<std::pair<uint64_t, uint64_t>> pinned;
    std::optional<uint64_t> victim;
    while (!heap_.empty()) {
      const auto [next, id] = heap_.top();
      heap_.pop();
      auto it = next_.find(id);
      if (it == next_.end() || it->second != next) continue;  // stale
      if (!evictable(id)) {
        pinned.push_back({next, id});
        continue;
      }
      next_.erase(it);
      victim = id;
      break;
    }
    for (const auto& p : pinned) heap_.push(p);
    if (heap_.size() > 4 * next_.size() + 1024) compact();
    return victim;
  }
  double metadata_bytes_per_entry() const override {
    return 16.0 / 0.875 + 16.0 * double(heap_.size()) / double(std::max<size_t>(1, next_.size()));
  }

 private:
  void compact() {
    std::priority_queue<std::pair<uint64_t, uint64_t>> fresh;
    for (const auto& [id, next] : next_) fresh.push({next, id});
    heap_.swap(fresh);
  }
  absl::flat_hash_map<uint64_t, uint64_t> next_;
  std::priority_queue<std::pair<uint64_t, uint64_t>> heap_;
};

}  // namespace

std::unique_ptr<Policy> make_opt(uint64_t) { return std::make_unique<Opt>(); }

}  // namespace brickyard::policy_detail
