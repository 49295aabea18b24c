// The reference for tetrahedral meshes: simple, slow, double precision, exact.
//
// A ray meets the clusters whose bounds it crosses (a BVH over the cluster table) and whose
// value range in the scene's time step can contribute (an isovalue inside it, visible opacity,
// or anything for MIP); those, and only those, are fetched through the cache. Inside a cluster
// a BVH over its tets (built the first time the cluster is used, kept beside the cache) finds
// the tets whose boxes the ray crosses, and each gives the exact closed interval the ray spends
// inside it. That interval comes from the four face planes, each computed from its three
// vertices in one canonical order (sorted by position), so the two tets sharing a face compute
// the same plane to the last bit and the same crossing parameter: one's exit is the other's
// entry, and no ray slips between them. Edges and vertices shared by more tets are covered by a
// tolerance of 1e-9 of the tet's size on the crossing; concave boundaries need nothing (every
// tet the ray meets is found, in or out of the mesh).
//
// - iso: the first crossing of up to 4 isovalues by the linear field of each tet; normals
//   from the tet's gradient; point-light (and other) shadows by the same search towards the
//   light; the clip box cuts the ray.
// - dvr: every tet's segment in ray order, the transfer function integrated along it between
//   its knots in steps of optical depth at most 1e-3 (colour and opacity piecewise linear in
//   the value, the value linear along the segment), opacity per unit length of the mesh.
// - mip: the largest value at the ends of every segment (linear inside a tet).

#include "renderers/reference/tets.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <fmt/format.h>

#include "renderers/common/pixel.h"
#include "renderers/common/shading.h"
#include "renderers/common/tet_geometry.h"

namespace brickyard {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kOpaque = 1 - 1e-7;

/// A bounding volume hierarchy over boxes, in float (conservatively rounded), leaves of up to
/// four items; used for the cluster table and for the tets of a cluster.
class BoxTree {
 public:
  struct Node {
    float lo[3], hi[3];
    uint32_t first = 0;  ///< leaf: first item in order(); inner: the right child (the left is next)
    uint32_t count = 0;  ///< items of a leaf; 0 for inner nodes
  };

  BoxTree() = default;
  /// `boxes`: lo x y z, hi x y z per item.
  explicit BoxTree(const std::vector<float>& boxes) {
    const size_t n = boxes.size() / 6;
    order_.resize(n);
    for (size_t i = 0; i < n; ++i) order_[i] = uint32_t(i);
    if (n) build(boxes, 0, n);
  }
  const std::vector<uint32_t>& order() const { return order_; }
  size_t bytes() const { return nodes_.size() * sizeof(Node) + order_.size() * sizeof(uint32_t); }

  /// Calls f(item) for every item whose box the ray o + t d meets for t in [t0, t1()] (t1 is
  /// re-read, so a search may shorten it); f returns false to stop.
  template <typename Limit, typename F>
  void traverse(const Vec3d& o, const Vec3d& inv_d, double t0, Limit&& t1, F&& f) const {
    if (nodes_.empty()) return;
    uint32_t stack[64];
    int top = 0;
    stack[top++] = 0;
    while (top) {
      const Node& n = nodes_[stack[--top]];
      double a = t0, b = t1();
      for (int ax = 0; ax < 3; ++ax) {
        double ta = (double(n.lo[ax]) - o[ax]) * inv_d[ax], tb = (double(n.hi[ax]) - o[ax]) * inv_d[ax];
        if (ta > tb) std::swap(ta, tb);
        if (std::isnan(ta)) ta = -kInf;  // 0 * inf: the ray lies in the slab's plane
        if (std::isnan(tb)) tb = kInf;
        a = std::max(a, ta), b = std::min(b, tb);
      }
      if (a > b) continue;
      if (n.count) {
        for (uint32_t i = n.first; i < n.first + n.count; ++i)
          if (!f(order_[i])) return;
      } else {
        if (top + 2 > 64) continue;  // cannot happen for trees of median splits
        stack[top++] = n.first;
        stack[top++] = uint32_t(&n - nodes_.data()) + 1;
      }
    }
  }

 private:
  uint32_t build(const std::vector<float>& boxes, size_t begin, size_t end) {
    const uint32_t index = uint32_t(nodes_.size());
    nodes_.push_back({});
    Node n;
    for (int a = 0; a < 3; ++a) n.lo[a] = std::numeric_limits<float>::infinity(), n.hi[a] = -n.lo[a];
    for (size_t i = begin; i < end; ++i)
      for (int a = 0; a < 3; ++a) {
        n.lo[a] = std::min(n.lo[a], boxes[size_t(order_[i]) * 6 + size_t(a)]);
        n.hi[a] = std::max(n.hi[a], boxes[size_t(order_[i]) * 6 + 3 + size_t(a)]);
      }
    for (int a = 0; a < 3; ++a) {  // outward by a float step: the double slab test never misses
      n.lo[a] = std::nextafter(n.lo[a], -std::numeric_limits<float>::infinity());
      n.hi[a] = std::nextafter(n.hi[a], std::numeric_limits<float>::infinity());
    }
    if (end - begin <= 4) {
      n.first = uint32_t(begin), n.count = uint32_t(end - begin);
      nodes_[index] = n;
      return index;
    }
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (n.hi[a] - n.lo[a] > n.hi[axis] - n.lo[axis]) axis = a;
    const size_t mid = begin + (end - begin) / 2;
    auto centre = [&](uint32_t i) { return boxes[size_t(i) * 6 + size_t(axis)] + boxes[size_t(i) * 6 + 3 + size_t(axis)]; };
    std::nth_element(order_.begin() + long(begin), order_.begin() + long(mid), order_.begin() + long(end),
                     [&](uint32_t x, uint32_t y) { return centre(x) < centre(y) || (centre(x) == centre(y) && x < y); });
    build(boxes, begin, mid);
    n.first = build(boxes, mid, end);
    n.count = 0;
    nodes_[index] = n;
    return index;
  }

  std::vector<Node> nodes_;
  std::vector<uint32_t> order_;
};

struct ClusterIndex {
  BoxTree tets;
};

class TetReference final : public Renderer {
 public:
  explicit TetReference(const RenderContext& ctx)
      : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), tets_(ctx.tets()), shading_(scene_.shading, geo_) {
    const auto clusters = tets_.clusters();
    std::vector<float> boxes;
    boxes.reserve(clusters.size() * 6);
    for (size_t c = 0; c < clusters.size(); ++c) {
      const TetCluster& e = clusters[c];
      boxes.insert(boxes.end(), {e.lo[0], e.lo[1], e.lo[2], e.hi[0], e.hi[1], e.hi[2]});
    }
    clusters_ = BoxTree(boxes);
    clip_ = Box3d(geo_.to_world(geo_.voxel_clip.lo), geo_.to_world(geo_.voxel_clip.hi));
  }

  void begin_frame(const FrameSetup& setup) override {
    if (!visible_.empty() && step_ == uint32_t(setup.time_step)) return;
    step_ = uint32_t(setup.time_step);
    const size_t clusters = tets_.clusters().size();
    visible_.resize(clusters);
    for (size_t c = 0; c < clusters; ++c) {
      const TetStepRange r = tets_.range(c, int(step_));
      visible_[c] = scene_.mode == RenderMode::mip || scene_.value_range_visible(r.min, r.max);
    }
  }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    const ImageRays rays(setup.camera, setup.width, setup.height);
    const bool gradients = ctx_.needs_gradients(setup.outputs);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) {
        ++counters.rays;
        const Rayd ray = rays.ray(x + 0.5, y + 0.5);
        PixelResult px;
        px.color = scene_.background;
        Interval<double> span = intersect(ray, clip_);
        span.t0 = std::max(span.t0, 0.0);
        if (!span.empty() && std::isfinite(span.t1)) {
          switch (scene_.mode) {
            case RenderMode::iso: iso(setup, ray, span, gradients, px, counters); break;
            case RenderMode::dvr: dvr(setup, ray, span, gradients, px, counters); break;
            case RenderMode::mip: mip(ray, span, px, counters); break;
          }
        }
        write_pixel(out, x, y, px);
      }
  }

 private:
  const ClusterIndex& index_of(uint64_t c, const TetClusterPage& page) const {
    {
      std::lock_guard lock(mutex_);
      if (auto it = indices_.find(c); it != indices_.end()) return *it->second;
    }
    std::vector<float> boxes(size_t(page.tet_count) * 6);
    for (uint32_t t = 0; t < page.tet_count; ++t) {
      float* b = &boxes[size_t(t) * 6];
      for (int a = 0; a < 3; ++a) b[a] = std::numeric_limits<float>::infinity(), b[3 + a] = -b[a];
      for (uint32_t s = 0; s < page.position_sets; ++s)  // a box over every step: one index for them all
        for (int k = 0; k < 4; ++k) {
          const float* q = page.positions_at(s) + 3 * size_t(page.corners[4 * size_t(t) + size_t(k)]);
          for (int a = 0; a < 3; ++a) b[a] = std::min(b[a], q[a]), b[3 + a] = std::max(b[3 + a], q[a]);
        }
    }
    auto built = std::make_unique<ClusterIndex>(ClusterIndex{BoxTree(boxes)});
    std::lock_guard lock(mutex_);
    auto [it, added] = indices_.try_emplace(c, std::move(built));
    return *it->second;
  }

  PageHandle fetch(uint64_t c, RayCounters& counters) const {
    ++counters.bricks;
    ++counters.lookups;
    // An unreadable cluster is failed: its tets are left out, and the cache reports it.
    return ctx_.pages().fetch_or_failed({RecordKind::tet_cluster, c});
  }

  /// Clusters the ray o + t d meets in [t0, t1] that can contribute, nearest entry first.
  std::vector<std::pair<double, uint32_t>> clusters_along(const Vec3d& o, const Vec3d& d, double t0, double t1,
                                                          RayCounters& counters) const {
    std::vector<std::pair<double, uint32_t>> out;
    const Vec3d inv = Vec3d(1.0) / d;
    clusters_.traverse(o, inv, t0, [&] { return t1; }, [&](uint32_t c) {
      ++counters.nodes;
      if (!visible_[c]) return true;
      const Interval<double> s = intersect(Rayd(o, d), tets_.clusters()[c].bounds());
      if (!s.empty() && s.t1 >= t0 && s.t0 <= t1) out.emplace_back(std::max(s.t0, t0), c);
      return true;
    });
    std::sort(out.begin(), out.end());
    return out;
  }

  struct Hit {
    double t = kInf;
    int surface = -1;
    Vec3d gradient{0.0};
  };

  /// The first crossing of any isosurface along o + t d, t in [t0, t1].
  Hit first_crossing(const Vec3d& o, const Vec3d& d, double t0, double t1, RayCounters& counters) const {
    Hit hit;
    const auto& surfaces = scene_.isosurfaces;
    const Vec3d inv = Vec3d(1.0) / d;
    for (const auto& [entry, c] : clusters_along(o, d, t0, t1, counters)) {
      if (entry > hit.t) break;
      const PageHandle h = fetch(c, counters);
      if (h.failed()) continue;
      const TetClusterPage page = TetClusterPage::view({h.bytes(), tets_.page_bytes()});
      const ClusterIndex& index = index_of(c, page);
      index.tets.traverse(o, inv, t0, [&] { return std::min(t1, hit.t); }, [&](uint32_t t) {
        const float* val = page.values_at(step_);
        const uint32_t* q = page.corners + 4 * size_t(t);
        const float lo = std::min({val[q[0]], val[q[1]], val[q[2]], val[q[3]]});
        const float hi = std::max({val[q[0]], val[q[1]], val[q[2]], val[q[3]]});
        bool any = false;
        for (const Isosurface& s : surfaces) any = any || (s.value >= lo && s.value <= hi);
        if (!any) return true;
        ++counters.cells;
        const TetGeometry g(page, t, step_);
        const Interval<double> span = g.span(o, d, t0, std::min(t1, hit.t));
        const double tol = 1e-9 * g.size();
        if (!(span.t0 <= span.t1 + tol)) return true;
        const Vec3d gradient = g.gradient();
        const double alpha = g.value_at(o + d * span.t0, gradient), beta = dot(gradient, d);
        for (size_t k = 0; k < surfaces.size(); ++k) {
          const double iso = surfaces[k].value;
          if (iso < lo || iso > hi) continue;
          ++counters.samples;
          double root;
          if (beta != 0) root = span.t0 + (iso - alpha) / beta;
          else if (alpha == iso) root = span.t0;
          else continue;
          if (!(root >= span.t0 - tol && root <= span.t1 + tol)) continue;
          root = std::clamp(root, std::min(span.t0, span.t1), std::max(span.t0, span.t1));
          if (root < t0 || root > t1) continue;
          if (root < hit.t || (root == hit.t && int(k) < hit.surface)) hit = Hit{root, int(k), gradient};
        }
        return true;
      });
    }
    return hit;
  }

  void iso(const FrameSetup& setup, const Rayd& ray, Interval<double> span, bool gradients, PixelResult& px,
           RayCounters& counters) const {
    const Hit hit = first_crossing(ray.org, ray.dir, span.t0, span.t1, counters);
    if (hit.surface < 0) return;
    px.depth = hit.t;
    px.alpha = 1;
    px.color = scene_.isosurfaces[size_t(hit.surface)].color;
    if (!gradients) return;
    ++counters.gradients;
    const Vec3d n = facing_normal(hit.gradient, ray.dir);
    if (setup.outputs.normals) px.normal = n;
    if (!shading_.lit()) return;
    const Vec3d p = ray.at(hit.t);
    double light_distance;
    const Vec3d l = shading_.to_light(p, setup.camera.eye, light_distance);
    bool shadowed = false;
    if (scene_.shading.casts_shadows()) {
      ++counters.shadow_rays;
      const double offset = 1e-6 * geo_.voxel_size;  // leave the surface the ray starts on
      Interval<double> s = intersect(Rayd(p, l), clip_);
      s.t0 = std::max(s.t0, offset);
      s.t1 = std::min(s.t1, light_distance);
      shadowed = !s.empty() && first_crossing(p, l, s.t0, s.t1, counters).surface >= 0;
    }
    px.color = shading_.shade(px.color, n, -ray.dir, l, shadowed);
  }

  struct Segment {
    double t0, t1, f0, f1;
    Vec3d gradient;
    bool operator<(const Segment& o) const { return t0 < o.t0 || (t0 == o.t0 && t1 < o.t1); }
  };

  /// Every tet segment of the ray in [t0, t1] that can contribute, in ray order (DVR: those
  /// whose values the transfer function shows; MIP: all).
  std::vector<Segment> segments(const Vec3d& o, const Vec3d& d, double t0, double t1, RayCounters& counters) const {
    std::vector<Segment> out;
    const Vec3d inv = Vec3d(1.0) / d;
    for (const auto& [entry, c] : clusters_along(o, d, t0, t1, counters)) {
      const PageHandle h = fetch(c, counters);
      if (h.failed()) continue;
      const TetClusterPage page = TetClusterPage::view({h.bytes(), tets_.page_bytes()});
      const float* val = page.values_at(step_);
      index_of(c, page).tets.traverse(o, inv, t0, [&] { return t1; }, [&](uint32_t t) {
        const uint32_t* q = page.corners + 4 * size_t(t);
        if (scene_.mode != RenderMode::mip &&
            !scene_.value_range_visible(std::min({val[q[0]], val[q[1]], val[q[2]], val[q[3]]}),
                                        std::max({val[q[0]], val[q[1]], val[q[2]], val[q[3]]})))
          return true;  // invisible all through (the field stays within its corners)
        ++counters.cells;
        const TetGeometry g(page, t, step_);
        const Interval<double> s = g.span(o, d, t0, t1);
        if (!(s.t0 < s.t1)) return true;
        const Vec3d gradient = g.gradient();
        out.push_back({s.t0, s.t1, g.value_at(o + d * s.t0, gradient), g.value_at(o + d * s.t1, gradient), gradient});
        return true;
      });
    }
    std::sort(out.begin(), out.end());
    return out;
  }

  void dvr(const FrameSetup& setup, const Rayd& ray, Interval<double> span, bool gradients, PixelResult& px,
           RayCounters& counters) const {
    const TransferFunction& tf = scene_.transfer_function;
    const double unit = geo_.voxel_size;
    Vec3d accum(0.0);
    double a_acc = 0;
    std::vector<double> knots;
    for (const Segment& s : segments(ray.org, ray.dir, span.t0, span.t1, counters)) {
      if (a_acc >= kOpaque) break;
      const double flo = std::min(s.f0, s.f1), fhi = std::max(s.f0, s.f1);
      if (!tf.visible(flo, fhi)) continue;
      // Split the segment where the value crosses a knot: between knots colour and opacity
      // are linear in the value, and the value is linear in t.
      knots.assign({0.0, 1.0});
      for (const TfPoint& k : tf.points())
        if (k.value > flo && k.value < fhi) knots.push_back((k.value - s.f0) / (s.f1 - s.f0));
      std::sort(knots.begin(), knots.end());
      const Vec3d n = gradients ? facing_normal(s.gradient, ray.dir) : Vec3d(0.0);
      if (gradients) ++counters.gradients;
      for (size_t k = 0; k + 1 < knots.size() && a_acc < kOpaque; ++k) {
        const double u0 = knots[k], u1 = knots[k + 1];
        const double ta = s.t0 + u0 * (s.t1 - s.t0), tb = s.t0 + u1 * (s.t1 - s.t0);
        if (!(tb > ta)) continue;
        // Colour (shaded) and extinction at a point u of the segment.
        auto at = [&](double u, Vec3d& colour) {
          Vec3f c;
          float a;
          tf.eval(s.f0 + u * (s.f1 - s.f0), c, a);
          ++counters.samples;
          if (shading_.lit()) {
            double light_distance;
            const Vec3d p = ray.at(s.t0 + u * (s.t1 - s.t0));
            c = shading_.shade(c, n, -ray.dir, shading_.to_light(p, setup.camera.eye, light_distance), false);
          }
          colour = Vec3d(c);
          return -std::log1p(-std::min(double(a), kOpaque)) / unit;
        };
        Vec3d c0, c1;
        double s0 = at(u0, c0);
        const double s1 = at(u1, c1);
        const double depth = std::max(s0, s1) * (tb - ta);
        if (!(depth > 0)) continue;
        // Sub-steps of optical depth at most 0.05, over which colour and extinction are taken
        // linear between their ends (exactly so where opacity is constant), and the emission
        // integral is then closed-form but for the integral of the transmittance, smooth and
        // within 5% of constant, by 3-point Gauss-Legendre.
        const int steps = int(std::clamp(std::ceil(depth / 0.05), 1.0, 1e5));
        const double L = (tb - ta) / steps;
        for (int i = 0; i < steps && a_acc < kOpaque; ++i) {
          Vec3d cb = c1;
          const double sb = i + 1 == steps ? s1 : at(u0 + (u1 - u0) * (i + 1) / steps, cb);
          const double slope = (sb - s0) / L;
          auto transmittance = [&](double u) { return std::exp(-(s0 * u + 0.5 * slope * u * u)); };
          const double t_end = transmittance(L);
          static constexpr double kNodes[3] = {-0.7745966692414834, 0.0, 0.7745966692414834};
          static constexpr double kWeights[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
          double integral = 0;
          for (int g = 0; g < 3; ++g) integral += kWeights[g] * transmittance(0.5 * L * (1 + kNodes[g]));
          integral *= 0.5 * L;
          const Vec3d emitted = c0 * (1 - t_end) + (cb - c0) * ((integral - L * t_end) / L);
          const double before = a_acc;
          accum += emitted * (1 - a_acc);
          a_acc += (1 - a_acc) * (1 - t_end);
          if (px.depth == kInf && a_acc >= 0.5) {
            // Where inside the sub-step the opacity reached one half (extinction taken constant).
            const double need = std::log((1 - before) / 0.5), have = std::max(1e-300, -std::log(t_end));
            px.depth = ta + (i + std::clamp(need / have, 0.0, 1.0)) * L;
            if (setup.outputs.normals) px.normal = n;
          }
          s0 = sb, c0 = cb;
        }
      }
    }
    const Vec3d final_color = accum + Vec3d(scene_.background) * (1 - a_acc);
    px.color = Vec3f(final_color);
    px.alpha = float(a_acc);
  }

  void mip(const Rayd& ray, Interval<double> span, PixelResult& px, RayCounters& counters) const {
    double best = -kInf, best_t = kInf;
    for (const Segment& s : segments(ray.org, ray.dir, span.t0, span.t1, counters)) {
      ++counters.samples;
      if (s.f0 > best) best = s.f0, best_t = s.t0;
      if (s.f1 > best) best = s.f1, best_t = s.t1;
    }
    if (best == -kInf) return;
    px.depth = best_t;
    mip_color(ctx_, best, px);
  }

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  const TetView& tets_;
  ShadingModel shading_;
  uint32_t step_ = 0;  ///< the frame's time step (begin_frame)
  Box3d clip_;
  BoxTree clusters_;
  std::vector<bool> visible_;
  mutable std::mutex mutex_;
  mutable std::unordered_map<uint64_t, std::unique_ptr<ClusterIndex>> indices_;
};

}  // namespace

std::unique_ptr<Renderer> make_tet_reference(const RenderContext& ctx) { return std::make_unique<TetReference>(ctx); }

}  // namespace brickyard
