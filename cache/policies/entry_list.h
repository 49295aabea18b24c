#pragma once
// An intrusive doubly-linked list of entries stored in a vector, with a free list, plus an id
// index: the building block of the list-based policies. Head is most recent.

#include <cstdint>
#include <vector>

#include <absl/container/flat_hash_map.h>

namespace brickyard::policy_detail {

inline constexpr uint32_t kNil = UINT32_MAX;

template <typename Extra>
class EntryList {
 public:
  struct Entry {
    uint64_t id = 0;
    uint64_t size = 0;
    uint32_t prev = kNil, next = kNil;
    Extra extra{};
  };

  uint32_t find(uint64_t id) const {
    auto it = index_.find(id);
    return it == index_.end() ? kNil : it->second;
  }
  Entry& at(uint32_t i) { return entries_[i]; }
  const Entry& at(uint32_t i) const { return entries_[i]; }
  uint32_t head() const { return head_; }
  uint32_t tail() const { return tail_; }
  size_t count() const { return index_.size(); }
  uint64_t bytes() const { return bytes_; }

  uint32_t push_front(uint64_t id, uint64_t size, Extra extra = {}) {
    uint32_t i;
    if (!free_.empty()) {
      i = free_.back();
      free_.pop_back();
    } else {
      i = uint32_t(entries_.size());
      entries_.emplace_back();
    }
    entries_[i] = {id, size, kNil, head_, extra};
    if (head_ != kNil) entries_[head_].prev = i;
    head_ = i;
    if (tail_ == kNil) tail_ = i;
    index_[id] = i;
    bytes_ += size;
    return i;
  }

  void unlink(uint32_t i) {
    Entry& e = entries_[i];
    if (e.prev != kNil) entries_[e.prev].next = e.next;
    else head_ = e.next;
    if (e.next != kNil) entries_[e.next].prev = e.prev;
    else tail_ = e.prev;
    e.prev = e.next = kNil;
  }

  void move_to_front(uint32_t i) {
    if (head_ == i) return;
    unlink(i);
    Entry& e = entries_[i];
    e.next = head_;
    if (head_ != kNil) entries_[head_].prev = i;
    head_ = i;
    if (tail_ == kNil) tail_ = i;
  }

  void erase(uint32_t i) {
    unlink(i);
    bytes_ -= entries_[i].size;
    index_.erase(entries_[i].id);
    free_.push_back(i);
  }

  /// Bytes of bookkeeping per entry: the entry and its index slot.
  static constexpr double overhead() { return double(sizeof(Entry)) + 16.0 / 0.875; }

 private:
  std::vector<Entry> entries_;
  std::vector<uint32_t> free_;
  absl::flat_hash_map<uint64_t, uint32_t> index_;
  uint32_t head_ = kNil, tail_ = kNil;
  uint64_t bytes_ = 0;
};

struct NoExtra {};

}  // namespace brickyard::policy_detail
