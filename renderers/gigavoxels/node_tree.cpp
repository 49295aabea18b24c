#include "renderers/gigavoxels/node_tree.h"

#include <algorithm>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard::gigavoxels {

NodeTree::NodeTree(int arity, uint32_t blocks, uint32_t bricks, int brick_size) : n_(arity), m_(brick_size) {
  if (arity != 2 && arity != 3)
    throw Error(Errc::invalid_argument, fmt::format("gigavoxels: arity {} is not supported (2 or 3)", arity));
  if (brick_size < 2)
    throw Error(Errc::invalid_argument, fmt::format("gigavoxels: brick size {} is too small", brick_size));
  if (blocks < 2 || bricks < 2)
    throw Error(Errc::invalid_argument,
                fmt::format("gigavoxels: pools of {} blocks and {} bricks are too small (at least 2 of each)", blocks, bricks));
  if (blocks >= (uint32_t(1) << 29) / 27)
    throw Error(Errc::invalid_argument, fmt::format("gigavoxels: {} node blocks exceed the 29-bit child pointer", blocks));
  n3_ = n_ * n_ * n_;
  brick_values_ = size_t(m_ + 2) * size_t(m_ + 2) * size_t(m_ + 2);
  nodes_.assign(size_t(blocks) * size_t(n3_), Node{});
  block_parent_.assign(blocks, kNoAddress);
  block_base_.assign(blocks, NodeAddress{});
  brick_owner_.assign(bricks, kNoAddress);
  block_stamp_.assign(blocks, 0);
  brick_stamp_.assign(bricks, 0);
  for (uint32_t b = 1; b < blocks; ++b) block_order_.push_back(b);
  for (uint32_t s = 1; s < bricks; ++s) brick_order_.push_back(s);
  brick_owner_[0] = 0;
}

void NodeTree::set_root(Node root, const NodeAddress& address) {
  nodes_[0] = root;
  root_address_ = address;
  block_base_[0] = address;
}

NodeAddress NodeTree::address_of(uint32_t node_address) const {
  const uint32_t block = node_address / uint32_t(n3_);
  if (block == 0) return root_address_;
  const int i = int(node_address % uint32_t(n3_));
  NodeAddress a = block_base_[block];
  a.x += i % n_;
  a.y += (i / n_) % n_;
  a.z += i / (n_ * n_);
  return a;
}

bool NodeTree::holds(uint32_t node_address, const NodeAddress& a) const {
  const uint32_t first = node_address / uint32_t(n3_);
  if (first >= block_parent_.size()) return false;
  if (first == 0) return node_address == 0 && a == root_address_;
  if (address_of(node_address) != a) return false;
  // Up to the root, each block still its parent's children: a block whose parent's block was
  // taken is not freed with it, and keeps its parent and base until it is taken itself. The
  // chain is a.depth - root depth blocks long; a longer one is not this node's.
  uint32_t block = first;
  for (int steps = a.depth - root_address_.depth; block != 0 && steps > 0; --steps) {
    const uint32_t parent = block_parent_[block];
    if (parent == kNoAddress || !nodes_[parent].has_children() || nodes_[parent].child_block() - 1 != block) return false;
    block = parent / uint32_t(n3_);
  }
  return block == 0;
}

void NodeTree::begin_feedback(uint64_t frame) {
  frame_ = frame;
  block_cursor_ = brick_cursor_ = 0;
}

void NodeTree::mark_used(uint32_t address) {
  const auto stamp_brick = [&](uint32_t node) {
    const Node n = nodes_[node];
    if (n.has_brick()) brick_stamp_[n.brick()] = frame_;
  };
  stamp_brick(address);
  // The blocks above, so that a used node stays reachable, and the bricks above, which rays
  // blend with (quadrilinear filtering reads up to two coarser levels) but do not name.
  for (uint32_t block = address / uint32_t(n3_); block != 0;) {
    if (block_stamp_[block] == frame_) break;  // this chain is stamped already
    block_stamp_[block] = frame_;
    const uint32_t parent = block_parent_[block];
    if (parent == kNoAddress) break;
    stamp_brick(parent);
    block = parent / uint32_t(n3_);
  }
}

bool NodeTree::brick_slot_available() {
  while (brick_cursor_ < brick_order_.size() && brick_stamp_[brick_order_[brick_cursor_]] == frame_) ++brick_cursor_;
  if (brick_cursor_ < brick_order_.size()) return true;
  ++counters_.failed_allocations;
  return false;
}

void NodeTree::sort_by_recency(std::vector<uint32_t>& order, const std::vector<uint64_t>& stamps) {
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return stamps[a] < stamps[b]; });
}

void NodeTree::end_of_feedback() {
  sort_by_recency(block_order_, block_stamp_);
  sort_by_recency(brick_order_, brick_stamp_);
  block_cursor_ = brick_cursor_ = 0;
}

uint32_t NodeTree::take_lru(std::vector<uint32_t>& order, size_t& cursor, const std::vector<uint64_t>& stamps) {
  // The order is partitioned at end_of_feedback(); slots taken since are stamped with this
  // frame and stay where they are until the next partition, so the cursor skips them.
  while (cursor < order.size()) {
    const uint32_t s = order[cursor++];
    if (stamps[s] != frame_) return s;
  }
  ++counters_.failed_allocations;
  return kNoAddress;
}

uint32_t NodeTree::subdivide(uint32_t address) {
  const uint32_t block = take_lru(block_order_, block_cursor_, block_stamp_);
  if (block == kNoAddress) return kNoAddress;
  // Evict: the previous parent loses its children if they are still these.
  const uint32_t old_parent = block_parent_[block];
  if (old_parent != kNoAddress) {
    Node p = nodes_[old_parent];
    if (p.child_block() == block + 1) {
      p.clear_children();
      nodes_[old_parent] = p;
    }
    ++counters_.block_evictions;
  } else {
    ++blocks_in_use_;
  }
  const NodeAddress parent = address_of(address);
  block_parent_[block] = address;
  block_base_[block] = {parent.depth + 1, parent.x * n_, parent.y * n_, parent.z * n_};
  block_stamp_[block] = frame_;
  std::fill_n(nodes_.begin() + std::ptrdiff_t(size_t(block) * size_t(n3_)), n3_, Node{});
  Node p = nodes_[address];
  p.set_children(block);
  nodes_[address] = p;
  ++counters_.subdivisions;
  return block * uint32_t(n3_);
}

uint32_t NodeTree::allocate_brick(uint32_t address) {
  uint32_t slot = 0;
  if (address != 0) {
    slot = take_lru(brick_order_, brick_cursor_, brick_stamp_);
    if (slot == kNoAddress) return kNoAddress;
    const uint32_t old_owner = brick_owner_[slot];
    if (old_owner != kNoAddress) {
      Node o = nodes_[old_owner];
      if (o.has_brick() && o.brick() == slot) {
        o.clear_brick();
        nodes_[old_owner] = o;
      }
      ++counters_.brick_evictions;
    } else {
      ++bricks_in_use_;
    }
  } else if (!nodes_[0].has_brick()) {
    ++bricks_in_use_;
  }
  brick_owner_[slot] = address;
  brick_stamp_[slot] = frame_;
  Node n = nodes_[address];
  n.set_brick(slot);
  nodes_[address] = n;
  ++counters_.brick_uploads;
  return slot;
}

void NodeTree::keep_brick(uint32_t slot) {
  auto it = std::find(brick_order_.begin(), brick_order_.end(), slot);
  if (it == brick_order_.end()) return;
  const size_t at = size_t(it - brick_order_.begin());
  brick_order_.erase(it);
  if (at < brick_cursor_) --brick_cursor_;
  brick_owner_[slot] = kNoAddress;
}

uint32_t NodeTree::blocks_used_this_frame() const {
  return uint32_t(std::count(block_stamp_.begin() + 1, block_stamp_.end(), frame_));
}
uint32_t NodeTree::bricks_used_this_frame() const {
  return uint32_t(std::count(brick_stamp_.begin() + 1, brick_stamp_.end(), frame_));
}

}  // namespace brickyard::gigavoxels
