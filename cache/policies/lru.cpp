// LRU: evict the least recently used entry.

#include "cache/policies/policies.h"
#include "cache/policies/entry_list.h"

namespace brickyard::policy_detail {
namespace {

class Lru final : public Policy {
 public:
  std::string_view name() const override { return "lru"; }
  void on_hit(uint64_t id, uint64_t) override {
    if (uint32_t i = list_.find(id); i != kNil) list_.move_to_front(i);
  }
  void on_insert(uint64_t id, uint64_t size, uint64_t) override { list_.push_front(id, size); }
  void on_remove(uint64_t id) override {
    if (uint32_t i = list_.find(id); i != kNil) list_.erase(i);
  }
  std::optional<uint64_t> evict(EvictableFn evictable) override {
    for (uint32_t i = list_.tail(); i != kNil; i = list_.at(i).prev) {
      const uint64_t id = list_.at(i).id;
      if (!evictable(id)) continue;
      list_.erase(i);
      return id;
    }
    return std::nullopt;
  }
  double metadata_bytes_per_entry() const override { return EntryList<NoExtra>::overhead(); }

 private:
  EntryList<NoExtra> list_;
};

}  // namespace

std::unique_ptr<Policy> make_lru(uint64_t) { return std::make_unique<Lru>(); }

}  // namespace brickyard::policy_detail
