// ARC (Megiddo & Modha, FAST 2003), weighted by entry size: T1 holds entries seen once
// recently, T2 entries seen at least twice; ghost lists B1 and B2 remember what each evicted,
// and a hit on a ghost moves the target size p of T1 towards the list that would have kept it.
// With unit sizes this is the original algorithm.

#include <algorithm>

#include "cache/policies/entry_list.h"
#include "cache/policies/policies.h"

namespace brickyard::policy_detail {
namespace {

class Arc final : public Policy {
 public:
  explicit Arc(uint64_t capacity) : c_(double(std::max<uint64_t>(capacity, 1))) {}
  std::string_view name() const override { return "arc"; }

  void on_hit(uint64_t id, uint64_t) override {
    if (uint32_t i = t1_.find(id); i != kNil) {
      const uint64_t size = t1_.at(i).size;
      t1_.erase(i);
      t2_.push_front(id, size);
    } else if (uint32_t j = t2_.find(id); j != kNil) {
      t2_.move_to_front(j);
    }
  }

  void on_miss(uint64_t id) override {
    ghost_ = Ghost::none;
    if (uint32_t i = b1_.find(id); i != kNil) {
      const double size = double(b1_.at(i).size);
      p_ = std::min(c_, p_ + std::max(1.0, double(b2_.bytes()) / std::max(1.0, double(b1_.bytes()))) * size);
      b1_.erase(i);
      ghost_ = Ghost::b1;
    } else if (uint32_t j = b2_.find(id); j != kNil) {
      const double size = double(b2_.at(j).size);
      p_ = std::max(0.0, p_ - std::max(1.0, double(b1_.bytes()) / std::max(1.0, double(b2_.bytes()))) * size);
      b2_.erase(j);
      ghost_ = Ghost::b2;
    }
  }

  void on_insert(uint64_t id, uint64_t size, uint64_t) override {
    if (ghost_ != Ghost::none) t2_.push_front(id, size);
    else t1_.push_front(id, size);
    ghost_ = Ghost::none;
    // Directory bounds: |T1| + |B1| <= c and |T1| + |T2| + |B1| + |B2| <= 2c.
    while (double(t1_.bytes() + b1_.bytes()) > c_ && b1_.count() > 0) b1_.erase(b1_.tail());
    while (double(t1_.bytes() + t2_.bytes() + b1_.bytes() + b2_.bytes()) > 2 * c_ && b2_.count() > 0) b2_.erase(b2_.tail());
  }

  void on_remove(uint64_t id) override {
    if (uint32_t i = t1_.find(id); i != kNil) t1_.erase(i);
    else if (uint32_t j = t2_.find(id); j != kNil) t2_.erase(j);
  }

  std::optional<uint64_t> evict(EvictableFn evictable) override {
    const double t1 = double(t1_.bytes());
    const bool from_t1 = t1 > 0 && (t1 > p_ || (ghost_ == Ghost::b2 && t1 == p_));
    if (auto v = evict_from(from_t1 ? t1_ : t2_, from_t1 ? b1_ : b2_, evictable)) return v;
    return evict_from(from_t1 ? t2_ : t1_, from_t1 ? b2_ : b1_, evictable);
  }

  double metadata_bytes_per_entry() const override {
    // Ghost entries are bookkeeping too: count them against the resident ones.
    const double resident = double(std::max<size_t>(1, t1_.count() + t2_.count()));
    return EntryList<NoExtra>::overhead() * double(t1_.count() + t2_.count() + b1_.count() + b2_.count()) / resident;
  }

 private:
  enum class Ghost { none, b1, b2 };
  static std::optional<uint64_t> evict_from(EntryList<NoExtra>& list, EntryList<NoExtra>& ghost, EvictableFn evictable) {
    for (uint32_t i = list.tail(); i != kNil; i = list.at(i).prev) {
      const uint64_t id = list.at(i).id;
      if (!evictable(id)) continue;
      const uint64_t size = list.at(i).size;
      list.erase(i);
      ghost.push_front(id, size);
      return id;
    }
    return std::nullopt;
  }

  double c_;
  double p_ = 0;
  Ghost ghost_ = Ghost::none;
  EntryList<NoExtra> t1_, t2_, b1_, b2_;
};

}  // namespace

std::unique_ptr<Policy> make_arc(uint64_t capacity) { return std::make_unique<Arc>(capacity); }

}  // namespace brickyard::policy_detail
