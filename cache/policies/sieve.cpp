// SIEVE (Zhang et al., NSDI 2024): a FIFO queue with a visited bit and a hand that moves from
// the oldest entry towards the newest, clearing visited bits, and evicts the first unvisited
// entry. New entries go to the head; hits only set the bit (no list movement).

#include "cache/policies/entry_list.h"
#include "cache/policies/policies.h"

namespace brickyard::policy_detail {
namespace {

class Sieve final : public Policy {
 public:
  std::string_view name() const override { return "sieve"; }
  void on_hit(uint64_t id, uint64_t) override {
    if (uint32_t i = list_.find(id); i != kNil) list_.at(i).extra = true;
  }
  void on_insert(uint64_t id, uint64_t size, uint64_t) override { list_.push_front(id, size, false); }
  void on_remove(uint64_t id) override {
    if (uint32_t i = list_.find(id); i != kNil) remove(i);
  }
  std::optional<uint64_t> evict(EvictableFn evictable) override {
    if (list_.count() == 0) return std::nullopt;
    // Two sweeps clear every visited bit; a third would find only pinned entries.
    for (size_t steps = 0; steps < 2 * list_.count() + 1; ++steps) {
      if (hand_ == kNil) hand_ = list_.tail();
      auto& e = list_.at(hand_);
      if (e.extra) {
        e.extra = false;
      } else if (evictable(e.id)) {
        const uint64_t id = e.id;
        remove(hand_);
        return id;
      }
      hand_ = e.prev;
    }
    return std::nullopt;
  }
  double metadata_bytes_per_entry() const override { return EntryList<bool>::overhead(); }

 private:
  void remove(uint32_t i) {
    if (hand_ == i) hand_ = list_.at(i).prev;
    list_.erase(i);
  }
  EntryList<bool> list_;  // extra: visited
  uint32_t hand_ = kNil;
};

}  // namespace

std::unique_ptr<Policy> make_sieve(uint64_t) { return std::make_unique<Sieve>(); }

}  // namespace brickyard::policy_detail
