#include "dataset/octree.h"

#include <algorithm>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

OctreeLayout OctreeLayout::make(const Vec3s& dims, ValueType type) {
  if (dims.x < 1 || dims.y < 1 || dims.z < 1)
    throw Error(Errc::invalid_argument, fmt::format("an octree over an empty grid ({}x{}x{})", dims.x, dims.y, dims.z));
  OctreeLayout l;
  l.dims = dims;
  l.type = type;
  const int64_t n = std::max({dims.x, dims.y, dims.z});
  l.depth = 1;
  while ((int64_t(1) << l.depth) < n) ++l.depth;
  // A cap page's root is at D - 4 and an upper page's bottom level must reach its children, so
  // two levels is the least that keeps caps below an interior node.
  l.depth = std::max(l.depth, 2);
  if (l.depth > kOctreeMaxDepth)
    throw Error(Errc::invalid_argument, fmt::format("a grid of {} voxels per axis needs an octree of depth {}, deeper "
                                                    "than the {} its page keys address",
                                                    n, l.depth, kOctreeMaxDepth));
  l.max_page_bytes = l.largest_page_bytes();
  return l;
}

Vec3s OctreeLayout::level_dims(int s) const {
  const int64_t step = int64_t(1) << s;
  return {(dims.x + step - 1) / step, (dims.y + step - 1) / step, (dims.z + step - 1) / step};
}

Vec3s OctreeLayout::nodes_at(int d) const {
  const Vec3s v = level_dims(level_of_depth(d));
  return {(v.x + 1) / 2, (v.y + 1) / 2, (v.z + 1) / 2};
}

int OctreeLayout::page_root(int d) const {
  const int rc = cap_page_root();
  if (d >= rc) return rc;
  const int r = rc - kOctreeUpperPageDepths * ((rc - d + kOctreeUpperPageDepths - 1) / kOctreeUpperPageDepths);
  return std::max(r, 0);
}

int OctreeLayout::page_levels(int r) const {
  const int rc = cap_page_root();
  if (r == rc) return cap_depth() - rc;
  // The page below this one is rooted at the smallest root deeper than r.
  int next = rc;
  while (next - kOctreeUpperPageDepths > r) next -= kOctreeUpperPageDepths;
  return next - r;
}

size_t OctreeLayout::page_bytes(std::span<const uint32_t> nodes_per_level, uint32_t caps) const {
  size_t bytes = sizeof(OctreePageHeader);
  for (uint32_t n : nodes_per_level) bytes += size_t(n) * (sizeof(OctreeNode) + scalar_bytes());
  return bytes + size_t(caps) * scalar_bytes();
}

size_t OctreeLayout::largest_page_bytes() const {
  // Every page is at most full: 8^l nodes at its level l, and 8 caps under each bottom node.
  size_t largest = 0;
  for (int r = 0; r <= cap_page_root(); ++r) {
    if (!is_page_root(r)) continue;
    std::array<uint32_t, 4> nodes{};
    const int levels = page_levels(r);
    uint32_t count = 1;
    for (int l = 0; l < levels; ++l, count *= 8) nodes[size_t(l)] = count;
    const uint32_t caps = r == cap_page_root() ? count : 0;
    largest = std::max(largest, page_bytes(std::span(nodes.data(), size_t(levels)), caps));
  }
  return largest;
}

template <typename T>
OctreePage<T> OctreePage<T>::view(std::span<const std::byte> bytes, const OctreeLayout& layout) {
  OctreePage page;
  if (bytes.size() < sizeof(OctreePageHeader)) throw Error(Errc::corrupt, "octree page shorter than its header");
  page.header = reinterpret_cast<const OctreePageHeader*>(bytes.data());
  const OctreePageHeader& h = *page.header;
  if (h.magic != kOctreePageMagic) throw Error(Errc::corrupt, "octree page without its magic");
  if (h.value_type != uint8_t(ValueTypeOf<T>::value))
    throw Error(Errc::corrupt, fmt::format("octree page of value type {}, the octree's is {}", h.value_type,
                                           to_string(ValueTypeOf<T>::value)));
  if (h.root_depth > layout.cap_page_root() || !layout.is_page_root(h.root_depth) ||
      h.levels != layout.page_levels(h.root_depth) || bool(h.has_caps) != (h.root_depth == layout.cap_page_root()))
    throw Error(Errc::corrupt, fmt::format("octree page rooted at depth {} with {} levels{} does not fit an octree of "
                                           "depth {}", h.root_depth, h.levels, h.has_caps ? " and caps" : "",
                                           layout.depth));
  const size_t need = layout.page_bytes(std::span(h.nodes, size_t(h.levels)), h.caps);
  if (need > bytes.size())
    throw Error(Errc::corrupt, fmt::format("octree page counts need {} bytes, the page has {}", need, bytes.size()));
  const std::byte* p = bytes.data() + sizeof(OctreePageHeader);
  for (int l = 0; l < h.levels; ++l) {
    page.nodes[size_t(l)] = reinterpret_cast<const OctreeNode*>(p);
    p += size_t(h.nodes[l]) * sizeof(OctreeNode);
    page.scalars[size_t(l)] = reinterpret_cast<const T*>(p);
    p += size_t(h.nodes[l]) * 8 * sizeof(T);
  }
  page.caps = reinterpret_cast<const T*>(p);
  return page;
}

template struct OctreePage<uint8_t>;
template struct OctreePage<int8_t>;
template struct OctreePage<int16_t>;
template struct OctreePage<uint16_t>;
template struct OctreePage<float>;

const OctreePageRange* OctreeView::page(uint64_t id) const {
  auto it = std::lower_bound(pages_.begin(), pages_.end(), id, [](const OctreePageRange& p, uint64_t v) { return p.id < v; });
  return it != pages_.end() && it->id == id ? &*it : nullptr;
}

std::string describe_octree_page(uint64_t id) {
  const BrickKey k = BrickKey::from_code(id);
  return fmt::format("octree page depth {} ({}, {}, {})", k.level, k.x, k.y, k.z);
}

}  // namespace brickyard
