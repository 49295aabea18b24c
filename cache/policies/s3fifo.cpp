// S3-FIFO (Yang et al., SOSP 2023): a small FIFO (10% of the capacity) filters one-hit
// wonders, a main FIFO with 2-bit frequencies keeps the rest (reinserting entries that were
// hit), and a ghost FIFO of recently evicted ids sends returning entries straight to main.

#include <algorithm>

#include "cache/policies/entry_list.h"
#include "cache/policies/policies.h"

namespace brickyard::policy_detail {
namespace {

class S3Fifo final : public Policy {
 public:
  explicit S3Fifo(uint64_t capacity)
      : small_target_(std::max(1.0, 0.1 * double(capacity))), ghost_limit_(std::max(1.0, 0.9 * double(capacity))) {}
  std::string_view name() const override { return "s3fifo"; }

  void on_hit(uint64_t id, uint64_t) override {
    uint32_t i = small_.find(id);
    auto& list = i != kNil ? small_ : main_;
    if (i == kNil) i = main_.find(id);
    if (i != kNil) list.at(i).extra = uint8_t(std::min(3, list.at(i).extra + 1));
  }

  void on_miss(uint64_t id) override {
    from_ghost_ = false;
    if (uint32_t g = ghost_.find(id); g != kNil) {
      ghost_.erase(g);
      from_ghost_ = true;
    }
  }

  void on_insert(uint64_t id, uint64_t size, uint64_t) override {
    (from_ghost_ ? main_ : small_).push_front(id, size, 0);
    from_ghost_ = false;
  }

  void on_remove(uint64_t id) override {
    if (uint32_t i = small_.find(id); i != kNil) small_.erase(i);
    else if (uint32_t j = main_.find(id); j != kNil) main_.erase(j);
  }

  std::optional<uint64_t> evict(EvictableFn evictable) override {
    // Each pass either evicts or moves/ages one entry; bound the passes for the all-pinned case.
    const size_t limit = 4 * (small_.count() + main_.count()) + 4;
    for (size_t pass = 0; pass < limit; ++pass) {
      const bool use_small = small_.count() > 0 && (double(small_.bytes()) >= small_target_ || main_.count() == 0);
      if (use_small) {
        const uint32_t t = last_evictable(small_, evictable);
        if (t == kNil) {
          if (auto v = evict_main(evictable)) return v;
          return std::nullopt;
        }
        auto& e = small_.at(t);
        if (e.extra > 1) {  // hit while in the small queue: promote
          const uint64_t id = e.id, size = e.size;
          small_.erase(t);
          main_.push_front(id, size, 0);
          continue;
        }
        const uint64_t id = e.id, size = e.size;
        small_.erase(t);
        ghost_.push_front(id, size, 0);
        while (double(ghost_.bytes()) > ghost_limit_ && ghost_.count() > 0) ghost_.erase(ghost_.tail());
        return id;
      }
      if (auto v = evict_main(evictable)) return v;
      if (main_.count() == 0 || last_evictable(main_, evictable) == kNil) {
        if (small_.count() == 0 || last_evictable(small_, evictable) == kNil) return std::nullopt;
      }
    }
    return std::nullopt;
  }

  double metadata_bytes_per_entry() const override {
    const double resident = double(std::max<size_t>(1, small_.count() + main_.count()));
    return EntryList<uint8_t>::overhead() * double(small_.count() + main_.count() + ghost_.count()) / resident;
  }

 private:
  static uint32_t last_evictable(EntryList<uint8_t>& list, EvictableFn evictable) {
    for (uint32_t i = list.tail(); i != kNil; i = list.at(i).prev)
      if (evictable(list.at(i).id)) return i;
    return kNil;
  }

  // One step of main's CLOCK-like sweep: evicts the oldest unreferenced entry, or ages one.
  std::optional<uint64_t> evict_main(EvictableFn evictable) {
    const size_t limit = 4 * main_.count() + 1;
    for (size_t step = 0; step < limit; ++step) {
      const uint32_t t = last_evictable(main_, evictable);
      if (t == kNil) return std::nullopt;
      auto& e = main_.at(t);
      if (e.extra > 0) {
        e.extra = uint8_t(e.extra - 1);
        main_.move_to_front(t);
        continue;
      }
      const uint64_t id = e.id;
      main_.erase(t);
      return id;
    }
    return std::nullopt;
  }

  double small_target_, ghost_limit_;
  bool from_ghost_ = false;
  EntryList<uint8_t> small_, main_, ghost_;  // extra: frequency 0..3
};

}  // namespace

std::unique_ptr<Policy> make_s3fifo(uint64_t capacity) { return std::make_unique<S3Fifo>(capacity); }

}  // namespace brickyard::policy_detail
