// tet_bvh's traversal: packets through the top-level BVH and each cluster's BVH, isopolygons
// extracted per tet and tested against the packet, and the shading of a packet's hits.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>

#include <fmt/format.h>

#include "core/error.h"
#include "renderers/common/tet_geometry.h"
#include "renderers/tet_bvh/renderer.h"

namespace brickyard::tet_bvh {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// The marching-tets table: for each of the 16 cases (bit i set when vertex i lies above the
/// isovalue), the tet edges the isopolygon's vertices lie on, in cyclic order (3 or 4; none
/// for cases 0 and 15).
struct CaseTable {
  static constexpr int kEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  int8_t count[16] = {};
  int8_t edge[16][4] = {};
  CaseTable() {
    auto edge_of = [](int a, int b) {
      for (int e = 0; e < 6; ++e)
        if ((kEdges[e][0] == a && kEdges[e][1] == b) || (kEdges[e][0] == b && kEdges[e][1] == a)) return int8_t(e);
      return int8_t(-1);
    };
    for (int m = 1; m < 15; ++m) {
      std::array<int, 4> above{}, below{};
      int na = 0, nb = 0;
      for (int v = 0; v < 4; ++v) (m >> v & 1 ? above[size_t(na++)] : below[size_t(nb++)]) = v;
      if (na == 1 || nb == 1) {  // a triangle around the lone vertex
        const int lone = na == 1 ? above[0] : below[0];
        int k = 0;
        for (int v = 0; v < 4; ++v)
          if (v != lone) edge[m][k++] = edge_of(lone, v);
        count[m] = 3;
      } else {  // a quad: above a, b; below c, d; cyclic a-c, a-d, b-d, b-c
        const int a = above[0], b = above[1], c = below[0], d = below[1];
        edge[m][0] = edge_of(a, c), edge[m][1] = edge_of(a, d), edge[m][2] = edge_of(b, d), edge[m][3] = edge_of(b, c);
        count[m] = 4;
      }
    }
  }
};
const CaseTable kCases;

/// A tet's isopolygon for one isovalue, ready for a packet with origin o: its plane
/// (gradient g, g . x = c) and its edges' planes through o, oriented inwards.
struct Isopolygon {
  int n = 0;
  Vec3d gradient;
  double plane_offset = 0;  ///< c - g . o
  Vec3d edge_normal[4];     ///< s_e * cross(a - o, b - o): inside where dot(., d) >= 0
};

/// The isopolygon's vertices in tet `tet` for `iso`, in cyclic order: how many (3 or 4; 0 when
/// the isosurface misses the tet). Each comes from its edge's ends in canonical order, so the
/// tets that share an edge put the vertex at the same place, to the bit.
int isopolygon_vertices(const TetGeometry& tet, double iso, Vec3d* v) {
  const Vec3d* p = tet.p;
  const double* f = tet.f;
  int mask = 0;
  for (int k = 0; k < 4; ++k) mask |= int(f[k] > iso) << k;
  const int n = kCases.count[mask];
  for (int k = 0; k < n; ++k) {
    int a = CaseTable::kEdges[kCases.edge[mask][k]][0], b = CaseTable::kEdges[kCases.edge[mask][k]][1];
    if (position_less(p[b], p[a])) std::swap(a, b);
    const double w = (iso - f[a]) / (f[b] - f[a]);
    v[k] = p[a] + (p[b] - p[a]) * w;
  }
  return n;
}

/// The isopolygon of n vertices v, ready for a packet with origin o; false when it is seen
/// edge-on from o (no ray meets its inside) or has no area. Vertices that coincide (a tet
/// vertex whose value is the isovalue ends each of its edges that cross: an unjittered
/// lattice's values are often exactly the isovalue) count once: a zero-length edge has no
/// plane, and once made the whole polygon look edge-on (2% of an image's pixels lost).
bool isopolygon_planes(const TetGeometry& tet, const Vec3d* in, int n_in, const Vec3d& o, Isopolygon& poly) {
  Vec3d v[4];
  int n = 0;
  for (int k = 0; k < n_in; ++k)
    if (n == 0 || !(in[k] == v[n - 1])) v[n++] = in[k];
  if (n > 1 && v[n - 1] == v[0]) --n;
  if (n < 3) return false;
  poly.gradient = tet.gradient();
  poly.plane_offset = dot(poly.gradient, v[0] - o);
  Vec3d centre(0.0);
  for (int k = 0; k < n; ++k) centre += v[k];
  centre = centre / double(n);
  for (int k = 0; k < n; ++k) {
    Vec3d a = v[k], b = v[(k + 1) % n];
    if (position_less(b, a)) std::swap(a, b);
    const Vec3d m = cross(a - o, b - o);
    const double side = dot(m, centre - o);
    if (side == 0) return false;
    poly.edge_normal[k] = side > 0 ? m : -m;
  }
  poly.n = n;
  return true;
}

struct Local {
  uint64_t packet_box = 0, ray_box = 0, isorange = 0, extractions = 0, ray_polygon = 0, full_miss = 0, full_hit = 0;
  uint64_t footprint_culled = 0, footprint_culled_box = 0, touched = 0, missing = 0;
};

/// Lanes [x0, x1] x [y0, y1] of a primary packet.
struct LaneRect {
  int x0 = 0, x1 = -1, y0 = 0, y1 = -1;
  bool empty() const { return x0 > x1 || y0 > y1; }
};

/// The lanes of a primary packet whose rays can meet the convex hull of `points`: the pixels
/// its projection covers, with a pixel of margin for rounding. False when some point is not in
/// front of the eye (then any lane may).
bool lanes_seeing(const Packet& p, const Vec3d* points, int n, LaneRect& r) {
  double lo_x = kInf, hi_x = -kInf, lo_y = kInf, hi_y = -kInf;
  for (int k = 0; k < n; ++k) {
    double px, py;
    if (!p.image->pixel_of(points[k], px, py)) return false;
    lo_x = std::min(lo_x, px), hi_x = std::max(hi_x, px), lo_y = std::min(lo_y, py), hi_y = std::max(hi_y, py);
  }
  const int h = (p.lanes + p.w - 1) / p.w;
  // Lane (x, y) is the ray through the pixel centre (x0 + x + 0.5, y0 + y + 0.5).
  auto first = [](double v, int size) { return int(std::ceil(std::clamp(v - 1.5, -1.0, double(size)))); };
  auto last = [](double v, int size) { return int(std::floor(std::clamp(v + 0.5, -1.0, double(size)))); };
  r.x0 = std::max(0, first(lo_x - p.x0, p.w)), r.x1 = std::min(p.w - 1, last(hi_x - p.x0, p.w));
  r.y0 = std::max(0, first(lo_y - p.y0, h)), r.y1 = std::min(h - 1, last(hi_y - p.y0, h));
  return true;
}

bool lanes_seeing(const Packet& p, const BvhNode& n, LaneRect& r) {
  Vec3d corners[8];
  for (int k = 0; k < 8; ++k)
    corners[k] = Vec3d(k & 1 ? n.hi[0] : n.lo[0], k & 2 ? n.hi[1] : n.lo[1], k & 4 ? n.hi[2] : n.lo[2]);
  return lanes_seeing(p, corners, 8, r);
}

/// Where ray l enters a box within its span (infinity when it misses it).
double ray_box_entry(const Packet& p, int l, const BvhNode& n) {
  double a = p.tmin[l], b = p.limit(l);
  const double inverse[3] = {p.ix[l], p.iy[l], p.iz[l]};
  for (int ax = 0; ax < 3; ++ax) {
    const double inv = inverse[ax];
    double t0 = (double(n.lo[ax]) - p.origin[ax]) * inv, t1 = (double(n.hi[ax]) - p.origin[ax]) * inv;
    if (t0 > t1) std::swap(t0, t1);
    if (std::isnan(t0)) t0 = -kInf;  // the ray lies in the slab's plane: 0 * inf
    if (std::isnan(t1)) t1 = kInf;
    a = std::max(a, t0), b = std::min(b, t1);
  }
  return a <= b ? a : kInf;
}

bool ray_hits_box(const Packet& p, int l, const BvhNode& n) { return ray_box_entry(p, l, n) < kInf; }

/// Whether the packet's frustum (directions within [dlo, dhi] from the shared origin) misses a
/// box, by interval arithmetic: the latest possible entry after the earliest possible exit.
bool frustum_misses(const Packet& p, const BvhNode& n) {
  double entry = p.t_lo, exit = p.t_hi;
  for (int ax = 0; ax < 3; ++ax) {
    if (!(p.dlo[ax] > 0 || p.dhi[ax] < 0)) continue;  // the interval holds 0: no bound on this axis
    const double lo = double(n.lo[ax]) - p.origin[ax], hi = double(n.hi[ax]) - p.origin[ax];
    const double near = p.dlo[ax] > 0 ? lo : hi, far = p.dlo[ax] > 0 ? hi : lo;
    // t = x / d is monotonic in d over an interval without 0: its bounds are at the ends.
    entry = std::max(entry, std::min(near / p.dlo[ax], near / p.dhi[ax]));
    exit = std::min(exit, std::max(far / p.dlo[ax], far / p.dhi[ax]));
  }
  return entry > exit;
}

bool iso_in(const BvhNode& n, const std::vector<double>& iso) {
  for (double v : iso)
    if (v >= double(n.lo[3]) && v <= double(n.hi[3])) return true;
  return false;
}

}  // namespace

thread_local uint32_t TetBvhRenderer::current_tile = 0;

void Packet::prepare() {
  for (int a = 0; a < 3; ++a) dlo[a] = kInf, dhi[a] = -kInf;
  t_lo = kInf, t_hi = -kInf;
  for (int l = 0; l < lanes; ++l) ix[l] = 1.0 / dx[l];
  for (int l = 0; l < lanes; ++l) iy[l] = 1.0 / dy[l];
  for (int l = 0; l < lanes; ++l) iz[l] = 1.0 / dz[l];
  for (int l = 0; l < lanes; ++l) {
    if (!active[l]) continue;
    const double d[3] = {dx[l], dy[l], dz[l]};
    for (int a = 0; a < 3; ++a) dlo[a] = std::min(dlo[a], d[a]), dhi[a] = std::max(dhi[a], d[a]);
    t_lo = std::min(t_lo, tmin[l]), t_hi = std::max(t_hi, limit(l));
  }
}

void TetBvhRenderer::leaf(Packet& p, const TetClusterPage& page, const ClusterBvh& bvh, const BvhNode& node, int first) const {
  Local c;
  Isopolygon poly;
  bool hits = false;
  for (uint32_t s = node.index; s < node.index + node.count; ++s) {
    const float lo = bvh.tet_range[2 * size_t(s)], hi = bvh.tet_range[2 * size_t(s) + 1];
    const uint32_t t = bvh.bvh.order[s];
    std::optional<TetGeometry> tet;
    for (size_t k = 0; k < iso_.size(); ++k) {
      ++c.isorange;
      if (!(iso_[k] >= lo && iso_[k] <= hi)) continue;
      ++c.extractions;
      if (!tet) tet.emplace(page, t, step_);
      Vec3d v[4];
      const int n = isopolygon_vertices(*tet, iso_[k], v);
      if (n == 0) continue;
      // A primary packet tests only the lanes whose pixels the polygon's projection covers
      // (a few of the 256: at a million tets a polygon covers some ten pixels), and none
      // when no lane there is still active.
      LaneRect r;
      const bool footprint = p.image && lanes_seeing(p, v, n, r);
      if (footprint) {
        bool any = false;
        for (int y = r.y0; y <= r.y1 && !any; ++y)
          for (int x = r.x0; x <= r.x1 && !any; ++x) {
            const int l = y * p.w + x;
            any = l >= first && l < p.lanes && p.active[l];
          }
        if (!any) {
          c.footprint_culled += uint64_t(p.lanes - first);
          continue;
        }
      }
      if (!isopolygon_planes(*tet, v, n, p.origin, poly)) continue;
      auto test_lane = [&](int l, bool all_inside) {
        if (!p.active[l]) return;
        ++c.ray_polygon;
        const Vec3d d = p.dir(l);
        if (!all_inside) {  // the edges first: most lanes a footprint holds miss the polygon
          for (int e = 0; e < poly.n; ++e)
            if (!(dot(poly.edge_normal[e], d) >= 0)) return;
        }
        const double den = dot(poly.gradient, d);
        if (den == 0) return;
        const double th = poly.plane_offset / den;
        if (!(th >= p.tmin[l] && th <= p.tmax[l])) return;
        if (th > p.hit_t[l] || (th == p.hit_t[l] && int(k) >= p.hit_surface[l])) return;
        p.hit_t[l] = th;
        p.hit_surface[l] = int(k);
        p.gx[l] = poly.gradient.x, p.gy[l] = poly.gradient.y, p.gz[l] = poly.gradient.z;
        if (p.any_hit) p.active[l] = false;
        hits = true;
      };
      if (footprint) {
        uint64_t tested = 0;
        for (int y = r.y0; y <= r.y1; ++y)
          for (int x = r.x0; x <= r.x1; ++x) {
            const int l = y * p.w + x;
            if (l < first || l >= p.lanes) continue;
            ++tested;
            test_lane(l, false);
          }
        c.footprint_culled += uint64_t(p.lanes - first) - tested;
        continue;
      }
      // The four corner rays: a packet wholly outside one edge misses; wholly inside every
      // edge, every ray is inside.
      bool all_inside = false;
      if (p.corners[0] >= 0 && p_.corner_culling) {
        bool miss = false;
        all_inside = true;
        for (int e = 0; e < poly.n && !miss; ++e) {
          int outside = 0;
          for (int cr : p.corners) outside += dot(poly.edge_normal[e], p.dir(cr)) < 0;
          miss = outside == 4;
          all_inside = all_inside && outside == 0;
        }
        if (miss) {
          c.full_miss += uint64_t(p.lanes - first);
          continue;
        }
        if (all_inside) c.full_hit += uint64_t(p.lanes - first);
      }
      for (int l = first; l < p.lanes; ++l) test_lane(l, all_inside);
    }
  }
  // The frustum's far bound shrinks with the hits: boxes behind every ray's hit are culled
  // whole (they still project onto the packet).
  if (hits) {
    double far = -kInf;  // a local, so that the reduction does not wait on a store each lane
    for (int l = 0; l < p.lanes; ++l) far = std::max(far, p.active[l] ? p.limit(l) : -kInf);
    p.t_hi = far;
  }
  counters_.isorange_tests.fetch_add(c.isorange, std::memory_order_relaxed);
  counters_.extractions.fetch_add(c.extractions, std::memory_order_relaxed);
  counters_.ray_polygon_tests.fetch_add(c.ray_polygon, std::memory_order_relaxed);
  counters_.full_miss_rays.fetch_add(c.full_miss, std::memory_order_relaxed);
  counters_.full_hit_rays.fetch_add(c.full_hit, std::memory_order_relaxed);
  counters_.footprint_culled_rays.fetch_add(c.footprint_culled, std::memory_order_relaxed);
}

namespace {

/// The first lane after `first` whose ray meets box n (p.lanes when none): a primary packet
/// searches the lanes the box's projection covers (none: the packet misses it); others test
/// the packet's frustum, then each ray in turn.
int next_hit(const Packet& p, const BvhNode& n, int first, Local& c) {
  if (p.lanes == 1) return p.lanes;
  ++c.packet_box;
  if (frustum_misses(p, n)) return p.lanes;
  LaneRect r;
  if (p.image && lanes_seeing(p, n, r)) {
    uint64_t tested = 0;
    for (int y = r.y0; y <= r.y1; ++y)
      for (int x = std::max(r.x0, y * p.w > first ? r.x0 : first + 1 - y * p.w); x <= r.x1; ++x) {
        const int l = y * p.w + x;
        if (l >= p.lanes) break;
        if (!p.active[l]) continue;
        ++c.ray_box, ++tested;
        if (ray_hits_box(p, l, n)) {
          c.footprint_culled_box += uint64_t(l - first) - tested;
          return l;
        }
      }
    c.footprint_culled_box += uint64_t(p.lanes - first - 1) - tested;
    return p.lanes;
  }
  for (int next = first + 1; next < p.lanes; ++next) {
    if (!p.active[next]) continue;
    ++c.ray_box;
    if (ray_hits_box(p, next, n)) return next;
  }
  return p.lanes;
}

/// The packet's walk of one BVH: implicit test, speculative first-active box test, frustum,
/// then the next ray that hits; `at_leaf(node, first)` for leaves. Near child first.
template <typename AtLeaf>
void walk(const BoxBvh& bvh, Packet& p, const std::vector<double>& iso, int first_active, Local& c, AtLeaf&& at_leaf) {
  if (bvh.nodes.empty()) return;
  struct Entry {
    uint32_t node;
    int first;
  };
  Entry stack[128];
  int top = 0;
  stack[top++] = {0, first_active};
  while (top) {
    const Entry e = stack[--top];
    const BvhNode& n = bvh.nodes[e.node];
    if (!iso_in(n, iso)) continue;
    int first = e.first;
    while (first < p.lanes && !p.active[first]) ++first;
    if (first >= p.lanes) continue;
    ++c.ray_box;
    if (!ray_hits_box(p, first, n)) {
      first = next_hit(p, n, first, c);
      if (first >= p.lanes) continue;
    }
    if (n.leaf()) {
      at_leaf(n, first);
      continue;
    }
    const double d = n.axis == 0 ? p.dx[first] : n.axis == 1 ? p.dy[first] : p.dz[first];
    const uint32_t left = e.node + 1, right = n.index;
    if (top + 2 > 128) continue;  // deeper than any tree of median splits
    if (d >= 0) stack[top++] = {right, first}, stack[top++] = {left, first};
    else stack[top++] = {left, first}, stack[top++] = {right, first};
  }
}

}  // namespace

void TetBvhRenderer::trace_cluster(Packet& p, const TetClusterPage& page, const ClusterBvh& bvh, int first,
                                   RayCounters& counters) const {
  Local c;
  walk(bvh.bvh, p, iso_, first, c, [&](const BvhNode& n, int f) {
    ++counters.cells;
    leaf(p, page, bvh, n, f);
  });
  counters.nodes += c.ray_box;
  counters_.packet_box_tests.fetch_add(c.packet_box, std::memory_order_relaxed);
  counters_.ray_box_tests.fetch_add(c.ray_box, std::memory_order_relaxed);
  counters_.footprint_culled_box_rays.fetch_add(c.footprint_culled_box, std::memory_order_relaxed);
}

uint64_t TetBvhRenderer::trace(Packet& p, RayCounters& counters) const {
  p.prepare();
  Local c;
  walk(top_, p, iso_, 0, c, [&](const BvhNode& n, int first) {
    for (uint32_t i = n.index; i < n.index + n.count; ++i) {
      const uint32_t cluster = top_.order[i];
      ++c.touched;
      ++counters.bricks;
      ++counters.lookups;
      // Nearer clusters first: the priority falls with the distance to the packet's origin.
      const Box3d b = tets_.clusters()[cluster].bounds();
      const float priority = float(1.0 / (1e-9 + distance(b, p.origin)));
      // Exact frames ask between passes, nearest first and no more than L1 keeps at once
      // (note_missing); frames that converge over frames ask at once.
      PageHandle h = ctx_.pages().lookup({RecordKind::tet_cluster, cluster}, priority, !frame_exact_);
      if (!h.resident() && !h.failed() && frame_exact_) {
        // A tile in focus (passes made no progress: L1 holds less than its rays need at once)
        // waits for each cluster where it needs it; other tiles ask between passes.
        if (current_tile == focus_tile_) h = ctx_.pages().fetch_or_failed({RecordKind::tet_cluster, cluster});
        else note_missing(cluster, priority, current_tile);
      }
      if (!h.resident()) {
        if (h.failed()) continue;  // unreadable: its tets are left out (the cache reports it)
        ++c.missing;
        ++counters.misses;
        // What each ray has passed before this cluster is certain; from its entry on, not.
        for (int l = first; l < p.lanes; ++l)
          if (p.active[l]) p.t_miss[l] = std::min(p.t_miss[l], ray_box_entry(p, l, n));
        continue;
      }
      ++counters.hits;
      const TetClusterPage page = TetClusterPage::view({h.bytes(), tets_.page_bytes()});
      const auto bvh = cluster_bvh(cluster, page);
      trace_cluster(p, page, *bvh, first, counters);
    }
  });
  counters.nodes += c.ray_box;
  counters_.packet_box_tests.fetch_add(c.packet_box, std::memory_order_relaxed);
  counters_.ray_box_tests.fetch_add(c.ray_box, std::memory_order_relaxed);
  counters_.footprint_culled_box_rays.fetch_add(c.footprint_culled_box, std::memory_order_relaxed);
  counters_.clusters_touched.fetch_add(c.touched, std::memory_order_relaxed);
  counters_.clusters_missing.fetch_add(c.missing, std::memory_order_relaxed);
  return c.missing;
}

}  // namespace brickyard::tet_bvh
