// `octree_cgt`: isosurface ray tracing of an octree volume (Knoll, Hijazi, Kensler, Schott,
// Hansen, Hagen, "Interactive isosurface ray tracing of large octree volumes"), its pages read
// through the cache.
//
// Two modes of one structure. Packets (the default, 8 x 8 rays): a packet descends the
// octree's implicit macrocells once, nearer half along the frame's major axis K first, culled
// by its frustum over K and by node ranges (cells of every finer level, forward neighbours
// included); each node keeps the lanes whose ray crosses it before their hit so far; in a cap,
// each lane visits the cells its ray crosses slice by slice along K, corners read from the
// cap's 3x3x3 voxels gathered once. The single-ray mode (`packet` 1), which the paper measures
// the coherent one against: a front-to-back descent per ray, children in entry order. In both,
// each cell's trilinear cubic along the ray is solved exactly (first root, tangent roots
// included), and consolidated subtrees are walked only along their forward faces, where their
// cells meet other values. `mcell`, `cell` and `slice` switch the culling and the shared
// gathering off, for the paper's Table II; the image does not change.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"
#include "dataset/octree_walk.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/common/params.h"
#include "renderers/common/pixel.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"
#include "renderers/octree_cgt/page_memo.h"

namespace brickyard {
namespace {

struct OctreeCgtParams {
  int packet{};             // rays per side of a packet; 1: the single-ray mode
  bool mcell{};             // cull macrocells (octree nodes, pages) by their range
  bool cell{};              // cull cells by their corners' range before solving their cubic
  bool slice{};             // packets: a cap's voxels gathered once for all its cells
  double dpdv{};            // level of detail: pixels a coarse voxel may cover; 0: the finest level
  bool show_levels{};       // colour hits by the level they were found at
  int pinned_pages{};       // pages a tile keeps pinned before it lets them go
  double root_tolerance{};  // relative |g| at an extremum of the cell's cubic that counts as a touching root
};

const ParamTable<OctreeCgtParams>& octree_cgt_params() {
  static const ParamTable<OctreeCgtParams> table{
      {"packet", &OctreeCgtParams::packet, 8, 1, 16,
       "packets of packet x packet rays traverse the octree together (2, 4, 8 or 16); 1: single-ray mode"},
      {"mcell", &OctreeCgtParams::mcell, 1, 0, 1, "1: skip octree nodes and pages whose range holds no isovalue; 0: visit them (Table II)"},
      {"cell", &OctreeCgtParams::cell, 1, 0, 1, "1: skip cells whose corners' range holds no isovalue; 0: solve every cell's cubic"},
      {"slice", &OctreeCgtParams::slice, 1, 0, 1,
       "packets, 1: a cap's 3x3x3 voxels gathered once for its cells; 0: every cell looks up its 8 corners"},
      {"dpdv", &OctreeCgtParams::dpdv, 0.0, 0.0, 64.0,
       "level of detail (the paper's dP/dV): a node's own coarser voxels are used where one covers at most this many pixels "
       "at the node's nearest slice along K; 0: always the finest"},
      {"show_levels", &OctreeCgtParams::show_levels, 0, 0, 1, "1: colour each hit by the level of detail it was found at"},
      {"pinned_pages", &OctreeCgtParams::pinned_pages, 64, 4, 4096,
       "octree pages one tile keeps pinned in the cache's L1 while it renders (then released, and fetched again)"},
      {"root_tolerance", &OctreeCgtParams::root_tolerance, 1e-12, 0.0, 1e-3,
       "a tangent touch of the isosurface counts as a hit where the cell's cubic comes this close to zero (relative)"},
  };
  return table;
}

template <typename T>
class OctreeCgtRenderer final : public Renderer {
 public:
  OctreeCgtRenderer(const RenderContext& ctx, const OctreeCgtParams& p)
      : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), view_(ctx.octree()), layout_(view_.layout()), p_(p),
        shading_(scene_.shading, geo_) {
    for (const auto& s : scene_.isosurfaces) iso_.push_back(s.value);
    for (int d = 0; d < layout_.depth; ++d) nodes_at_.push_back(layout_.nodes_at(d));
    for (int l = 0; l < layout_.depth; ++l) level_dims_.push_back(layout_.level_dims(l));
  }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    Tracer t(*this, setup, counters);
    if (p_.packet > 1) return t.render_packets(tile, p_.packet, out);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) t.pixel(x, y, out);
  }

  void begin_frame(const FrameSetup& setup) override {
    // The major axis K, once per frame: the camera's forward direction's largest component in
    // voxel coordinates (packets whose rays disagree with it along K go ray by ray).
    Vec3d f, right, up;
    setup.camera.basis(f, right, up);
    const Vec3d fv = f / geo_.spacing;
    major_axis_ = std::abs(fv.x) >= std::abs(fv.y) && std::abs(fv.x) >= std::abs(fv.z) ? 0 : std::abs(fv.y) >= std::abs(fv.z) ? 1 : 2;
    // The transition slices (the paper's Algorithm 2): a node at depth d is drawn with its own
    // level-L voxels from K distance lod_k_[d] on, where one of them covers dpdv pixels. A pixel
    // covers z * pixel_angle of world at view depth z, and a slice k voxels away along K lies at
    // z = k * spacing_K / |forward_K|.
    const int K = major_axis_;
    eye_k_ = geo_.to_voxel(setup.camera.eye)[K];
    const double pixel_angle = 2.0 * std::tan(setup.camera.fov_degrees * M_PI / 360.0) / double(std::max(setup.height, 1));
    const double fk = std::max(std::abs(f[K]), 1e-12);
    lod_k_.assign(size_t(layout_.depth), std::numeric_limits<double>::infinity());
    if (p_.dpdv > 0)
      for (int d = 0; d < layout_.depth; ++d) {
        const double voxel = double(int64_t(1) << layout_.level_of_depth(d)) * geo_.voxel_size;
        lod_k_[size_t(d)] = voxel / (p_.dpdv * pixel_angle) * fk / geo_.spacing[K];
      }
  }

 private:
  struct Hit {
    double t = std::numeric_limits<double>::infinity();
    int surface = -1;
    int level = 0;            // the level of detail of the cell it was found in (0: finest)
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
    octree_cgt::PageMemo<T> pages;

    Tracer(const OctreeCgtRenderer& renderer, const FrameSetup& s, RayCounters& c)
        : r(renderer), setup(s), rays(s.camera, s.width, s.height), counters(c),
          pages(r.ctx_.pages(), r.layout_, size_t(r.p_.pinned_pages), c) {}

    const OctreePage<T>* page(uint64_t id) { return pages.page(id); }

    /// Caps near the ray, found by descent once each: a cell's corners lie in up to 8 caps,
    /// and the next cells along the ray share most of them.
    struct CapEntry {
      int depth = -1;
      Vec3s c{-1};
      uint64_t generation = ~uint64_t(0);
      OctreeScalars<T> scalars;
    };
    std::array<CapEntry, 16> caps{};
    size_t next_cap = 0;

    /// The scalars of the node at depth d and coordinates c (a cap, or a coarser node where the
    /// level of detail stops above the caps).
    const OctreeScalars<T>& scalars_at(int d, const Vec3s& c) {
      for (const CapEntry& e : caps)
        if (e.c == c && e.depth == d && e.generation == pages.generation()) return e.scalars;
      ++counters.samples;  // a lookup of the octree
      CapEntry& e = caps[next_cap++ % caps.size()];
      e.scalars = octree_scalars<T>(r.layout_, pages, d, c);
      e.c = c, e.depth = d, e.generation = pages.generation();
      return e.scalars;
    }

    /// A node's own 8 scalars (null for one inside a consolidated subtree: its value is n.constant).
    const T* own_scalars(const Node& n) const {
      if (n.consolidated) return nullptr;
      return n.depth == r.layout_.cap_depth() ? n.page->cap_scalars(n.index) : n.page->node_scalars(n.level, n.index);
    }

    /// Whether the level of detail stops at node n: one of its voxels covers at most dpdv pixels
    /// at its nearest slice along K (the frame's transition slices).
    bool lod_leaf(const Node& n) const {
      if (n.depth == r.layout_.cap_depth()) return true;
      if (r.p_.dpdv <= 0) return false;
      const int K = r.major_axis_;
      const int64_t w = width(n.depth);
      const double lo = double(n.c[K] * w), hi = double((n.c[K] + 1) * w);
      const double e = r.eye_k_;
      const double distance = e < lo ? lo - e : e > hi ? e - hi : 0.0;
      return distance >= r.lod_k_[size_t(n.depth)];
    }

    /// How far a node's cells reach past its region at the levels of detail it or a node below it
    /// may be drawn at: a level-L voxel i sits at finest coordinate (i + 1/2) 2^L - 1/2, so
    /// level-L cells reach (2^L - 1) / 2 past. The coarsest level possible in the subtree is
    /// that of the shallowest depth whose transition slice lies within the node's K extent.
    double lod_reach(const Node& n) const {
      if (r.p_.dpdv <= 0) return 0;
      const int K = r.major_axis_;
      const int64_t w = width(n.depth);
      const double far = std::max(std::abs(double(n.c[K] * w) - r.eye_k_), std::abs(double((n.c[K] + 1) * w) - r.eye_k_));
      for (int d = n.depth; d < r.layout_.cap_depth(); ++d)
        if (r.lod_k_[size_t(d)] <= far) return 0.5 * double((int64_t(1) << r.layout_.level_of_depth(d)) - 1);
      return 0;
    }

    /// Whether a node's (or page's) range holds an isovalue; always, without macrocell culling.
    bool crosses(float lo, float hi) const {
      if (!r.p_.mcell) return true;
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
      if (r.p_.show_levels) {
        static const Vec3f kLevels[] = {{0.9f, 0.9f, 0.9f}, {0.2f, 0.6f, 1.0f}, {0.3f, 0.9f, 0.3f},
                                        {1.0f, 0.8f, 0.2f}, {1.0f, 0.4f, 0.2f}, {0.9f, 0.2f, 0.8f}};
        px.color = kLevels[std::min<size_t>(size_t(h.level), std::size(kLevels) - 1)];
      }
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
      const double reach = lod_reach(n);
      Interval<double> s = span;
      for (int a = 0; a < 3; ++a) {
        const double lo = double(n.c[a] * w), hi = std::min(double((n.c[a] + 1) * w) + reach, double(r.layout_.dims[a] - 1));
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
      if (lod_leaf(n)) {
        single_cells(n, o, d, span, best);
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
        // No return at a child's hit: with levels of detail a coarser neighbour's cells reach
        // past its region, so a later sibling entered before the hit may hold a nearer one.
        descend(child(n, order[size_t(i)].second), o, d, inv, s, best);
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
        if (r.p_.mcell && !face && !std::any_of(r.iso_.begin(), r.iso_.end(), [&](double v) { return v == n.constant; }))
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

    /// The cells of a leaf node for one ray: the packets' cell code with one lane, K the ray's
    /// own major axis (never parallel to its slices).
    void single_cells(const Node& n, const Vec3d& o, const Vec3d& d, Interval<double> span, Hit& best) {
      if (!single) single = std::make_unique<Packet>();
      Packet& p = *single;
      const int K = std::abs(d.x) >= std::abs(d.y) && std::abs(d.x) >= std::abs(d.z) ? 0 : std::abs(d.y) >= std::abs(d.z) ? 1 : 2;
      p.lanes = 1;
      p.ray[0].org = o, p.ray[0].dir = d, p.ray[0].span = span;
      p.inv[0] = {1.0 / d.x, 1.0 / d.y, 1.0 / d.z};
      p.inv_dk[0] = 1.0 / d[K];
      p.o = o;
      p.forward = d[K] > 0;
      p.hit[0] = best;
      const std::vector<uint16_t> lane{0};
      packet_cells(p, n, lane, K, (K + 1) % 3, (K + 2) % 3);
      best = p.hit[0];
    }

    /// Voxel v of the level node n holds (its own scalars, or a neighbour's at n's depth).
    double corner(const Vec3s& v, const Node& n, const T* own) {
      const int octant = int(v.x & 1) | int((v.y & 1) << 1) | int((v.z & 1) << 2);
      if (v.x >> 1 == n.c.x && v.y >> 1 == n.c.y && v.z >> 1 == n.c.z) return n.consolidated ? n.constant : double(own[octant]);
      return double(scalars_at(n.depth, {v.x >> 1, v.y >> 1, v.z >> 1})[octant]);
    }

    /// A cell's 8 corners (index dx + 2 dy + 4 dz) and their range.
    void cell_corners(const Vec3s& cell, const Node& n, const T* cap, double c[8], double& lo, double& hi) {
      lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
      for (int k = 0; k < 8; ++k) {
        c[k] = corner({cell.x + (k & 1), cell.y + ((k >> 1) & 1), cell.z + ((k >> 2) & 1)}, n, cap);
        lo = std::min(lo, c[k]), hi = std::max(hi, c[k]);
      }
    }

    bool crosses_corners(double lo, double hi) const {
      if (!r.p_.cell) return true;
      for (double iso : r.iso_)
        if (iso >= lo && iso <= hi) return true;
      return false;
    }

    /// One ray against one cell of corners c: the first root of each isosurface's cubic.
    bool intersect(const Vec3s& cell, const double c[8], double lo, double hi, const Vec3d& o, const Vec3d& d,
                   const Vec3d& inv, Interval<double> s, Hit& best) {
      Interval<double> cs = s;
      for (int a = 0; a < 3; ++a) {
        double t0 = (double(cell[a]) - o[a]) * inv[a], t1 = (double(cell[a] + 1) - o[a]) * inv[a];
        if (t0 > t1) std::swap(t0, t1);
        if (std::isnan(t0)) t0 = -std::numeric_limits<double>::infinity();
        if (std::isnan(t1)) t1 = std::numeric_limits<double>::infinity();
        cs.t0 = std::max(cs.t0, t0), cs.t1 = std::min(cs.t1, t1);
      }
      if (cs.t0 > cs.t1 || cs.t0 >= best.t) return false;
      ++counters.cells;
      bool found = false;
      for (size_t i = 0; i < r.iso_.size(); ++i) {
        const double iso = r.iso_[i];
        if (r.p_.cell && (iso < lo || iso > hi)) continue;
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

    // --- Packets: one traversal of the octree's implicit macrocells for a square of rays ---

    static constexpr int kMaxLanes = 16 * 16;
    /// Rays of one packet, structure of arrays; lanes outside the volume start done.
    struct Packet {
      int lanes = 0;
      std::array<int, kMaxLanes> px{}, py{};
      std::array<PrimaryRay, kMaxLanes> ray{};
      std::array<Hit, kMaxLanes> hit{};
      std::array<double, kMaxLanes> inv_dk{};
      std::array<Vec3d, kMaxLanes> inv{};
      std::array<uint8_t, kMaxLanes> live{};
      Vec3d o{0.0};
      double su_lo = 0, su_hi = 0, sv_lo = 0, sv_hi = 0;  // slopes du/dK, dv/dK over the live lanes
      bool forward = true;                                // the live lanes' d_K > 0
    };
    std::unique_ptr<Packet> packet;
    std::unique_ptr<Packet> single;  // the one lane of single_cells()
    /// Per depth, the lanes whose rays still cross the node being visited there and can still
    /// find a nearer hit in it: a node tests only its parent's lanes.
    std::vector<std::vector<uint16_t>> lanes_at;

    /// The lanes of `from` whose ray crosses box b before its hit so far, into `to`.
    void lanes_through(const Packet& p, const Box3d& b, const std::vector<uint16_t>& from, std::vector<uint16_t>& to) const {
      to.clear();
      for (uint16_t i : from) {
        const PrimaryRay& ray = p.ray[i];
        const Vec3d& inv = p.inv[i];
        double t0 = ray.span.t0, t1 = std::min(ray.span.t1, p.hit[i].t);
        for (int a = 0; a < 3; ++a) {
          double ta = (b.lo[a] - ray.org[a]) * inv[a], tb = (b.hi[a] - ray.org[a]) * inv[a];
          if (ta > tb) std::swap(ta, tb);
          if (std::isnan(ta)) ta = -std::numeric_limits<double>::infinity();
          if (std::isnan(tb)) tb = std::numeric_limits<double>::infinity();
          t0 = std::max(t0, ta), t1 = std::min(t1, tb);
        }
        if (t0 <= t1) to.push_back(i);
      }
    }

    void render_packets(const Tile& tile, int size, FrameBuffers& out) {
      if (!packet) packet = std::make_unique<Packet>();
      for (int y0 = tile.y0; y0 < tile.y1; y0 += size)
        for (int x0 = tile.x0; x0 < tile.x1; x0 += size) {
          // A partial packet at the image's border holds only the pixels that are there.
          Packet& p = *packet;
          p.lanes = 0;
          for (int y = y0; y < std::min(y0 + size, tile.y1); ++y)
            for (int x = x0; x < std::min(x0 + size, tile.x1); ++x) {
              const int i = p.lanes++;
              p.px[size_t(i)] = x, p.py[size_t(i)] = y;
              p.ray[size_t(i)] = primary_ray(rays, r.geo_, x, y);
              p.hit[size_t(i)] = Hit{};
            }
          counters.rays += uint64_t(p.lanes);
          pages.begin_ray();
          trace_packet(p);
          for (int i = 0; i < p.lanes; ++i) {
            PixelResult px;
            px.color = r.scene_.background;
            if (p.hit[size_t(i)].surface >= 0) shade(p.ray[size_t(i)], p.hit[size_t(i)], px);
            write_pixel(out, p.px[size_t(i)], p.py[size_t(i)], px);
          }
        }
    }

    void trace_packet(Packet& p) {
      const int K = r.major_axis_, U = (K + 1) % 3, V = (K + 2) % 3;
      int live = 0, forward = 0;
      p.su_lo = p.sv_lo = std::numeric_limits<double>::infinity();
      p.su_hi = p.sv_hi = -std::numeric_limits<double>::infinity();
      for (int i = 0; i < p.lanes; ++i) {
        const PrimaryRay& ray = p.ray[size_t(i)];
        p.live[size_t(i)] = ray.hits();
        if (!ray.hits()) continue;
        p.o = ray.org;  // one eye: every lane starts there
        ++live;
        const double dk = ray.dir[K];
        forward += dk > 0;
        p.inv_dk[size_t(i)] = 1.0 / dk;
        p.inv[size_t(i)] = {1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z};
        const double su = ray.dir[U] / dk, sv = ray.dir[V] / dk;
        p.su_lo = std::min(p.su_lo, su), p.su_hi = std::max(p.su_hi, su);
        p.sv_lo = std::min(p.sv_lo, sv), p.sv_hi = std::max(p.sv_hi, sv);
      }
      if (live == 0) return;
      // Rays that do not all head one way along K (or run parallel to its slices) have no
      // bounding frustum over K: each goes alone.
      const bool coherent = (forward == live || forward == 0) && std::isfinite(p.su_lo + p.su_hi + p.sv_lo + p.sv_hi);
      if (!coherent) {
        ++counters.nodes;  // counted as the packet's one test
        for (int i = 0; i < p.lanes; ++i)
          if (p.live[size_t(i)]) p.hit[size_t(i)] = trace(p.ray[size_t(i)].org, p.ray[size_t(i)].dir, p.ray[size_t(i)].span);
        return;
      }
      p.forward = forward == live;
      if (lanes_at.size() < size_t(r.layout_.depth) + 1) {
        lanes_at.resize(size_t(r.layout_.depth) + 1);
        for (auto& l : lanes_at) l.reserve(kMaxLanes);
      }
      std::vector<uint16_t>& all = lanes_at[0];
      all.clear();
      for (int i = 0; i < p.lanes; ++i)
        if (p.live[size_t(i)]) all.push_back(uint16_t(i));
      Node root;
      root.page = page(OctreeLayout::page_id(0, Vec3s(0)));
      root.min = root.page->nodes[0][0].min, root.max = root.page->nodes[0][0].max;
      descend_packet(p, root, all, K, U, V);
    }

    /// Whether the packet's frustum meets the box [lo, hi] (finest voxel coordinates): one test
    /// for every lane, before each lane's own.
    bool packet_meets(const Packet& p, const Vec3d& lo, const Vec3d& hi, int K, int U, int V) const {
      double k0 = lo[K], k1 = hi[K];
      if (p.forward) k0 = std::max(k0, p.o[K]);
      else k1 = std::min(k1, p.o[K]);
      if (k0 > k1) return false;
      const double s0 = k0 - p.o[K], s1 = k1 - p.o[K];
      const double u_lo = p.o[U] + std::min({s0 * p.su_lo, s0 * p.su_hi, s1 * p.su_lo, s1 * p.su_hi});
      const double u_hi = p.o[U] + std::max({s0 * p.su_lo, s0 * p.su_hi, s1 * p.su_lo, s1 * p.su_hi});
      if (u_hi < lo[U] || u_lo > hi[U]) return false;
      const double v_lo = p.o[V] + std::min({s0 * p.sv_lo, s0 * p.sv_hi, s1 * p.sv_lo, s1 * p.sv_hi});
      const double v_hi = p.o[V] + std::max({s0 * p.sv_lo, s0 * p.sv_hi, s1 * p.sv_lo, s1 * p.sv_hi});
      if (v_hi < lo[V] || v_lo > hi[V]) return false;
      return true;
    }

    Box3d node_box(const Node& n) const {
      const int64_t w = width(n.depth);
      const double reach = lod_reach(n);
      Vec3d lo, hi;
      for (int a = 0; a < 3; ++a)
        lo[a] = double(n.c[a] * w), hi[a] = std::min(double((n.c[a] + 1) * w) + reach, double(r.layout_.dims[a] - 1));
      return {lo, hi};
    }

    void descend_packet(Packet& p, const Node& n, const std::vector<uint16_t>& parent_lanes, int K, int U, int V) {
      ++counters.nodes;
      if (!crosses(n.min, n.max)) return;
      const Box3d box = node_box(n);
      if (!packet_meets(p, box.lo, box.hi, K, U, V)) return;
      std::vector<uint16_t>& lanes = lanes_at[size_t(n.depth) + 1];
      lanes_through(p, box, parent_lanes, lanes);
      if (lanes.empty()) return;
      if (n.unread_page) {
        Node read = n;
        read.page = page(n.unread_page);
        read.unread_page = 0;
        lod_leaf(read) ? packet_cells(p, read, lanes, K, U, V) : descend_children(p, read, lanes, K, U, V);
        return;
      }
      if (lod_leaf(n)) return packet_cells(p, n, lanes, K, U, V);
      descend_children(p, n, lanes, K, U, V);
    }

    void descend_children(Packet& p, const Node& n, const std::vector<uint16_t>& lanes, int K, int U, int V) {
      // The half of the children nearer along K first: a lane's hit there is nearer than any
      // in the far half; within a half, each lane keeps its nearest.
      const int near = p.forward ? 0 : 1;
      for (int half : {near, 1 - near})
        for (int oct = 0; oct < 8; ++oct) {
          if (((oct >> K) & 1) != half) continue;
          const Node c = child(n, oct);
          if (c.depth >= 0) descend_packet(p, c, lanes, K, U, V);
        }
    }

    /// Voxels lo + {0, 1, 2}^3 of the cap n (lo = 2 n.c), x fastest: the cap's own 8 and its
    /// forward neighbours', one lookup per neighbouring cap. Voxels past the volume's last are
    /// never a corner of a cell; they are left at the cap's first.
    void cap_block(const Node& n, const Vec3s& lo, double block[27]) {
      const T* own = own_scalars(n);
      const Vec3s all = r.nodes_at_[size_t(n.depth)];
      for (int nb = 0; nb < 8; ++nb) {
        const Vec3s off{nb & 1, (nb >> 1) & 1, (nb >> 2) & 1};
        const Vec3s cc = n.c + off;
        if (cc.x >= all.x || cc.y >= all.y || cc.z >= all.z) {
          for (int64_t z = 0; z < 3; ++z)
            for (int64_t y = 0; y < 3; ++y)
              for (int64_t x = 0; x < 3; ++x)
                if ((x == 2) == bool(off.x) && (y == 2) == bool(off.y) && (z == 2) == bool(off.z))
                  block[(z * 3 + y) * 3 + x] = own ? double(own[0]) : n.constant;
          continue;
        }
        const OctreeScalars<T>* other = nb == 0 ? nullptr : &scalars_at(n.depth, cc);
        for (int64_t z = off.z * 2; z <= (off.z ? 2 : 1); ++z)
          for (int64_t y = off.y * 2; y <= (off.y ? 2 : 1); ++y)
            for (int64_t x = off.x * 2; x <= (off.x ? 2 : 1); ++x) {
              const int octant = int((lo.x + x) & 1) | int(((lo.y + y) & 1) << 1) | int(((lo.z + z) & 1) << 2);
              block[(z * 3 + y) * 3 + x] = nb == 0 ? (own ? double(own[octant]) : n.constant) : double((*other)[octant]);
            }
      }
    }

    /// A cap's cells for the packet: each live lane visits only the cells its ray crosses in
    /// each of the cap's slices along K (at most 2 x 2 a slice: K is the major axis), nearer
    /// slice first, and stops at its first hit; a cell's corners are gathered once, for the
    /// first lane that needs them, and shared by the others.
    void packet_cells(Packet& p, const Node& n, const std::vector<uint16_t>& lanes, int K, int U, int V) {
      // The node's cells at its own level L (0 at the caps): coordinates in level-L voxels, where
      // voxel i sits at finest coordinate (i + 1/2) 2^L - 1/2; rays keep their parameter t.
      const int L = r.layout_.level_of_depth(n.depth);
      const double scale = 1.0 / double(int64_t(1) << L);
      const auto to_level = [&](const Vec3d& x) { return L ? (x + Vec3d(0.5)) * scale - Vec3d(0.5) : x; };
      const Vec3s dims = r.level_dims_[size_t(L)];
      const Vec3s lo = n.c * int64_t(2);
      const Vec3s hi{std::min(lo.x + 1, dims.x - 2), std::min(lo.y + 1, dims.y - 2), std::min(lo.z + 1, dims.z - 2)};
      if (hi.x < lo.x || hi.y < lo.y || hi.z < lo.z) return;
      const Vec3d o = to_level(p.o);
      // The cap's voxels and its forward neighbours' (3 x 3 x 3, from up to 8 caps), gathered
      // once: every cell's corners are read from them.
      double block[27];
      if (r.p_.slice) cap_block(n, lo, block);
      double corners[8][8], vlo[8], vhi[8];
      uint8_t state[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // 0: not gathered, 1: may cross, 2: culled
      constexpr double kSlack = 1e-9;  // cell ranges are widened: the exact test is intersect()'s
      for (uint16_t i : lanes) {
        const PrimaryRay& ray = p.ray[size_t(i)];
        Hit& hit = p.hit[size_t(i)];
        const Vec3d org = to_level(ray.org), dir = L ? ray.dir * scale : ray.dir;
        const Vec3d inv = L ? p.inv[size_t(i)] / scale : p.inv[size_t(i)];
        const double su = ray.dir[U] * p.inv_dk[size_t(i)], sv = ray.dir[V] * p.inv_dk[size_t(i)];
        const int surface_before = hit.surface;
        const double t_before = hit.t;
        for (int64_t step = 0; step <= hi[K] - lo[K]; ++step) {
          const int64_t k = p.forward ? lo[K] + step : hi[K] - step;
          const double s0 = double(k) - o[K], s1 = s0 + 1;
          const double u0 = o[U] + s0 * su, u1 = o[U] + s1 * su, v0 = o[V] + s0 * sv, v1 = o[V] + s1 * sv;
          const int64_t a0 = std::max(lo[U], int64_t(std::floor(std::min(u0, u1) - kSlack)));
          const int64_t a1 = std::min(hi[U], int64_t(std::floor(std::max(u0, u1) + kSlack)));
          const int64_t b0 = std::max(lo[V], int64_t(std::floor(std::min(v0, v1) - kSlack)));
          const int64_t b1 = std::min(hi[V], int64_t(std::floor(std::max(v0, v1) + kSlack)));
          bool found = false;
          for (int64_t a = a0; a <= a1; ++a)
            for (int64_t b = b0; b <= b1; ++b) {
              Vec3s cell;
              cell[K] = k, cell[U] = a, cell[V] = b;
              const int local = int(cell.x - lo.x) | int((cell.y - lo.y) << 1) | int((cell.z - lo.z) << 2);
              if (state[local] == 0 && !r.p_.slice) {
                cell_corners(cell, n, own_scalars(n), corners[local], vlo[local], vhi[local]);
                state[local] = crosses_corners(vlo[local], vhi[local]) ? 1 : 2;
              }
              if (state[local] == 0) {
                double& l = vlo[local] = std::numeric_limits<double>::max();
                double& h = vhi[local] = std::numeric_limits<double>::lowest();
                const Vec3s q = cell - lo;
                for (int m = 0; m < 8; ++m) {
                  const double v = block[((q.z + ((m >> 2) & 1)) * 3 + q.y + ((m >> 1) & 1)) * 3 + q.x + (m & 1)];
                  corners[local][m] = v, l = std::min(l, v), h = std::max(h, v);
                }
                state[local] = crosses_corners(l, h) ? 1 : 2;
              }
              if (state[local] == 2) continue;
              found |= intersect(cell, corners[local], vlo[local], vhi[local], org, dir, inv, ray.span, hit);
            }
          if (found) break;  // the next slice is farther along this ray
        }
        if (hit.t != t_before || hit.surface != surface_before) hit.level = L;
      }
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
  int major_axis_ = 0;           // K, chosen in begin_frame()
  double eye_k_ = 0;             // the eye's K coordinate, finest voxels
  std::vector<double> lod_k_;    // per depth: the K distance from which a node is drawn at its own level
  std::vector<Vec3s> level_dims_;  // per level of detail
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
  e.info.quality_param = "dpdv";
  e.info.quality_sweep = {4.0, 2.0, 1.0, 0.5, 0.0};
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const OctreeCgtParams op = octree_cgt_params().bind(p);
    if (op.packet & (op.packet - 1))
      throw Error(Errc::invalid_argument, fmt::format("packet {} is not 1, 2, 4, 8 or 16", op.packet)).with_field("packet");
    return dispatch_value_type(ctx.octree().layout().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      return std::make_unique<OctreeCgtRenderer<decltype(stored)>>(ctx, op);
    });
  };
  return e;
}

}  // namespace brickyard
