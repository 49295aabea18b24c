#include "preprocess/octree_builder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/enumerable_thread_specific.h>

#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "preprocess/box_filter.h"
#include "preprocess/builder.h"
#include "storage/store.h"
#include "storage/store_lock.h"

namespace brickyard {
namespace {

int64_t linear(const Vec3s& c, const Vec3s& n) { return (c.z * n.y + c.y) * n.x + c.x; }

/// What a node's parent and the pages need of it.
struct NodeInfo {
  bool present = false;       ///< inside the volume
  bool consolidated = false;  ///< its region is one value within the tolerance
  double rep = 0;             ///< that value, when consolidated
  double error = 0;           ///< |rep - voxel| at most, when consolidated
  float min = std::numeric_limits<float>::max(), max = std::numeric_limits<float>::lowest();  ///< cells, all levels
  double rmin = std::numeric_limits<double>::max(), rmax = std::numeric_limits<double>::lowest();  ///< finest voxels of its region

  // Voxel values are u8, u16 or f32: exact in a float.
  void add_cells(double lo, double hi) { min = std::min(min, float(lo)), max = std::max(max, float(hi)); }
  void add_child(const NodeInfo& c) {
    min = std::min(min, c.min), max = std::max(max, c.max);
    rmin = std::min(rmin, c.rmin), rmax = std::max(rmax, c.rmax);
  }
};

/// Decides consolidation from the region's finest range.
template <typename T>
void consolidate(NodeInfo& n, double tolerance) {
  const double rep = double(round_to<T>(0.5 * (n.rmin + n.rmax)));
  const double error = std::max(n.rmax - rep, rep - n.rmin);
  n.consolidated = tolerance == 0 ? n.rmin == n.rmax : error <= tolerance;
  n.rep = n.consolidated ? (tolerance == 0 ? n.rmin : rep) : 0;
  n.error = n.consolidated ? (tolerance == 0 ? 0 : error) : 0;
}

/// The octree's voxels of every level: the store's bricks for the finest levels (read through a
/// per-thread cache of decoded bricks), dense arrays for the coarse ones (above cap pages).
template <typename T>
class LevelSource {
 public:
  LevelSource(const Store& store, const OctreeLayout& layout, const OctreeBuildOptions& options, Downsample mode)
      : store_(store), layout_(layout), mode_(mode), dense_(size_t(layout.depth)) {
    if (options.clamp) clamp_ = *options.clamp;
  }

  /// Fills the dense arrays of levels s0 and coarser, and of every level the store's mip
  /// pyramid stops short of (smaller than one brick).
  void fill_dense(int s0) {
    s0 = std::min(s0, store_.layout().finest() + 1);
    for (int s = s0; s < layout_.depth; ++s) {
      const Vec3s d = layout_.level_dims(s);
      auto& a = dense_[size_t(s)];
      a.resize(size_t(volume(d)));
      if (s <= store_.layout().finest()) {
        read_bricks(s, Vec3s(0), d, a.data());
        continue;
      }
      const Vec3s fd = layout_.level_dims(s - 1);
      std::vector<T> finer;  // the store's coarsest level, when it is the one below
      if (dense_[size_t(s - 1)].empty()) {
        finer.resize(size_t(volume(fd)));
        read_bricks(s - 1, Vec3s(0), fd, finer.data());
      }
      const auto& f = finer.empty() ? dense_[size_t(s - 1)] : finer;
      for (int64_t z = 0; z < d.z; ++z)
        for (int64_t y = 0; y < d.y; ++y)
          for (int64_t x = 0; x < d.x; ++x) {
            T v[8];
            for (int o = 0; o < 8; ++o) {
              const Vec3s c{std::min(2 * x + (o & 1), fd.x - 1), std::min(2 * y + ((o >> 1) & 1), fd.y - 1),
                            std::min(2 * z + ((o >> 2) & 1), fd.z - 1)};
              v[o] = f[size_t(linear(c, fd))];
            }
            a[size_t(linear({x, y, z}, d))] = filter_8(v, mode_);
          }
    }
  }

  /// Voxel v of a dense level, indices clamped into the level.
  T dense(int s, Vec3s v) const {
    const Vec3s d = layout_.level_dims(s);
    v = {std::min(v.x, d.x - 1), std::min(v.y, d.y - 1), std::min(v.z, d.z - 1)};
    return dense_[size_t(s)][size_t(linear(v, d))];
  }

  /// Level-s voxels lo .. lo + n - 1 into out (x fastest), indices clamped into the level (the
  /// store's replicated border), clamped into the clamp range.
  void read_block(int s, const Vec3s& lo, const Vec3s& n, T* out) const {
    if (!dense_[size_t(s)].empty()) {
      for (int64_t z = 0; z < n.z; ++z)
        for (int64_t y = 0; y < n.y; ++y)
          for (int64_t x = 0; x < n.x; ++x) out[(z * n.y + y) * n.x + x] = dense(s, lo + Vec3s{x, y, z});
      return;
    }
    read_bricks(s, lo, n, out);
  }

 private:
  void read_bricks(int s, const Vec3s& lo, const Vec3s& n, T* out) const {
    const BrickFormat& f = store_.format();
    const int64_t M = f.brick_size, A = f.apron, E = f.edge();
    const Vec3s d = layout_.level_dims(s);
    const uint32_t level = uint32_t(store_.layout().finest() - s);
    Bricks& cache = bricks_.local();
    for (int64_t z = 0; z < n.z; ++z)
      for (int64_t y = 0; y < n.y; ++y) {
        const int64_t gz = std::min(lo.z + z, d.z - 1), gy = std::min(lo.y + y, d.y - 1);
        for (int64_t x = 0; x < n.x; ++x) {
          const int64_t gx = std::min(lo.x + x, d.x - 1);
          const BrickKey key{level, uint32_t(gx / M), uint32_t(gy / M), uint32_t(gz / M)};
          const T* b = cache.get(store_, key, f.bytes());
          T v = b[((gz % M + A) * E + (gy % M + A)) * E + (gx % M + A)];
          out[(z * n.y + y) * n.x + x] = clamp(v);
        }
      }
  }

  T clamp(T v) const {
    if (!clamp_) return v;
    return round_to<T>(std::clamp(double(v), clamp_->first, clamp_->second));
  }

  /// A few decoded bricks, least recently used replaced: cap pages are visited brick by brick.
  struct Bricks {
    struct Entry {
      uint64_t code = ~uint64_t(0), used = 0;
      std::vector<std::byte> bytes;
    };
    std::vector<Entry> entries = std::vector<Entry>(16);
    uint64_t clock = 0;
    const T* get(const Store& store, const BrickKey& key, size_t bytes) {
      const uint64_t code = key.code();
      Entry* victim = &entries[0];
      for (Entry& e : entries) {
        if (e.code == code) {
          e.used = ++clock;
          return reinterpret_cast<const T*>(e.bytes.data());
        }
        if (e.used < victim->used) victim = &e;
      }
      victim->bytes.resize(bytes);
      store.read_brick(key, victim->bytes);
      victim->code = code, victim->used = ++clock;
      return reinterpret_cast<const T*>(victim->bytes.data());
    }
  };

  const Store& store_;
  const OctreeLayout& layout_;
  Downsample mode_;
  std::optional<std::pair<double, double>> clamp_;
  std::vector<std::vector<T>> dense_;
  mutable tbb::enumerable_thread_specific<Bricks> bricks_;
};

/// Lays a page out from the nodes below its root. `info(d, c)` is the node at depth d and
/// global coordinates c (null outside what the caller holds), `scalar(d, c, o)` its scalar o.
template <typename T, typename Info, typename Scalar>
std::vector<std::byte> lay_out_page(const OctreeLayout& layout, int root, const Vec3s& root_coords, Info&& info,
                                    Scalar&& scalar, OctreeSummary& stats) {
  const int levels = layout.page_levels(root);
  const bool has_caps = root == layout.cap_page_root();
  std::vector<std::vector<Vec3s>> coords(static_cast<size_t>(levels) + 1);
  std::vector<std::vector<OctreeNode>> nodes(static_cast<size_t>(levels));
  coords[0].push_back(root_coords);
  for (int l = 0; l < levels; ++l) {
    const int d = root + l;
    for (const Vec3s& c : coords[size_t(l)]) {
      OctreeNode n;
      const NodeInfo* self = info(d, c);
      n.min = self->min, n.max = self->max;
      const bool children_here = l + 1 < levels || has_caps;
      n.first_child = uint32_t(coords[size_t(l) + 1].size());
      for (int o = 0; o < 8; ++o) {
        const Vec3s cc{2 * c.x + (o & 1), 2 * c.y + ((o >> 1) & 1), 2 * c.z + ((o >> 2) & 1)};
        const NodeInfo* child = info(d + 1, cc);
        if (!child || !child->present) continue;
        if (child->consolidated) {
          n.const_mask |= uint8_t(1u << o);
          ++stats.consolidated;
          stats.max_error = std::max(stats.max_error, child->error);
          continue;
        }
        n.child_mask |= uint8_t(1u << o);
        if (children_here) coords[size_t(l) + 1].push_back(cc);
      }
      if (!children_here) n.first_child = 0;
      nodes[size_t(l)].push_back(n);
    }
  }
  OctreePageHeader h;
  h.root_depth = uint8_t(root);
  h.levels = uint8_t(levels);
  h.has_caps = has_caps;
  h.value_type = uint8_t(layout.type);
  for (int l = 0; l < levels; ++l) h.nodes[l] = uint32_t(nodes[size_t(l)].size());
  h.caps = has_caps ? uint32_t(coords[size_t(levels)].size()) : 0;
  std::vector<std::byte> page(layout.page_bytes(std::span(h.nodes, size_t(levels)), h.caps));
  std::byte* p = page.data();
  std::memcpy(p, &h, sizeof h);
  p += sizeof h;
  for (int l = 0; l < levels; ++l) {
    if (!nodes[size_t(l)].empty())  // (an empty level's data() may be null, which memcpy may not take)
      std::memcpy(p, nodes[size_t(l)].data(), nodes[size_t(l)].size() * sizeof(OctreeNode));
    p += nodes[size_t(l)].size() * sizeof(OctreeNode);
    T* s = reinterpret_cast<T*>(p);
    for (size_t i = 0; i < nodes[size_t(l)].size(); ++i) {
      const Vec3s& c = coords[size_t(l)][i];
      for (int o = 0; o < 8; ++o) {
        const Vec3s cc{2 * c.x + (o & 1), 2 * c.y + ((o >> 1) & 1), 2 * c.z + ((o >> 2) & 1)};
        const NodeInfo* child = info(root + l + 1, cc);
        s[8 * i + size_t(o)] = child && child->consolidated ? T(child->rep) : scalar(root + l, c, o);
      }
    }
    p += nodes[size_t(l)].size() * 8 * sizeof(T);
    stats.interior_nodes += nodes[size_t(l)].size();
  }
  if (has_caps) {
    T* s = reinterpret_cast<T*>(p);
    for (size_t i = 0; i < coords[size_t(levels)].size(); ++i)
      for (int o = 0; o < 8; ++o) s[8 * i + size_t(o)] = scalar(layout.cap_depth(), coords[size_t(levels)][i], o);
    stats.caps += coords[size_t(levels)].size();
  }
  stats.bytes += page.size();
  ++stats.pages;
  return page;
}

/// One cap page: its blocks of every level, its nodes' summaries, and the laid-out page (empty
/// when the root is consolidated).
template <typename T>
struct CapPage {
  NodeInfo root;
  std::vector<std::byte> bytes;
  OctreeSummary stats;
};

template <typename T>
CapPage<T> build_cap_page(const OctreeLayout& layout, const LevelSource<T>& source, const Vec3s& pc, double tolerance) {
  const int rc = layout.cap_page_root(), sc = layout.level_of_depth(rc);
  // Block of level s: voxels pc * 2^(sc + 1 - s) .. + 2^(sc + 1 - s), the last one the forward
  // neighbour of the cells at the block's end.
  std::vector<std::vector<T>> blocks(static_cast<size_t>(sc) + 1);
  std::vector<int64_t> edge(static_cast<size_t>(sc) + 1);
  for (int s = 0; s <= sc; ++s) {
    const int64_t span = int64_t(2) << (sc - s);
    edge[size_t(s)] = span + 1;
    blocks[size_t(s)].resize(size_t(edge[size_t(s)] * edge[size_t(s)] * edge[size_t(s)]));
    source.read_block(s, pc * span, Vec3s(edge[size_t(s)]), blocks[size_t(s)].data());
  }
  auto block_at = [&](int s, const Vec3s& local) {
    const int64_t e = edge[size_t(s)];
    return blocks[size_t(s)][size_t((local.z * e + local.y) * e + local.x)];
  };
  // Nodes of every depth rc .. D - 1, page-local coordinates, linear index.
  const int depths = layout.depth - rc;
  std::vector<std::vector<NodeInfo>> info(static_cast<size_t>(depths));
  for (int k = depths - 1; k >= 0; --k) {
    const int d = rc + k, s = layout.level_of_depth(d);
    const int64_t n = int64_t(1) << k;
    const Vec3s all = layout.nodes_at(d);
    auto& level = info[size_t(k)];
    level.resize(size_t(n * n * n));
    for (int64_t z = 0; z < n; ++z)
      for (int64_t y = 0; y < n; ++y)
        for (int64_t x = 0; x < n; ++x) {
          const Vec3s local{x, y, z}, global = pc * n + local;
          NodeInfo& node = level[size_t(linear(local, Vec3s(n)))];
          if (global.x >= all.x || global.y >= all.y || global.z >= all.z) continue;
          node.present = true;
          double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
          for (int64_t dz = 0; dz <= 2; ++dz)
            for (int64_t dy = 0; dy <= 2; ++dy)
              for (int64_t dx = 0; dx <= 2; ++dx) {
                const double v = double(block_at(s, {2 * x + dx, 2 * y + dy, 2 * z + dz}));
                lo = std::min(lo, v), hi = std::max(hi, v);
                if (k == depths - 1 && dx < 2 && dy < 2 && dz < 2) node.rmin = std::min(node.rmin, v), node.rmax = std::max(node.rmax, v);
              }
          node.add_cells(lo, hi);
          if (k + 1 < depths)
            for (int o = 0; o < 8; ++o) {
              const Vec3s cl{2 * x + (o & 1), 2 * y + ((o >> 1) & 1), 2 * z + ((o >> 2) & 1)};
              const NodeInfo& c = info[size_t(k) + 1][size_t(linear(cl, Vec3s(2 * n)))];
              if (c.present) node.add_child(c);
            }
          consolidate<T>(node, tolerance);
        }
  }
  CapPage<T> out;
  out.root = info[0][0];
  // The whole volume's root is never consolidated away: it has no parent to stand for it.
  if (out.root.consolidated && rc > 0) return out;
  auto node_info = [&](int d, const Vec3s& c) -> const NodeInfo* {
    const int k = d - rc;
    if (k < 0 || k >= depths) return nullptr;
    const int64_t n = int64_t(1) << k;
    const Vec3s local = c - pc * n;
    return &info[size_t(k)][size_t(linear(local, Vec3s(n)))];
  };
  auto scalar = [&](int d, const Vec3s& c, int o) {
    const int64_t n = int64_t(1) << (d - rc);
    const Vec3s local = c - pc * n;
    return block_at(layout.level_of_depth(d), {2 * local.x + (o & 1), 2 * local.y + ((o >> 1) & 1), 2 * local.z + ((o >> 2) & 1)});
  };
  out.bytes = lay_out_page<T>(layout, rc, pc, node_info, scalar, out.stats);
  return out;
}

void add(OctreeSummary& into, const OctreeSummary& s) {
  into.pages += s.pages, into.interior_nodes += s.interior_nodes, into.caps += s.caps;
  into.consolidated += s.consolidated, into.bytes += s.bytes;
  into.max_error = std::max(into.max_error, s.max_error);
}

template <typename T>
OctreeSummary build_typed(Store& store, const OctreeBuildOptions& options, Downsample mode, Progress* progress) {
  const OctreeLayout layout = store.octree_layout();
  const int rc = layout.cap_page_root();
  LevelSource<T> source(store, layout, options, mode);
  source.fill_dense(layout.level_of_depth(rc) + 1);
  OctreeWriter writer(store, options.batch_bytes);

  OctreeSummary summary;
  std::vector<OctreePageRange> ranges;
  summary.depth = layout.depth;
  summary.tolerance = options.tolerance;
  if (options.clamp) summary.clamped = true, summary.clamp_lo = options.clamp->first, summary.clamp_hi = options.clamp->second;
  summary.raw_bytes = uint64_t(volume(layout.dims)) * size_of(layout.type);
  summary.page_bytes = layout.page_bytes();

  // Cap pages, a z-slab of roots at a time: the slab's pages in parallel, written in order.
  std::vector<std::vector<NodeInfo>> info(static_cast<size_t>(rc) + 1);
  const Vec3s roots = layout.nodes_at(rc);
  info[size_t(rc)].resize(size_t(volume(roots)));
  const int64_t page_voxels = int64_t(1) << (3 * (layout.depth - rc));
  std::vector<CapPage<T>> slab(size_t(roots.x * roots.y));
  for (int64_t z = 0; z < roots.z; ++z) {
    parallel_for<int64_t>(0, roots.x * roots.y, 1, [&](int64_t b, int64_t e) {
      for (int64_t i = b; i < e; ++i) {
        slab[size_t(i)] = build_cap_page<T>(layout, source, {i % roots.x, i / roots.x, z}, options.tolerance);
        if (progress) progress->advance(uint64_t(page_voxels));
      }
    });
    for (int64_t i = 0; i < roots.x * roots.y; ++i) {
      CapPage<T>& p = slab[size_t(i)];
      const Vec3s c{i % roots.x, i / roots.x, z};
      info[size_t(rc)][size_t(linear(c, roots))] = p.root;
      if (!p.bytes.empty()) {
        summary.stored_bytes += writer.put_page(OctreeLayout::page_id(rc, c), p.bytes);
        ranges.push_back({OctreeLayout::page_id(rc, c), p.root.min, p.root.max});
      }
      add(summary, p.stats);
      p = CapPage<T>{};
    }
  }

  // The nodes above cap pages, depth by depth, from their children and the dense levels.
  for (int d = rc - 1; d >= 0; --d) {
    const Vec3s n = layout.nodes_at(d), nc = layout.nodes_at(d + 1);
    const int s = layout.level_of_depth(d);
    auto& level = info[size_t(d)];
    level.resize(size_t(volume(n)));
    for (int64_t z = 0; z < n.z; ++z)
      for (int64_t y = 0; y < n.y; ++y)
        for (int64_t x = 0; x < n.x; ++x) {
          NodeInfo& node = level[size_t(linear({x, y, z}, n))];
          node.present = true;
          double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
          for (int64_t dz = 0; dz <= 2; ++dz)
            for (int64_t dy = 0; dy <= 2; ++dy)
              for (int64_t dx = 0; dx <= 2; ++dx) {
                const double v = double(source.dense(s, {2 * x + dx, 2 * y + dy, 2 * z + dz}));
                lo = std::min(lo, v), hi = std::max(hi, v);
              }
          node.add_cells(lo, hi);
          for (int o = 0; o < 8; ++o) {
            const Vec3s c{2 * x + (o & 1), 2 * y + ((o >> 1) & 1), 2 * z + ((o >> 2) & 1)};
            if (c.x < nc.x && c.y < nc.y && c.z < nc.z && info[size_t(d) + 1][size_t(linear(c, nc))].present)
              node.add_child(info[size_t(d) + 1][size_t(linear(c, nc))]);
          }
          consolidate<T>(node, options.tolerance);
        }
  }
  auto node_info = [&](int d, const Vec3s& c) -> const NodeInfo* {
    if (d > rc) return nullptr;
    const Vec3s n = layout.nodes_at(d);
    if (c.x >= n.x || c.y >= n.y || c.z >= n.z) return nullptr;
    return &info[size_t(d)][size_t(linear(c, n))];
  };
  auto scalar = [&](int d, const Vec3s& c, int o) {
    return source.dense(layout.level_of_depth(d), {2 * c.x + (o & 1), 2 * c.y + ((o >> 1) & 1), 2 * c.z + ((o >> 2) & 1)});
  };
  // Upper pages: every page root above the caps' whose node is stored (the volume's root always).
  for (int r = rc - 1; r >= 0; --r) {
    if (!layout.is_page_root(r)) continue;
    const Vec3s n = layout.nodes_at(r);
    for (int64_t z = 0; z < n.z; ++z)
      for (int64_t y = 0; y < n.y; ++y)
        for (int64_t x = 0; x < n.x; ++x) {
          const NodeInfo& node = info[size_t(r)][size_t(linear({x, y, z}, n))];
          if (node.consolidated && r > 0) continue;
          const auto page = lay_out_page<T>(layout, r, {x, y, z}, node_info, scalar, summary);
          summary.stored_bytes += writer.put_page(OctreeLayout::page_id(r, {x, y, z}), page);
          ranges.push_back({OctreeLayout::page_id(r, {x, y, z}), node.min, node.max});
        }
  }
  writer.finish(summary, std::move(ranges));
  return summary;
}

void validate(const OctreeBuildOptions& options) {
  if (!(options.tolerance >= 0))
    throw Error(Errc::invalid_argument, fmt::format("tolerance {} is below zero", options.tolerance)).with_field("--tolerance");
  if (options.clamp && !(options.clamp->first < options.clamp->second))
    throw Error(Errc::invalid_argument, fmt::format("clamp range [{}, {}] is empty or inverted", options.clamp->first,
                                                    options.clamp->second))
        .with_field("--range");
}

}  // namespace

OctreeBuildResult build_octree(const std::string& dir, const OctreeBuildOptions& options, Progress* progress) {
  validate(options);
  const StoreWriteLock lock(dir);  // an import or another build-octree may be writing it
  return build_octree(dir, options, lock, progress);
}

OctreeBuildResult build_octree(const std::string& dir, const OctreeBuildOptions& options, const StoreWriteLock&,
                               Progress* progress) {
  validate(options);
  const auto start = std::chrono::steady_clock::now();
  Store::OpenOptions open;
  open.writable = true;
  Store store(dir, open);
  if (store.kind() != DataKind::structured)
    throw Error(Errc::unsupported, "an octree volume is built over a grid; this store is a tetrahedral mesh").with_file(dir);
  Downsample mode = Downsample::average;
  const auto grid_build = nlohmann::json::parse(store.manifest().build, nullptr, false);
  if (grid_build.is_object() && grid_build.contains("downsample") && grid_build["downsample"].is_string())
    mode = parse_downsample(grid_build["downsample"].get<std::string>());
  OctreeBuildResult result;
  result.summary = dispatch_value_type(store.format().type, [&](auto t) {
    return build_typed<decltype(t)>(store, options, mode, progress);
  });
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace brickyard
