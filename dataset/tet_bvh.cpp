#include "dataset/tet_bvh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <cstring>

#include <fmt/format.h>

#include "core/error.h"
#include "core/math.h"

namespace brickyard::tet_bvh {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

struct Builder {
  const std::vector<Bounds4>& items;
  BuildMethod method;
  uint32_t leaf_size;
  BoxBvh out;
  std::vector<float> centre;  // 3 per item

  Bounds4 bounds_of(size_t begin, size_t end) const {
    Bounds4 b;
    for (int a = 0; a < 4; ++a) b.lo[a] = kInf, b.hi[a] = -kInf;
    for (size_t i = begin; i < end; ++i) {
      const Bounds4& t = items[out.order[i]];
      for (int a = 0; a < 4; ++a) b.lo[a] = std::min(b.lo[a], t.lo[a]), b.hi[a] = std::max(b.hi[a], t.hi[a]);
    }
    return b;
  }
  float c(uint32_t item, int axis) const { return centre[size_t(item) * 3 + size_t(axis)]; }

  /// Where to split [begin, end) and along which axis; mid == begin or end means no split.
  size_t split(size_t begin, size_t end, int& axis) {
    float clo[3] = {kInf, kInf, kInf}, chi[3] = {-kInf, -kInf, -kInf};
    for (size_t i = begin; i < end; ++i)
      for (int a = 0; a < 3; ++a) clo[a] = std::min(clo[a], c(out.order[i], a)), chi[a] = std::max(chi[a], c(out.order[i], a));
    if (method == BuildMethod::sah) return sah_split(begin, end, clo, chi, axis);
    // BIH-style: the middle of the centres' box along its longest axis (the node's own box
    // comes from its children afterwards, so no pass over the items is spent on it here).
    axis = 0;
    for (int a = 1; a < 3; ++a)
      if (chi[a] - clo[a] > chi[axis] - clo[axis]) axis = a;
    const float plane = 0.5f * (clo[axis] + chi[axis]);
    auto mid = std::partition(out.order.begin() + long(begin), out.order.begin() + long(end),
                              [&](uint32_t i) { return c(i, axis) < plane; });
    return size_t(mid - out.order.begin());
  }

  size_t sah_split(size_t begin, size_t end, const float* clo, const float* chi, int& best_axis) {
    constexpr int kBins = 16;
    double best = std::numeric_limits<double>::infinity();
    int best_bin = -1;
    best_axis = -1;
    auto area = [](const Bounds4& b) {
      const double x = std::max(0.0f, b.hi[0] - b.lo[0]), y = std::max(0.0f, b.hi[1] - b.lo[1]),
                   z = std::max(0.0f, b.hi[2] - b.lo[2]);
      return x * y + y * z + z * x;
    };
    for (int a = 0; a < 3; ++a) {
      const float extent = chi[a] - clo[a];
      if (!(extent > 0)) continue;
      std::array<Bounds4, kBins> bins;
      std::array<uint32_t, kBins> counts{};
      for (auto& bin : bins)
        for (int k = 0; k < 4; ++k) bin.lo[k] = kInf, bin.hi[k] = -kInf;
      for (size_t i = begin; i < end; ++i) {
        const uint32_t it = out.order[i];
        const int bin = std::min(kBins - 1, int((c(it, a) - clo[a]) / extent * kBins));
        ++counts[size_t(bin)];
        for (int k = 0; k < 4; ++k)
          bins[size_t(bin)].lo[k] = std::min(bins[size_t(bin)].lo[k], items[it].lo[k]),
          bins[size_t(bin)].hi[k] = std::max(bins[size_t(bin)].hi[k], items[it].hi[k]);
      }
      // Sweep: cost of splitting after bin s = left count * left area + right count * right area.
      std::array<double, kBins> left_cost{};
      Bounds4 acc = bins[0];
      uint32_t n = 0;
      for (int s = 0; s < kBins - 1; ++s) {
        if (s > 0)
          for (int k = 0; k < 4; ++k) acc.lo[k] = std::min(acc.lo[k], bins[size_t(s)].lo[k]), acc.hi[k] = std::max(acc.hi[k], bins[size_t(s)].hi[k]);
        n += counts[size_t(s)];
        left_cost[size_t(s)] = n ? double(n) * area(acc) : 0;
      }
      acc = bins[kBins - 1];
      n = 0;
      for (int s = kBins - 1; s > 0; --s) {
        if (s < kBins - 1)
          for (int k = 0; k < 4; ++k) acc.lo[k] = std::min(acc.lo[k], bins[size_t(s)].lo[k]), acc.hi[k] = std::max(acc.hi[k], bins[size_t(s)].hi[k]);
        n += counts[size_t(s)];
        const double cost = left_cost[size_t(s - 1)] + (n ? double(n) * area(acc) : 0);
        if (n > 0 && n < end - begin && cost < best) best = cost, best_bin = s, best_axis = a;
      }
    }
    if (best_axis < 0) {
      best_axis = 0;
      return begin;  // every centre in one place: the caller splits by count
    }
    const float extent = chi[best_axis] - clo[best_axis];
    auto mid = std::partition(out.order.begin() + long(begin), out.order.begin() + long(end), [&](uint32_t i) {
      return std::min(kBins - 1, int((c(i, best_axis) - clo[best_axis]) / extent * kBins)) < best_bin;
    });
    return size_t(mid - out.order.begin());
  }

  /// Builds the subtree over [begin, end); its bounds go to `bounds`.
  uint32_t node(size_t begin, size_t end, Bounds4& bounds) {
    const uint32_t index = uint32_t(out.nodes.size());
    out.nodes.emplace_back();
    BvhNode n;
    if (end - begin <= leaf_size) {
      bounds = bounds_of(begin, end);
      n.index = uint32_t(begin), n.count = uint16_t(end - begin);
    } else {
      int axis = 0;
      size_t mid = split(begin, end, axis);
      if (mid == begin || mid == end) {  // every centre on one side: split by count along the axis
        mid = begin + (end - begin) / 2;
        std::nth_element(out.order.begin() + long(begin), out.order.begin() + long(mid), out.order.begin() + long(end),
                         [&](uint32_t x, uint32_t y) { return c(x, axis) < c(y, axis) || (c(x, axis) == c(y, axis) && x < y); });
      }
      Bounds4 right;
      node(begin, mid, bounds);
      n.index = node(mid, end, right);
      n.axis = uint16_t(axis);
      for (int a = 0; a < 4; ++a) bounds.lo[a] = std::min(bounds.lo[a], right.lo[a]), bounds.hi[a] = std::max(bounds.hi[a], right.hi[a]);
    }
    std::copy(bounds.lo, bounds.lo + 4, n.lo);
    std::copy(bounds.hi, bounds.hi + 4, n.hi);
    out.nodes[index] = n;
    return index;
  }
};

}  // namespace

BoxBvh build_bvh(const std::vector<Bounds4>& items, BuildMethod method, uint32_t leaf_size) {
  Builder b{items, method, std::max(1u, leaf_size), {}, {}};
  b.out.order.resize(items.size());
  b.centre.resize(items.size() * 3);
  for (size_t i = 0; i < items.size(); ++i) {
    b.out.order[i] = uint32_t(i);
    for (int a = 0; a < 3; ++a) b.centre[i * 3 + size_t(a)] = 0.5f * (items[i].lo[a] + items[i].hi[a]);
  }
  Bounds4 root;
  if (!items.empty()) b.node(0, items.size(), root);
  return std::move(b.out);
}

namespace {

/// Tet t's {x, y, z, value} bounds at `step`; false when it must stay out of the BVH (not
/// positively oriented, not finite, or corners outside the page): stores keep only valid
/// tets, and a page from anywhere else must not bring a degenerate one in.
bool tet_bounds(const TetClusterPage& page, const float* pos, const float* val, uint32_t t, Bounds4& b) {
  const uint32_t* q = page.corners + 4 * size_t(t);
  for (int a = 0; a < 4; ++a) b.lo[a] = kInf, b.hi[a] = -kInf;
  Vec3d p[4];
  bool finite = true;
  for (int k = 0; k < 4; ++k) {
    if (q[k] >= page.vertex_count) return false;
    const float* v = pos + 3 * size_t(q[k]);
    p[k] = Vec3d(v[0], v[1], v[2]);
    for (int a = 0; a < 3; ++a) b.lo[a] = std::min(b.lo[a], v[a]), b.hi[a] = std::max(b.hi[a], v[a]);
    b.lo[3] = std::min(b.lo[3], val[q[k]]), b.hi[3] = std::max(b.hi[3], val[q[k]]);
    finite = finite && std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]) && std::isfinite(val[q[k]]);
  }
  return finite && dot(cross(p[1] - p[0], p[2] - p[0]), p[3] - p[0]) > 0;
}

void unite(float* lo, float* hi, const float* olo, const float* ohi) {
  for (int a = 0; a < 4; ++a) lo[a] = std::min(lo[a], olo[a]), hi[a] = std::max(hi[a], ohi[a]);
}

}  // namespace

void refit_bvh(BoxBvh& bvh, const Bounds4* slot_bounds) {
  // Nodes are in depth-first order with the left child next: walking them backwards meets
  // every child before its parent.
  for (size_t i = bvh.nodes.size(); i-- > 0;) {
    BvhNode& n = bvh.nodes[i];
    for (int a = 0; a < 4; ++a) n.lo[a] = kInf, n.hi[a] = -kInf;
    if (n.leaf()) {
      for (uint32_t s = n.index; s < n.index + n.count; ++s) unite(n.lo, n.hi, slot_bounds[s].lo, slot_bounds[s].hi);
    } else {
      unite(n.lo, n.hi, bvh.nodes[i + 1].lo, bvh.nodes[i + 1].hi);
      unite(n.lo, n.hi, bvh.nodes[n.index].lo, bvh.nodes[n.index].hi);
    }
  }
}

ClusterBvh ClusterBvh::build(const TetClusterPage& page, uint32_t step, BuildMethod method, uint32_t leaf_size) {
  const float* pos = page.positions_at(step);
  const float* val = page.values_at(step);
  std::vector<Bounds4> items;
  std::vector<uint32_t> tet_of;  // item -> tet
  items.reserve(page.tet_count);
  ClusterBvh out;
  out.step = step;
  for (uint32_t t = 0; t < page.tet_count; ++t) {
    Bounds4 b;
    if (!tet_bounds(page, pos, val, t, b)) {
      ++out.skipped;
      continue;
    }
    items.push_back(b);
    tet_of.push_back(t);
  }
  out.bvh = build_bvh(items, method, leaf_size);
  out.tet_range.resize(items.size() * 2);
  for (size_t s = 0; s < out.bvh.order.size(); ++s) {
    const uint32_t item = out.bvh.order[s];
    out.tet_range[2 * s] = items[item].lo[3];
    out.tet_range[2 * s + 1] = items[item].hi[3];
    out.bvh.order[s] = tet_of[item];
  }
  return out;
}

std::optional<ClusterBvh> ClusterBvh::refit(const TetClusterPage& page, uint32_t new_step) const {
  const float* pos = page.positions_at(new_step);
  const float* val = page.values_at(new_step);
  const size_t slots = bvh.order.size();
  if (slots + skipped != page.tet_count) return std::nullopt;
  std::vector<Bounds4> slot_bounds(slots);
  for (size_t s = 0; s < slots; ++s)
    if (bvh.order[s] >= page.tet_count || !tet_bounds(page, pos, val, bvh.order[s], slot_bounds[s])) return std::nullopt;
  if (skipped > 0) {  // a tet left out at the build step must still be invalid at this one
    std::vector<uint8_t> in_bvh(page.tet_count, 0);
    for (uint32_t t : bvh.order) in_bvh[t] = 1;
    Bounds4 b;
    for (uint32_t t = 0; t < page.tet_count; ++t)
      if (!in_bvh[t] && tet_bounds(page, pos, val, t, b)) return std::nullopt;
  }
  ClusterBvh out;
  out.bvh = bvh;
  out.skipped = skipped;
  out.step = new_step;
  refit_bvh(out.bvh, slot_bounds.data());
  out.tet_range.resize(slots * 2);
  for (size_t s = 0; s < slots; ++s) out.tet_range[2 * s] = slot_bounds[s].lo[3], out.tet_range[2 * s + 1] = slot_bounds[s].hi[3];
  return out;
}

namespace {
constexpr uint32_t kStoredMagic = 0x31564254;  // "TBV1"
constexpr size_t kStoredHeader = 6 * sizeof(uint32_t);
size_t padding(size_t offset) { return (8 - offset % 8) % 8; }
}  // namespace

std::vector<std::byte> ClusterBvh::encode(size_t page_size, BuildMethod method, uint32_t leaf_size) const {
  const size_t pad = padding(page_size), slots = bvh.order.size();
  std::vector<std::byte> out(pad + kStoredHeader + bvh.nodes.size() * sizeof(BvhNode) + slots * 3 * sizeof(uint32_t));
  std::byte* p = out.data() + pad;
  const uint32_t header[6] = {kStoredMagic, uint32_t(method), leaf_size, uint32_t(bvh.nodes.size()), uint32_t(slots), skipped};
  std::memcpy(p, header, sizeof header);
  p += sizeof header;
  std::memcpy(p, bvh.nodes.data(), bvh.nodes.size() * sizeof(BvhNode));
  p += bvh.nodes.size() * sizeof(BvhNode);
  std::memcpy(p, bvh.order.data(), slots * sizeof(uint32_t));
  p += slots * sizeof(uint32_t);
  std::memcpy(p, tet_range.data(), tet_range.size() * sizeof(float));
  return out;
}

std::optional<ClusterBvh> ClusterBvh::stored(const TetClusterPage& page, BuildMethod method, uint32_t leaf_size) {
  const std::span<const std::byte> tail = page.tail;
  const size_t start = padding(TetClusterPage::bytes(page.vertex_count, page.tet_count, page.steps, page.position_sets));
  if (tail.size() < start + kStoredHeader) return std::nullopt;
  uint32_t h[6];
  std::memcpy(h, tail.data() + start, sizeof h);
  if (h[0] != kStoredMagic) return std::nullopt;  // zeros: the page holds none
  if (h[1] != uint32_t(method) || h[2] != leaf_size) return std::nullopt;
  const size_t nodes = h[3], slots = h[4];
  auto bad = [&](const std::string& what) { return Error(Errc::corrupt, "the cluster's stored BVH " + what); };
  if (slots + h[5] != page.tet_count)
    throw bad(fmt::format("holds {} tets and leaves out {}, the page has {}", slots, h[5], page.tet_count));
  if (nodes > slots * 2 + 1 || tail.size() < start + kStoredHeader + nodes * sizeof(BvhNode) + slots * 3 * sizeof(uint32_t))
    throw bad(fmt::format("of {} nodes and {} slots does not fit in the page's {} bytes after its tets", nodes, slots,
                          tail.size()));
  ClusterBvh out;
  out.skipped = h[5];
  out.bvh.nodes.resize(nodes);
  out.bvh.order.resize(slots);
  out.tet_range.resize(slots * 2);
  const std::byte* p = tail.data() + start + kStoredHeader;
  std::memcpy(out.bvh.nodes.data(), p, nodes * sizeof(BvhNode));
  p += nodes * sizeof(BvhNode);
  std::memcpy(out.bvh.order.data(), p, slots * sizeof(uint32_t));
  p += slots * sizeof(uint32_t);
  std::memcpy(out.tet_range.data(), p, slots * 2 * sizeof(float));
  // A tree, as the builder lays it out: every node but the root one parent, children after
  // their parent, the leaves in node order covering the slots one after the other, no deeper
  // than traversal's stack; every slot a distinct valid tet; and the bounds its tets' own.
  if ((nodes == 0) != (slots == 0)) throw bad(fmt::format("has {} nodes for {} tets", nodes, slots));
  constexpr uint32_t kMaxDepth = 100;
  std::vector<uint8_t> parents(nodes, 0);
  std::vector<uint32_t> depth(nodes, 0);
  size_t next_slot = 0;
  for (size_t i = 0; i < nodes; ++i) {
    const BvhNode& n = out.bvh.nodes[i];
    if (i > 0 && parents[i] != 1) throw bad(fmt::format("node {} has {} parents", i, int(parents[i])));
    if (n.leaf()) {
      if (n.index != next_slot || size_t(n.index) + n.count > slots)
        throw bad(fmt::format("leaf {} holds slots {} to {}, not the next ones from {}", i, n.index, n.index + n.count, next_slot));
      next_slot += n.count;
      continue;
    }
    if (!(i + 1 < nodes && n.index > i + 1 && n.index < nodes)) throw bad(fmt::format("node {} points outside the tree", i));
    if (depth[i] >= kMaxDepth) throw bad(fmt::format("is deeper than {} levels", kMaxDepth));
    for (size_t child : {i + 1, size_t(n.index)}) parents[child] = uint8_t(std::min(2, parents[child] + 1)), depth[child] = depth[i] + 1;
  }
  if (next_slot != slots) throw bad(fmt::format("leaves cover {} of its {} slots", next_slot, slots));
  std::vector<uint8_t> seen(page.tet_count, 0);
  std::vector<Bounds4> slot_bounds(slots);
  const float* pos = page.positions_at(0);
  const float* val = page.values_at(0);
  for (size_t k = 0; k < slots; ++k) {
    const uint32_t t = out.bvh.order[k];
    if (t >= page.tet_count || seen[t]) throw bad(fmt::format("names tet {} twice or of a cluster of {}", t, page.tet_count));
    seen[t] = 1;
    if (!tet_bounds(page, pos, val, t, slot_bounds[k])) throw bad(fmt::format("holds tet {}, which is not valid", t));
    if (out.tet_range[2 * k] != slot_bounds[k].lo[3] || out.tet_range[2 * k + 1] != slot_bounds[k].hi[3])
      throw bad(fmt::format("gives tet {} a value range that is not its own", t));
  }
  BoxBvh refitted = out.bvh;
  refit_bvh(refitted, slot_bounds.data());
  for (size_t i = 0; i < nodes; ++i)
    for (int a = 0; a < 4; ++a)  // by value: the two zeros are one
      if (refitted.nodes[i].lo[a] != out.bvh.nodes[i].lo[a] || refitted.nodes[i].hi[a] != out.bvh.nodes[i].hi[a])
        throw bad(fmt::format("bounds node {} otherwise than its tets", i));
  return out;
}

}  // namespace brickyard::tet_bvh
