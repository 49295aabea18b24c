// The build of the `gobbetti` spatial index: a hash table of the cut's families (an inner
// node's 8 children: leaf with payload, inner, or nothing), a breadth-first pass that lays out
// the nodes with one probe per inner node, and a second pass that derives every node's links
// from its parent's. O(nodes); all storage is reused from frame to frame.

#include "renderers/gobbetti/spatial_index.h"

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard::gobbetti {

namespace {

constexpr uint64_t kEmptyCode = ~0ull;  // bit 63 of a BrickKey code is always zero
/// What a family record says of one child.
constexpr uint32_t kChildNone = 0, kChildLeaf = 1, kChildInner = 2;
/// Inner node whose children are not laid out yet (only during the breadth-first pass).
constexpr uint32_t kInnerPending = 0;

size_t slot_of(uint64_t code, int shift) { return size_t((code * 0x9e3779b97f4a7c15ull) >> shift); }
/// Which child of its parent a brick is: 0..7 in BrickKey::child order.
int child_index(const BrickKey& k) { return int((k.x & 1) | ((k.y & 1) << 1) | ((k.z & 1) << 2)); }
uint32_t child_kind(uint32_t kinds, int c) { return (kinds >> (2 * c)) & 3; }

Error cut_error(const std::string& what) { return Error(Errc::invalid_argument, "invalid cut: " + what); }

}  // namespace

// --- hash table of the cut's families ----------------------------------------------------

void SpatialIndex::table_reset(size_t expected) {
  size_t capacity = 64;
  int bits = 6;
  while (capacity < 2 * expected) capacity <<= 1, ++bits;  // load factor <= 1/2
  table_.assign(capacity, Family{kEmptyCode, 0, {}});
  table_shift_ = 64 - bits;
  table_used_ = 0;
}

SpatialIndex::Family* SpatialIndex::table_find(uint64_t code) {
  const size_t mask = table_.size() - 1;
  for (size_t i = slot_of(code, table_shift_);; i = (i + 1) & mask) {
    if (table_[i].code == code) return &table_[i];
    if (table_[i].code == kEmptyCode) return nullptr;
  }
}

SpatialIndex::Family* SpatialIndex::table_insert(uint64_t code, bool& inserted) {
  if (2 * (table_used_ + 1) > table_.size()) table_grow();
  const size_t mask = table_.size() - 1;
  for (size_t i = slot_of(code, table_shift_);; i = (i + 1) & mask) {
    if (table_[i].code == code) {
      inserted = false;
      return &table_[i];
    }
    if (table_[i].code == kEmptyCode) {
      table_[i].code = code;
      table_[i].kinds = 0;
      ++table_used_;
      inserted = true;
      return &table_[i];
    }
  }
}

void SpatialIndex::table_grow() {
  table_spare_.swap(table_);
  const size_t used = table_used_;
  table_reset(table_spare_.size());  // doubles: capacity >= 2 * old capacity
  const size_t mask = table_.size() - 1;
  for (const Family& f : table_spare_) {
    if (f.code == kEmptyCode) continue;
    size_t i = slot_of(f.code, table_shift_);
    while (table_[i].code != kEmptyCode) i = (i + 1) & mask;
    table_[i] = f;
  }
  table_used_ = used;
}

// --- build ---------------------------------------------------------------------------

void SpatialIndex::build(const GridLayout& layout, std::span<const CutLeaf> leaves) {
  if (layout.levels < 1 || layout.levels > kMaxLevels)
    throw Error(Errc::invalid_argument, fmt::format("spatial index: {} levels (1..{} supported)", layout.levels, kMaxLevels));
  levels_ = layout.levels;
  for (int l = 0; l < levels_; ++l) scale_[l] = std::ldexp(double(layout.brick_size), levels_ - 1 - l);
  scale_[levels_] = scale_[levels_ - 1] / 2;
  max_steps_ = (uint64_t(3) << (levels_ - 1)) + 4;
  Vec3s bricks[kMaxLevels];  // layout.contains() divides; this table does not
  for (int l = 0; l < levels_; ++l) bricks[l] = layout.level_bricks(l);
  auto contains = [&](const BrickKey& k) {
    const Vec3s& b = bricks[k.level];
    return int64_t(k.x) < b.x && int64_t(k.y) < b.y && int64_t(k.z) < b.z;
  };
  nodes_.clear();
  keys_.clear();
  cut_leaves_ = outside_leaves_ = 0;
  if (leaves.empty()) throw cut_error("it has no leaves: brick L0 (0, 0, 0) is covered by no leaf");

  // Step 1: each leaf goes into its parent's family record. A new record makes the parent an
  // inner node of the grandparent's record, and so on up until a record already exists: the
  // walks together touch each inner node once. A leaf meeting an inner node in its slot, or
  // an inner node meeting a leaf, is an overlap.
  table_reset(leaves.size() / 7 + 16);
  const CutLeaf* root_leaf = nullptr;
  for (const CutLeaf& leaf : leaves) {
    if (!leaf.key.valid() || int(leaf.key.level) >= levels_ || !contains(leaf.key))
      throw cut_error(fmt::format("leaf {} is not a brick of the layout", leaf.key.to_string()));
    if (leaf.key.level == 0) {
      if (root_leaf) throw cut_error(fmt::format("leaf {} is given twice", leaf.key.to_string()));
      root_leaf = &leaf;
      continue;
    }
    bool inserted = false;
    Family* family = table_insert(leaf.key.parent().code(), inserted);
    const int c = child_index(leaf.key);
    const uint32_t kind = child_kind(family->kinds, c);
    if (kind == kChildLeaf) throw cut_error(fmt::format("leaf {} is given twice", leaf.key.to_string()));
    if (kind == kChildInner) throw cut_error(fmt::format("leaves overlap: leaf {} holds other leaves", leaf.key.to_string()));
    family->kinds |= kChildLeaf << (2 * c);
    family->payload[c] = leaf.payload;
    for (BrickKey k = leaf.key.parent(); inserted && k.level > 0; k = k.parent()) {
      Family* up = table_insert(k.parent().code(), inserted);
      const int ck = child_index(k);
      if (child_kind(up->kinds, ck) == kChildLeaf)
        throw cut_error(fmt::format("leaves overlap: leaf {} lies inside leaf {}", leaf.key.to_string(), k.to_string()));
      up->kinds |= kChildInner << (2 * ck);
    }
  }
  if (root_leaf && leaves.size() > 1) {
    const CutLeaf& other = &leaves[0] == root_leaf ? leaves[1] : leaves[0];
    throw cut_error(fmt::format("leaves overlap: leaf {} lies inside leaf {}", other.key.to_string(), root_leaf->key.to_string()));
  }

  // Step 2: breadth-first layout; the node array itself is the queue. A child that is a
  // brick of the layout must be a leaf or an inner node of the cut, or nothing covers it.
  nodes_.push_back(Node{root_leaf ? kLeafTag : kInnerPending, root_leaf ? root_leaf->payload : 0, {}});
  keys_.push_back(BrickKey{});
  for (uint32_t i = 0; i < nodes_.size(); ++i) {
    if (nodes_[i].child != kInnerPending) continue;
    const uint32_t first = uint32_t(nodes_.size());
    if (size_t(first) + 8 > kMaxNodes)
      throw Error(Errc::resource, fmt::format("spatial index: more than {} nodes", kMaxNodes));
    nodes_[i].child = first;
    const BrickKey parent = keys_[i];
    const Family* family = table_find(parent.code());
    BY_CHECK(family != nullptr);
    for (int c = 0; c < 8; ++c) {
      const BrickKey k = parent.child(c);
      keys_.push_back(k);
      const uint32_t kind = child_kind(family->kinds, c);
      if (kind == kChildLeaf) {
        nodes_.push_back(Node{kLeafTag, family->payload[c], {}});
      } else if (kind == kChildInner) {
        nodes_.push_back(Node{kInnerPending, 0, {}});
      } else if (!contains(k)) {
        nodes_.push_back(Node{kOutsideTag, kOutsidePayload, {}});
        ++outside_leaves_;
      } else {
        throw cut_error(fmt::format("brick {} is covered by no leaf", k.to_string()));
      }
    }
  }
  cut_leaves_ = uint32_t(nodes_.size()) - outside_leaves_ - (uint32_t(nodes_.size()) - 1) / 8;
  BY_CHECK_EQ(size_t(cut_leaves_), leaves.size());
  compute_links();
}

void SpatialIndex::compute_links() {
  for (uint32_t& l : nodes_[0].links) l = kNullLink;
  // Parents come before children, so a node's links are final when its children need them.
  // A link is either a node at the linking node's level or a coarser leaf; so when a parent's
  // link names an inner node, that node's children lie at the children's level.
  for (uint32_t i = 0; i < nodes_.size(); ++i) {
    const Node& parent = nodes_[i];
    if (parent.child >= kOutsideTag) continue;
    const uint32_t first = parent.child;
    const int level = int(keys_[i].level) + 1;
    for (uint32_t c = 0; c < 8; ++c) {
      Node& child = nodes_[first + c];
      for (int a = 0; a < 3; ++a) {
        const uint32_t bit = 1u << a;
        const uint32_t sibling = make_link(first + (c ^ bit), level);
        const int inner_face = (c & bit) ? 2 * a : 2 * a + 1;  // the face towards the sibling
        const int outer_face = inner_face ^ 1;
        child.links[inner_face] = sibling;
        const uint32_t across = parent.links[outer_face];
        if (across != kNullLink && nodes_[link_index(across)].child < kOutsideTag)
          child.links[outer_face] = make_link(nodes_[link_index(across)].child + (c ^ bit), level);
        else
          child.links[outer_face] = across;  // null, or a leaf at the parent's level or coarser
      }
    }
  }
}

Box3d SpatialIndex::box(uint32_t i) const {
  const BrickKey& k = keys_[i];
  const double s = scale_[k.level];
  const Vec3d lo(double(k.x) * s, double(k.y) * s, double(k.z) * s);
  return {lo, lo + Vec3d(s)};
}

size_t SpatialIndex::bytes() const {
  return nodes_.capacity() * sizeof(Node) + keys_.capacity() * sizeof(BrickKey) +
         (table_.capacity() + table_spare_.capacity()) * sizeof(Family);
}

}  // namespace brickyard::gobbetti
