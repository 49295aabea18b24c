// `octree_cgt`: isosurface ray tracing of an octree volume (Knoll, Hijazi, Kensler, Schott,
// Hansen, Hagen, "Interactive isosurface ray tracing of large octree volumes"), its pages read
// through the cache.
//
// This file holds the single-ray mode the paper measures its coherent traversal against: a
// front-to-back descent of the octree per ray, culling nodes whose min/max (cells of every
// finer level, forward neighbours included) misses every isovalue, down to the cap nodes; in
// each cap's 2x2x2 cells the trilinear cubic along the ray is solved exactly (first root,
// tangent roots included), corners from the cap or, across caps, by a descent from the root.
// Consolidated subtrees are walked only along their forward faces, where their cells meet
// other values.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "dataset/octree_walk.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/common/params.h"
#include "renderers/common/pixel.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"

namespace brickyard {
namespace {

struct OctreeCgtParams {
  int pinned_pages{};       // pages a tile keeps pinned before it lets them go
  double root_tolerance{};  // relative |g| at an extremum of the cell's cubic that counts as a touching root
};

const ParamTable<OctreeCgtParams>& octree_cgt_params() {
  static const ParamTable<OctreeCgtParams> table{
      {"pinned_pages", &OctreeCgtParams::pinned_pages, 64, 4, 4096,
       "octree pages one tile keeps pinned in the cache's L1 while it renders (then released, and fetched again)"},
      {"root_tolerance", &OctreeCgtParams::root_tolerance, 1e-12, 0.0, 1e-3,
       "a tangent touch of the isosurface counts as a hit where the cell's cubic comes this close to zero (relative)"},
  };
  return table;
}

/// The pages a tile has fetched, pinned and parsed, until a ray starts with more than
/// `capacity` held (never during a ray: its nodes point into them).
template <typename T>
class PageMemo {
 public:
  PageMemo(PageCache& cache, const OctreeLayout& layout, size_t capacity, RayCounters& counters)
      : cache_(cache), layout_(layout), page_bytes_(layout.page_bytes()), capacity_(capacity), counters_(counters) {}
  const OctreePage<T>* page(uint64_t id) {
    for (const auto& e : entries_)
      if (e->id == id) return &e->view;
    ++counters_.lookups;
    ++counters_.bricks;  // a page visit
    auto e = std::make_unique<Entry>();
    e->id = id;
    e->handle = cache_.fetch({RecordKind::octree_page, id});
    e->view = OctreePage<T>::view({e->handle.bytes(), page_bytes_}, layout_);
    entries_.push_back(std::move(e));
    return &entries_.back()->view;
  }
  /// For octree_scalars().
  const OctreePage<T>* operator()(uint64_t id) { return page(id); }
  void begin_ray() {
    if (entries_.size() >= capacity_) entries_.clear(), ++generation_;
  }
  /// Changes whenever pages are let go: pointers into them from before are stale.
  uint64_t generation() const { return generation_; }

 private:
  struct Entry {
    uint64_t id = 0;
    PageHandle handle;
    OctreePage<T> view;
  };
  PageCache& cache_;
  const OctreeLayout& layout_;
  size_t page_bytes_, capacity_;
  RayCounters& counters_;
  std::vector<std::unique_ptr<Entry>> entries_;
  uint64_t generation_ = 0;
};

template <typename T>
class OctreeCgtRenderer final : public Renderer {
 public:
  OctreeCgtRenderer(const RenderContext& ctx, const OctreeCgtParams& p)
      : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), view_(ctx.octree()), layout_(view_.layout()), p_(p),
        shading_(scene_.shading, geo_) {
    for (const auto& s : scene_.isosurfaces) iso_.push_back(s.value);
    for (int d = 0; d < layout_.depth; ++d) nodes_at_.push_back(layout_.nodes_at(d));
  }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    Tracer t(*this, setup, counters);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) t.pixel(x, y, out);
  }

 private:
  struct Hit {
    double t = std::numeric_limits<double>::infinity();
    int surface = -1;
    Vec3d normal_voxel{0.0};  // gradient of the interpolant, voxel coordinates
  };

  /// A node on the way down: where it is, and where its record is (null for a node inside a
  /// consolidated subtree, which has none: its value is `constant`).
  struct Node {
    int depth = 0;
    Vec3s c{0};
    const OctreePage<T>* page = nullptr;
    int level = 0;
    uint32_t index = 0;
    bool consolidated = false;
    double constant = 0;
    float min = 0, max = 0;
    uint64_t unread_page = 0;  // the page rooted here, fetched only once the ray needs it (0: read)
    Vec3s forward_end{0};  // for consolidated nodes: the end (finest voxels) of the subtree that is one value
  };
  static Node none() {
    Node n;
    n.depth = -1;
    return n;
  }
  /// Orders a few entries by their first member (ray entry), in place.
  template <typename E, size_t N>
  static void sort_by_entry(std::array<E, N>& a, int count) {
    for (int i = 1; i < count; ++i)
      for (int j = i; j > 0 && a[size_t(j)].first < a[size_t(j - 1)].first; --j) std::swap(a[size_t(j)], a[size_t(j - 1)]);
  }

  struct Tracer {
    const OctreeCgtRenderer& r;
    const FrameSetup& setup;
    const ImageRays rays;
    RayCounters& counters;
    PageMemo<T> pages;

    Tracer(const OctreeCgtRenderer& renderer, const FrameSetup& s, RayCounters& c)
        : r(renderer), setup(s), rays(s.camera, s.width, s.height), counters(c),
          pages(r.ctx_.pages(), r.layout_, size_t(r.p_.pinned_pages), c) {}

    const OctreePage<T>* page(uint64_t id) { return pages.page(id); }

    /// Caps near the ray, found by descent once each: a cell's corners lie in up to 8 caps,
    /// and the next cells along the ray share most of them.
    struct CapEntry {
      Vec3s c{-1};
      uint64_t generation = ~uint64_t(0);
      OctreeScalars<T> scalars;
    };
    std::array<CapEntry, 16> caps{};
    size_t next_cap = 0;

    const OctreeScalars<T>& cap_at(const Vec3s& c) {
      for (const CapEntry& e : caps)
        if (e.c == c && e.generation == pages.generation()) return e.scalars;
      ++counters.samples;  // a lookup of the octree
      CapEntry& e = caps[next_cap++ % caps.size()];
      e.scalars = octree_scalars<T>(r.layout_, pages, r.layout_.cap_depth(), c);
      e.c = c, e.generation = pages.generation();
      return e.scalars;
    }

    bool crosses(float lo, float hi) const {
      for (double iso : r.iso_)
        if (iso >= lo && iso <= hi) return true;
      return false;
    }

    /// Width in finest voxels of a node at depth d.
    int64_t width(int d) const { return int64_t(1) << (r.layout_.depth - d); }

    void pixel(int x, int y, FrameBuffers& out) {
      ++counters.rays;
      pages.begin_ray();
      const PrimaryRay ray = primary_ray(rays, r.geo_, x, y);
      PixelResult px;
      px.color = r.scene_.background;
      if (ray.hits()) {
        const Hit h = trace(ray.org, ray.dir, ray.span);
        if (h.surface >= 0) shade(ray, h, px);
      }
      write_pixel(out, x, y, px);
    }

    void shade(const PrimaryRay& ray, const Hit& h, PixelResult& px) {
      px.depth = h.t;
      px.alpha = 1;
      px.color = r.scene_.isosurfaces[size_t(h.surface)].color;
      if (!r.ctx_.needs_gradients(setup.outputs)) return;
      ++counters.gradients;
      const Vec3d n = facing_normal(h.normal_voxel / r.geo_.spacing, ray.world.dir);
      if (setup.outputs.normals) px.normal = n;
      if (!r.shading_.lit()) return;
      double light_distance;
      const Vec3d l = r.shading_.to_light_along(ray.world, h.t, light_distance);
      px.color = r.shading_.shade(px.color, n, -ray.world.dir, l, false);
    }

    /// Front-to-back descent from the root over [span.t0, span.t1].
    Hit trace(const Vec3d& o, const Vec3d& d, Interval<double> span) {
      Hit best;
      const Vec3d inv{1.0 / d.x, 1.0 / d.y, 1.0 / d.z};
      Node root;
      root.page = page(OctreeLayout::page_id(0, Vec3s(0)));
      root.min = root.page->nodes[0][0].min, root.max = root.page->nodes[0][0].max;
      descend(root, o, d, inv, span, best);
      return best;
    }

    /// The ray's interval over a node's cells: voxels [c W, (c + 1) W] clipped to the volume's
    /// last voxel (a cell's upper corner lies in the next node).
    Interval<double> node_span(const Node& n, const Vec3d& o, const Vec3d& inv, Interval<double> span) const {
      const int64_t w = width(n.depth);
      Interval<double> s = span;
      for (int a = 0; a < 3; ++a) {
        const double lo = double(n.c[a] * w), hi = double(std::min((n.c[a] + 1) * w, r.layout_.dims[a] - 1));
        double t0 = (lo - o[a]) * inv[a], t1 = (hi - o[a]) * inv[a];
        if (t0 > t1) std::swap(t0, t1);
        if (std::isnan(t0)) t0 = -std::numeric_limits<double>::infinity();  // on a face, parallel to it
        if (std::isnan(t1)) t1 = std::numeric_limits<double>::infinity();
        s.t0 = std::max(s.t0, t0), s.t1 = std::min(s.t1, t1);
      }
      return s;
    }

    /// Returns true when the ray is done (a hit before anything later can be).
    bool descend(const Node& n, const Vec3d& o, const Vec3d& d, const Vec3d& inv, Interval<double> span, Hit& best) {
      ++counters.nodes;
      const Interval<double> s = node_span(n, o, inv, span);
      if (s.t0 > s.t1 || s.t0 >= best.t) return false;
      if (!crosses(n.min, n.max)) return false;
      if (n.unread_page) {
        Node read = n;
        read.page = page(n.unread_page);
        read.unread_page = 0;
        return descend(read, o, d, inv, span, best);
      }
      if (n.depth == r.layout_.cap_depth()) {
        cells(n, o, d, s, best);
        return best.surface >= 0;
      }
      // Children front to back: order by where the ray enters each.
      std::array<std::pair<double, int>, 8> order;
      int count = 0;
      for (int oct = 0; oct < 8; ++oct) {
        Node c = child(n, oct);
        if (c.depth < 0) continue;
        const Interval<double> cs = node_span(c, o, inv, s);
        if (cs.t0 > cs.t1) continue;
        order[size_t(count++)] = {cs.t0, oct};
      }
      sort_by_entry(order, count);
      for (int i = 0; i < count; ++i) {
        if (order[size_t(i)].first >= best.t) break;
        if (descend(child(n, order[size_t(i)].second), o, d, inv, s, best)) return true;
      }
      return false;
    }

    /// Child `oct` of n (depth -1 when it is outside the volume or needs no visit).
    Node child(const Node& n, int oct) {
      Node c;
      c.depth = n.depth + 1;
      c.c = {2 * n.c.x + (oct & 1), 2 * n.c.y + ((oct >> 1) & 1), 2 * n.c.z + ((oct >> 2) & 1)};
      const Vec3s all = r.nodes_at_[size_t(c.depth)];
      if (c.c.x >= all.x || c.c.y >= all.y || c.c.z >= all.z) return none();
      if (n.consolidated) {
        // Inside a region of one value, only cells on its forward faces meet other values,
        // unless an isovalue equals it.
        const int64_t w = width(c.depth);
        bool face = false;
        for (int a = 0; a < 3; ++a) face |= (c.c[a] + 1) * w >= n.forward_end[a];
        if (!face && !std::any_of(r.iso_.begin(), r.iso_.end(), [&](double v) { return v == n.constant; }))
          return none();
        c.consolidated = true, c.constant = n.constant, c.min = n.min, c.max = n.max, c.forward_end = n.forward_end;
        return c;
      }
      const OctreeNode& rec = n.page->nodes[size_t(n.level)][n.index];
      const T* scalars = n.page->node_scalars(n.level, n.index);
      if (rec.const_mask & (1u << oct)) {
        c.consolidated = true;
        c.constant = double(scalars[oct]);
        c.min = rec.min, c.max = rec.max;  // the parent's: cells on the forward faces reach its neighbours
        const int64_t w = width(c.depth);
        c.forward_end = (c.c + Vec3s(1)) * w;
        return c;
      }
      if (!(rec.child_mask & (1u << oct))) return none();
      if (c.depth == r.layout_.cap_depth()) {
        c.page = n.page, c.level = n.level, c.index = rec.child_index(oct);
        c.min = rec.min, c.max = rec.max;  // caps hold no range: their parent's covers them
        return c;
      }
      if (n.level + 1 < n.page->header->levels) {
        c.page = n.page, c.level = n.level + 1, c.index = rec.child_index(oct);
      } else {
        // The child's page: its range from the page table, the page itself when a ray enters it.
        const OctreePageRange* p = r.view_.page(OctreeLayout::page_id(c.depth, c.c));
        if (!p) return none();
        c.unread_page = p->id, c.level = 0, c.index = 0;
        c.min = p->min, c.max = p->max;
        return c;
      }
      const OctreeNode& crec = c.page->nodes[size_t(c.level)][c.index];
      c.min = crec.min, c.max = crec.max;
      return c;
    }

    /// The 2x2x2 cells of a cap (or of a consolidated node at the cap depth), in ray order.
    void cells(const Node& n, const Vec3d& o, const Vec3d& d, Interval<double> s, Hit& best) {
      const Vec3s lo = n.c * int64_t(2);
      const Vec3s hi{std::min(lo.x + 1, r.layout_.dims.x - 2), std::min(lo.y + 1, r.layout_.dims.y - 2),
                     std::min(lo.z + 1, r.layout_.dims.z - 2)};
      const T* cap = n.consolidated ? nullptr : n.page->cap_scalars(n.index);
      std::array<std::pair<double, Vec3s>, 8> order;
      int count = 0;
      const Vec3d inv{1.0 / d.x, 1.0 / d.y, 1.0 / d.z};
      for (int64_t z = lo.z; z <= hi.z; ++z)
        for (int64_t y = lo.y; y <= hi.y; ++y)
          for (int64_t x = lo.x; x <= hi.x; ++x) {
            Interval<double> cs = s;
            const Vec3s cell{x, y, z};
            for (int a = 0; a < 3; ++a) {
              double t0 = (double(cell[a]) - o[a]) * inv[a], t1 = (double(cell[a] + 1) - o[a]) * inv[a];
              if (t0 > t1) std::swap(t0, t1);
              if (std::isnan(t0)) t0 = -std::numeric_limits<double>::infinity();
              if (std::isnan(t1)) t1 = std::numeric_limits<double>::infinity();
              cs.t0 = std::max(cs.t0, t0), cs.t1 = std::min(cs.t1, t1);
            }
            if (cs.t0 <= cs.t1) order[size_t(count++)] = {cs.t0, cell};
          }
      sort_by_entry(order, count);
      for (int i = 0; i < count; ++i) {
        if (order[size_t(i)].first >= best.t) return;
        if (cell(order[size_t(i)].second, n, cap, o, d, s, best)) return;
      }
    }

    double corner(const Vec3s& v, const Node& n, const T* cap) {
      const int octant = int(v.x & 1) | int((v.y & 1) << 1) | int((v.z & 1) << 2);
      if (v.x >> 1 == n.c.x && v.y >> 1 == n.c.y && v.z >> 1 == n.c.z) return n.consolidated ? n.constant : double(cap[octant]);
      return double(cap_at({v.x >> 1, v.y >> 1, v.z >> 1})[octant]);
    }

    /// Intersects one cell; true when it holds a hit.
    bool cell(const Vec3s& cell, const Node& n, const T* cap, const Vec3d& o, const Vec3d& d, Interval<double> s,
              Hit& best) {
      double c[8];
      double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
      for (int k = 0; k < 8; ++k) {
        c[k] = corner({cell.x + (k & 1), cell.y + ((k >> 1) & 1), cell.z + ((k >> 2) & 1)}, n, cap);
        lo = std::min(lo, c[k]), hi = std::max(hi, c[k]);
      }
      Interval<double> cs = s;
      for (int a = 0; a < 3; ++a) {
        double t0 = (double(cell[a]) - o[a]) / d[a], t1 = (double(cell[a] + 1) - o[a]) / d[a];
        if (t0 > t1) std::swap(t0, t1);
        if (std::isnan(t0)) t0 = -std::numeric_limits<double>::infinity();
        if (std::isnan(t1)) t1 = std::numeric_limits<double>::infinity();
        cs.t0 = std::max(cs.t0, t0), cs.t1 = std::min(cs.t1, t1);
      }
      if (cs.t0 > cs.t1) return false;
      ++counters.cells;
      bool found = false;
      for (size_t i = 0; i < r.iso_.size(); ++i) {
        const double iso = r.iso_[i];
        if (iso < lo || iso > hi) continue;
        const Vec3d p0 = o + d * cs.t0;
        const double u0[3] = {p0.x - double(cell.x), p0.y - double(cell.y), p0.z - double(cell.z)};
        const double du[3] = {d.x, d.y, d.z};
        const Cubic g = trilinear_cubic(c, iso, u0, du);
        const auto root = first_root(g, cs.t1 - cs.t0, r.p_.root_tolerance);
        if (!root) continue;
        const double t = cs.t0 + *root;
        if (t >= best.t) continue;
        best.t = t, best.surface = int(i), found = true;
        const Vec3d u{u0[0] + du[0] * *root, u0[1] + du[1] * *root, u0[2] + du[2] * *root};
        best.normal_voxel = trilinear_gradient(c, u.x, u.y, u.z);
      }
      return found;
    }
  };

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  const OctreeView& view_;
  OctreeLayout layout_;
  OctreeCgtParams p_;
  ShadingModel shading_;
  std::vector<double> iso_;
  std::vector<Vec3s> nodes_at_;  // per depth
};

}  // namespace

BackendEntry octree_cgt_backend() {
  BackendEntry e;
  e.info.name = "octree_cgt";
  e.info.description = "Knoll et al.: isosurfaces of an octree volume (brickyard build-octree), exact trilinear "
                       "roots, octree pages through the cache; single-ray mode";
  e.info.kinds = {DataKind::structured};
  e.info.records = {RecordKind::octree_page};
  e.info.modes = {RenderMode::iso};
  e.info.params = octree_cgt_params().declarations();
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const OctreeCgtParams op = octree_cgt_params().bind(p);
    return dispatch_value_type(ctx.octree().layout().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      return std::make_unique<OctreeCgtRenderer<decltype(stored)>>(ctx, op);
    });
  };
  return e;
}

}  // namespace brickyard
