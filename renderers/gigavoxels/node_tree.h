#pragma once
/// @file node_tree.h
/// @brief GigaVoxels' GPU-side structure, kept as a GPU would hold it: a node pool of fixed
/// size in blocks of N^3 nodes (the children of a node are one block, so one pointer reaches all
/// of them), a brick pool of fixed size, and the loader's CPU-side bookkeeping beside them.
///
/// One node is 64 bits:
///   [63..35] child block + 1 (0: no children)   [34] max-refined   [33] constant
///   [32] has brick                               [31..0] brick slot, or the constant's float bits
/// Block 0 holds only the root (node address 0); brick slot 0 is the root's brick. Neither
/// ever takes part in replacement, so the root is never lost.
///
/// Replacement is GigaVoxels' two LRU caches with per-frame timestamps: the loader stamps the
/// blocks and bricks that this frame's compacted feedback names (and the blocks above them),
/// then end_of_feedback() sorts each pool's order by stamp, least recently used first (never
/// used: stamp 0), as the paper sorts its timestamps. Allocations take slots from the front and
/// never one stamped with the current frame, so nothing the current frame used is evicted. The
/// sort is by stamp, not a mere partition into this frame and the rest: a slot filled last
/// frame that this frame's lists happened not to name (lists are bounded) must still rank
/// after slots unused for longer, or two such nodes evict each other frame after frame. Nothing is ever collapsed explicitly: an evicted block's
/// parent loses its child pointer (it is refined again if rays ask), and the blocks below it,
/// no longer reachable, simply age out.
///
/// The tree manages brick slots, not voxels: the back end keeps the pool's voxels itself, in
/// the type its source delivers (a store's own type, 4x smaller than float for 8-bit data).
///
/// Thread safety: rays read node() concurrently while nothing writes; every other
/// member is the loader's and runs on one thread between passes.

#include <cstdint>
#include <cstring>
#include <vector>

#include "renderers/gigavoxels/procedural.h"  // NodeAddress

namespace brickyard::gigavoxels {

inline constexpr uint32_t kNoAddress = 0xffffffffu;

/// @brief One 64-bit node, decoded.
struct Node {
  uint64_t bits = 0;

  uint32_t child_block() const { return uint32_t(bits >> 35); }  ///< block + 1; 0: none
  bool has_children() const { return child_block() != 0; }
  bool max_refined() const { return bits & (uint64_t(1) << 34); }
  bool constant() const { return bits & (uint64_t(1) << 33); }
  bool has_brick() const { return bits & (uint64_t(1) << 32); }
  uint32_t brick() const { return uint32_t(bits); }
  float value() const {
    const uint32_t u = uint32_t(bits);
    float f;
    std::memcpy(&f, &u, 4);
    return f;
  }

  static Node make_constant(float v) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    return {(uint64_t(1) << 34) | (uint64_t(1) << 33) | u};
  }
  static Node make_data(bool max_refined) { return {max_refined ? uint64_t(1) << 34 : 0}; }
  void set_children(uint32_t block) { bits = (bits & ((uint64_t(1) << 35) - 1)) | (uint64_t(block + 1) << 35); }
  void clear_children() { bits &= (uint64_t(1) << 35) - 1; }
  void set_brick(uint32_t slot) { bits = (bits & ~uint64_t(0x1ffffffff)) | (uint64_t(1) << 32) | slot; }
  void clear_brick() { bits &= ~uint64_t(0x1ffffffff); }
};
static_assert(sizeof(Node) == 8);

struct PoolCounters {
  uint64_t subdivisions = 0, brick_uploads = 0;
  uint64_t block_evictions = 0, brick_evictions = 0;
  uint64_t failed_allocations = 0;  ///< everything was used this frame
};

class NodeTree {
 public:
  /// @param arity N (2 or 3); @param blocks node-pool blocks (the root's included);
  /// @param bricks brick-pool slots (the root's included); @param brick_size M (voxels per
  /// side without the 1-voxel border).
  NodeTree(int arity, uint32_t blocks, uint32_t bricks, int brick_size);

  int arity() const { return n_; }
  int block_nodes() const { return n3_; }
  int brick_size() const { return m_; }
  int brick_edge() const { return m_ + 2; }
  /// @brief Voxels per brick, (M + 2)^3.
  size_t brick_values() const { return brick_values_; }
  uint32_t block_capacity() const { return uint32_t(block_parent_.size()); }
  uint32_t brick_capacity() const { return uint32_t(brick_owner_.size()); }

  // --- read by rays ---------------------------------------------------------------------
  Node node(uint32_t address) const { return nodes_[address]; }
  uint32_t child_address(Node n, int child) const { return (n.child_block() - 1) * uint32_t(n3_) + uint32_t(child); }

  // --- the loader -----------------------------------------------------------------------
  /// @brief Starts a frame: timestamps below this are "not used this frame".
  void begin_feedback(uint64_t frame);
  /// @brief Usage feedback: the node, its brick, its block, and every block and brick above it
  /// were used.
  void mark_used(uint32_t address);
  /// @brief Re-sorts both pools by recency (stable sort by stamp, oldest first).
  void end_of_feedback();

  /// @brief Sets the root's content (block 0, node 0). Call once before rendering.
  void set_root(Node root, const NodeAddress& address);
  NodeAddress address_of(uint32_t node_address) const;
  /// @brief Whether the node at node_address is in the tree (reachable from the root) and is
  /// the node at `a` (a block's addresses are reused once it is evicted).
  bool holds(uint32_t node_address, const NodeAddress& a) const;
  /// @brief Gives the node a block of children (taken from the least recently used block not
  /// used this frame) and returns it, or kNoAddress when none can be taken. The caller fills
  /// the N^3 children with set_node().
  uint32_t subdivide(uint32_t address);
  void set_node(uint32_t address, Node n) { nodes_[address] = n; }
  /// @brief A brick slot for the node (least recently used, not used this frame), for the
  /// caller to fill in its voxel pool; kNoAddress when none can be taken.
  uint32_t allocate_brick(uint32_t address);
  /// @brief Whether allocate_brick() would find a slot (one not used this frame): asked before
  /// a brick is read or produced, so that a full pool costs no work.
  bool brick_slot_available();
  /// @brief Takes a slot out of replacement for good: an instanced brick that many nodes point
  /// to (evicting it would leave all but its owner pointing at other data).
  void keep_brick(uint32_t slot);

  // --- figures --------------------------------------------------------------------------
  uint32_t blocks_in_use() const { return blocks_in_use_; }
  uint32_t bricks_in_use() const { return bricks_in_use_; }
  /// @brief Blocks and bricks stamped with the current frame.
  uint32_t blocks_used_this_frame() const;
  uint32_t bricks_used_this_frame() const;
  uint64_t block_stamp(uint32_t block) const { return block_stamp_[block]; }
  uint64_t brick_stamp(uint32_t slot) const { return brick_stamp_[slot]; }
  uint64_t frame() const { return frame_; }
  const PoolCounters& counters() const { return counters_; }

 private:
  /// Takes the front of an LRU order unless it was used this frame; evicts what it held.
  uint32_t take_lru(std::vector<uint32_t>& order, size_t& cursor, const std::vector<uint64_t>& stamps);
  static void sort_by_recency(std::vector<uint32_t>& order, const std::vector<uint64_t>& stamps);

  int n_, n3_, m_;
  size_t brick_values_;
  std::vector<Node> nodes_;        // blocks * N^3
  // CPU side: what each block and brick belongs to, and their recency.
  std::vector<uint32_t> block_parent_;   // node address whose children the block is, kNoAddress: free
  std::vector<NodeAddress> block_base_;  // address of the block's first node (child 0)
  std::vector<uint32_t> brick_owner_;    // node address, kNoAddress: free
  std::vector<uint64_t> block_stamp_, brick_stamp_;
  std::vector<uint32_t> block_order_, brick_order_;  // least recently used first; the root's excluded
  size_t block_cursor_ = 0, brick_cursor_ = 0;
  uint32_t blocks_in_use_ = 1, bricks_in_use_ = 0;
  uint64_t frame_ = 1;
  NodeAddress root_address_;
  PoolCounters counters_;
};

}  // namespace brickyard::gigavoxels
