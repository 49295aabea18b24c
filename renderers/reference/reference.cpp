// The reference renderer: simple, slow, double precision, at the finest level, reading
// through the cache with blocking fetches. It defines the truth every back end's error is
// measured against.
//
// - iso: walks every cell the ray crosses (3D DDA) and finds the exact first zero of the
//   trilinear interpolant minus the isovalue in each (a cubic in the ray parameter, roots
//   isolated between the derivative's roots, tangent roots included); normals from the exact
//   gradient of the interpolant, or by differences when the scene asks.
// - dvr: emission-absorption integral at fixed steps (1/8 voxel by default, divided by the
//   scene's sampling rate), opacity corrected for the step, no early termination short of an
//   opacity of 1 - 1e-7.
// - mip: the exact maximum of the interpolant along the ray (per cell, at the cubic's ends
//   and critical points).
// - analytic = 1: the same integrals evaluated on the procedural field the store was made
//   from (the dataset's source), a truth that does not depend on the voxel grid.

#include <cmath>
#include <limits>
#include <memory>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "fields/field.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/common/grid_walk.h"
#include "renderers/common/params.h"
#include "renderers/common/pixel.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"
#include "renderers/reference/tets.h"

namespace brickyard {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kOpaque = 1 - 1e-7;

/// The field a store was made from, in the store's units and world coordinates.
class AnalyticTruth {
 public:
  /// `source`: the dataset's provenance (DatasetInfo::source); `type`: its stored value type.
  static std::unique_ptr<AnalyticTruth> from_source(const std::string& source, ValueType type) {
    const nlohmann::json j = nlohmann::json::parse(source, nullptr, /*allow_exceptions=*/false);
    if (!j.is_object()) return nullptr;
    const nlohmann::json* g = &j;
    if (j.value("kind", "") != "field") {
      auto it = j.find("generator");
      if (it == j.end() || !it->is_object()) return nullptr;
      g = &*it;
    }
    if (!g->contains("field") || !(*g)["field"].is_string()) return nullptr;
    FieldParamValues params;
    if (auto p = g->find("params"); p != g->end() && p->is_object())
      for (auto it = p->begin(); it != p->end(); ++it)
        if (it->is_number()) params[it.key()] = it->get<double>();
    auto truth = std::make_unique<AnalyticTruth>();
    truth->field_ = make_field((*g)["field"].get<std::string>(), params);
    if (is_integer(type)) {
      auto q = g->find("quantization");
      if (q == g->end() || !q->is_array() || q->size() != 2) return nullptr;
      const double lo = (*q)[0].get<double>(), hi = (*q)[1].get<double>();
      truth->scale_ = (integer_max(type) - integer_min(type)) / (hi - lo);
      truth->offset_ = integer_min(type) - lo * truth->scale_;
    }
    return truth;
  }
  double value(const Vec3d& world) const { return offset_ + scale_ * field_->value(world); }
  Vec3d gradient(const Vec3d& world) const { return field_->gradient(world) * scale_; }
  std::string_view name() const { return field_->name(); }

 private:
  std::unique_ptr<Field> field_;
  double scale_ = 1, offset_ = 0;
};

struct ReferenceParams {
  double step{};  // voxels, for DVR (and the analytic iso/MIP search)
  bool analytic{};
};

const ParamTable<ReferenceParams>& reference_params() {
  static const ParamTable<ReferenceParams> table{
      {"step", &ReferenceParams::step, 0.125, 1e-3, 1.0,
       "DVR sampling step in voxels (divided by the scene's sampling_rate); analytic mode's search step"},
      {"analytic", &ReferenceParams::analytic, 0, 0, 1,
       "1: render the procedural field the store was made from instead of its voxels"},
  };
  return table;
}

template <typename Stored>
class ReferenceRenderer final : public Renderer {
 public:
  ReferenceRenderer(const RenderContext& ctx, const ReferenceParams& p, std::unique_ptr<AnalyticTruth> truth)
      : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), p_(p), truth_(std::move(truth)),
        shading_(scene_.shading, geo_) {
    const Vec3s d = geo_.dims;
    cells_ = Vec3s(std::max<int64_t>(1, d.x - 1), std::max<int64_t>(1, d.y - 1), std::max<int64_t>(1, d.z - 1));
    finest_ = ctx.layout().finest();
    M_ = ctx.layout().brick_size;
  }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    Tracer t(*this, setup, counters);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) t.pixel(x, y, out);
  }

 private:
  /// Per-tile state: accessors remember their last brick.
  struct Tracer {
    const ReferenceRenderer& r;
    const FrameSetup& setup;
    const ImageRays rays;
    RayCounters& counters;
    CellAccessor<Stored> cells;
    TrilinearSampler<Stored, double> sampler;
    const bool gradients;
    Vec3s visible_brick{-1};
    Vec3s visible_lo{0}, visible_hi{-1};  // the cells of visible_brick
    bool visible = true;

    Tracer(const ReferenceRenderer& renderer, const FrameSetup& s, RayCounters& c)
        : r(renderer), setup(s), rays(s.camera, s.width, s.height), counters(c), cells(r.ctx_.bricks(), c, r.finest_), sampler(r.ctx_.bricks(), c, r.finest_),
          gradients(r.ctx_.needs_gradients(s.outputs)) {}

    /// Whether the brick holding cell (i, j, k) can contribute (node table): others are never fetched.
    /// (Per sample: recomputing the layout's brick counts was about 13% of a DVR frame; the bounds
    /// test spares the three divisions too. A cell clamped into the last brick takes the longer
    /// way, to the same answer.)
    bool cell_visible(int64_t i, int64_t j, int64_t k) {
      if (i >= visible_lo.x && i < visible_hi.x && j >= visible_lo.y && j < visible_hi.y && k >= visible_lo.z && k < visible_hi.z)
        return visible;
      const Vec3s b = cells.brick_of(i, j, k);
      for (int a = 0; a < 3; ++a) visible_lo[a] = b[a] * r.M_, visible_hi[a] = visible_lo[a] + r.M_;
      if (b == visible_brick) return visible;
      ++counters.nodes;
      visible_brick = b;
      visible = r.ctx_.node_visible(r.ctx_.nodes().at(BrickKey{uint32_t(r.finest_), uint32_t(b.x), uint32_t(b.y), uint32_t(b.z)}));
      return visible;
    }

    void pixel(int x, int y, FrameBuffers& out) {
      ++counters.rays;
      const PrimaryRay ray = primary_ray(rays, r.geo_, x, y);
      PixelResult px;
      px.color = r.scene_.background;
      if (ray.hits()) {
        switch (r.scene_.mode) {
          case RenderMode::iso: iso(ray.world, ray.org, ray.dir, ray.span, px.color, px.alpha, px.depth, px.normal); break;
          case RenderMode::dvr: dvr(ray.world, ray.org, ray.dir, ray.span, px.color, px.alpha, px.depth, px.normal); break;
          case RenderMode::mip: mip(ray.org, ray.dir, ray.span, px); break;
        }
      }
      write_pixel(out, x, y, px);
    }

    // --- isosurfaces -------------------------------------------------------------------
    struct Hit {
      double t = kInf;
      int surface = -1;
      Vec3d gradient_voxel{0.0};  // exact trilinear gradient at the hit (voxel units)
    };

    /// The first crossing of any isosurface along o + t d, t in [t0, t1].
    Hit first_crossing(const Vec3d& o, const Vec3d& d, double t0, double t1, bool want_gradient) {
      Hit hit;
      if (r.truth_ && r.p_.analytic) return analytic_crossing(o, d, t0, t1);
      const auto& surfaces = r.scene_.isosurfaces;
      walk_cells(o, d, t0, t1, r.cells_, [&](const int64_t c[3], double ta, double tb) {
        ++counters.cells;
        if (!cell_visible(c[0], c[1], c[2])) return true;
        double v[8];
        cells.corners(c[0], c[1], c[2], v);
        double lo = v[0], hi = v[0];
        for (int n = 1; n < 8; ++n) lo = std::min(lo, v[n]), hi = std::max(hi, v[n]);
        const Vec3d p = o + d * ta;
        const double u0[3] = {p.x - double(c[0]), p.y - double(c[1]), p.z - double(c[2])};
        const double du[3] = {d.x, d.y, d.z};
        for (size_t s = 0; s < surfaces.size(); ++s) {
          const double iso = surfaces[s].value;
          if (iso < lo || iso > hi) continue;  // the interpolant stays within its corners
          const auto root = first_root(trilinear_cubic(v, iso, u0, du), tb - ta);
          ++counters.samples;
          if (root && ta + *root < hit.t) {
            hit.t = ta + *root;
            hit.surface = int(s);
            if (want_gradient) {
              const Vec3d q = o + d * hit.t;
              auto local = [&](int a) { return std::clamp(q[a] - double(c[a]), 0.0, 1.0); };
              hit.gradient_voxel = trilinear_gradient(v, local(0), local(1), local(2));
            }
          }
        }
        return hit.surface < 0;
      });
      return hit;
    }

    /// Analytic mode: sign changes of the field at fine steps, refined by bisection.
    Hit analytic_crossing(const Vec3d& o, const Vec3d& d, double t0, double t1) {
      Hit hit;
      const auto& surfaces = r.scene_.isosurfaces;
      const double dt = 0.5 * r.p_.step / length(d);
      auto g = [&](double t, size_t s) {
        ++counters.samples;
        return r.truth_->value(r.geo_.to_world(o + d * t)) - surfaces[s].value;
      };
      std::vector<double> prev(surfaces.size());
      for (size_t s = 0; s < surfaces.size(); ++s) prev[s] = g(t0, s);
      for (size_t s = 0; s < surfaces.size(); ++s)
        if (prev[s] == 0) return Hit{t0, int(s), {}};
      const int64_t steps = std::max<int64_t>(1, int64_t(std::ceil((t1 - t0) / dt)));
      for (int64_t i = 1; i <= steps; ++i) {
        const double ta = t0 + double(i - 1) / double(steps) * (t1 - t0), tb = t0 + double(i) / double(steps) * (t1 - t0);
        for (size_t s = 0; s < surfaces.size(); ++s) {
          const double gb = g(tb, s);
          if ((prev[s] < 0) != (gb < 0) || gb == 0) {
            const double t = bisect_crossing([&](double m) { return g(m, s); }, ta, tb, prev[s], gb, 80);
            if (t < hit.t) hit = Hit{t, int(s), {}};
          }
          prev[s] = gb;
        }
        if (hit.surface >= 0) return hit;
      }
      return hit;
    }

    /// World-space gradient at voxel position q by the scene's method.
    Vec3d gradient_world(const Vec3d& q, const Vec3d& exact_voxel) {
      ++counters.gradients;
      if (r.truth_ && r.p_.analytic) return r.truth_->gradient(r.geo_.to_world(q));
      Vec3d g;
      switch (r.scene_.shading.normals) {
        case NormalMethod::analytic: g = exact_voxel; break;
        case NormalMethod::central:
          g = sampler.difference_gradient(q, true, r.M_);
          counters.samples += 6;
          break;
        case NormalMethod::forward:
          g = sampler.difference_gradient(q, false, r.M_);
          counters.samples += 4;
          break;
      }
      return g / r.geo_.spacing;
    }

    void iso(const Rayd& world_ray, const Vec3d& o, const Vec3d& d, Interval<double> span, Vec3f& color, float& alpha,
             double& depth, Vec3d& normal) {
      const Hit hit = first_crossing(o, d, span.t0, span.t1, gradients);
      if (hit.surface < 0) return;
      depth = hit.t;
      alpha = 1;
      color = r.scene_.isosurfaces[size_t(hit.surface)].color;
      if (!gradients) return;
      const Vec3d q = o + d * hit.t;
      const Vec3d n = facing_normal(gradient_world(q, hit.gradient_voxel), world_ray.dir);
      if (setup.outputs.normals) normal = n;
      if (!r.shading_.lit()) return;
      const Vec3d p_world = world_ray.at(hit.t);
      double light_distance;
      const Vec3d l = r.shading_.to_light(p_world, setup.camera.eye, light_distance);
      bool shadowed = false;
      if (r.scene_.shading.casts_shadows()) shadowed = in_shadow(p_world, l, light_distance);
      color = r.shading_.shade(color, n, -world_ray.dir, l, shadowed);
    }

    bool in_shadow(const Vec3d& p_world, const Vec3d& l, double light_distance) {
      ++counters.shadow_rays;
      const double offset = 1e-2 * r.geo_.voxel_size;  // leave the surface the ray starts on
      const Vec3d o = r.geo_.to_voxel(p_world), d = l / r.geo_.spacing;
      Interval<double> span = intersect(Rayd(o, d), r.geo_.voxel_clip);
      span.t0 = std::max(span.t0, offset);
      span.t1 = std::min(span.t1, light_distance);
      if (span.empty()) return false;
      return first_crossing(o, d, span.t0, span.t1, false).surface >= 0;
    }

    // --- direct volume rendering --------------------------------------------------------
    void dvr(const Rayd& world_ray, const Vec3d& o, const Vec3d& d, Interval<double> span, Vec3f& color, float& alpha,
             double& depth, Vec3d& normal) {
      const double h = r.p_.step / r.scene_.sampling_rate;  // voxels
      const double dt = h / length(d);
      const TransferFunction& tf = r.scene_.transfer_function;
      const bool lit = r.shading_.lit();
      Vec3d accum(0.0);
      double a_acc = 0;
      const int64_t steps = int64_t(std::floor((span.t1 - span.t0) / dt));
      for (int64_t i = 0; i <= steps && a_acc < kOpaque; ++i) {
        const double t = span.t0 + (double(i) + 0.5) * dt;
        if (t > span.t1) break;
        const Vec3d q = o + d * t;
        double value;
        Vec3d grad_voxel(0.0);
        if (r.truth_ && r.p_.analytic) {
          value = r.truth_->value(r.geo_.to_world(q));
          ++counters.samples;
        } else {
          int64_t c[3];
          for (int a = 0; a < 3; ++a) c[a] = std::clamp<int64_t>(int64_t(q[a]), 0, r.cells_[a] - 1);
          if (!cell_visible(c[0], c[1], c[2])) continue;
          value = gradients ? sampler.sample(q, grad_voxel) : sampler.sample(q);
          ++counters.samples;
        }
        Vec3f c;
        float a_tf;
        tf.eval(value, c, a_tf);
        if (!(a_tf > 0)) continue;
        const double a = 1 - std::pow(1 - double(a_tf), h);
        Vec3d n(0.0);
        if (gradients) n = facing_normal(gradient_world(q, grad_voxel), world_ray.dir);
        if (lit) {
          double light_distance;
          const Vec3d p_world = world_ray.at(t);
          c = r.shading_.shade(c, n, -world_ray.dir, r.shading_.to_light(p_world, setup.camera.eye, light_distance), false);
        }
        accum += Vec3d(c) * ((1 - a_acc) * a);
        a_acc += (1 - a_acc) * a;
        if (depth == kInf && a_acc >= 0.5) {
          depth = t;
          if (setup.outputs.normals) normal = n;
        }
      }
      const Vec3d bg(r.scene_.background);
      const Vec3d final_color = accum + bg * (1 - a_acc);
      color = Vec3f(final_color);
      alpha = float(a_acc);
    }

    // --- maximum intensity projection ---------------------------------------------------
    void mip(const Vec3d& o, const Vec3d& d, Interval<double> span, PixelResult& px) {
      double best = -kInf, best_t = kInf;
      if (r.truth_ && r.p_.analytic) {
        const double dt = r.p_.step / length(d);
        for (double t = span.t0; t <= span.t1; t += dt) {
          ++counters.samples;
          const double v = r.truth_->value(r.geo_.to_world(o + d * t));
          if (v > best) best = v, best_t = t;
        }
      } else {
        walk_cells(o, d, span.t0, span.t1, r.cells_, [&](const int64_t c[3], double ta, double tb) {
          ++counters.cells;
          double v[8];
          cells.corners(c[0], c[1], c[2], v);
          const Vec3d p = o + d * ta;
          const double u0[3] = {p.x - double(c[0]), p.y - double(c[1]), p.z - double(c[2])};
          const double du[3] = {d.x, d.y, d.z};
          double where;
          const double m = cubic_max(trilinear_cubic(v, 0, u0, du), tb - ta, where);
          ++counters.samples;
          if (m > best) best = m, best_t = ta + where;
          return true;
        });
      }
      if (best == -kInf) return;
      px.depth = best_t;
      mip_color(r.ctx_, double(best), px);
    }
  };

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  ReferenceParams p_;
  std::unique_ptr<AnalyticTruth> truth_;
  ShadingModel shading_;
  Vec3s cells_;
  int finest_ = 0;
  int64_t M_ = 32;
};

}  // namespace

BackendEntry reference_backend() {
  BackendEntry e;
  e.info.name = "reference";
  e.info.description = "double-precision ground truth at the finest level: exact trilinear isosurface crossings, "
                       "fine-step emission-absorption, exact MIP; optionally the analytic field itself; on "
                       "tetrahedral meshes exact linear crossings and per-tet segment integrals";
  e.info.kinds = {DataKind::structured, DataKind::tetrahedral};
  e.info.modes = {RenderMode::iso, RenderMode::dvr, RenderMode::mip};
  e.info.shadows = true;
  e.info.normals = {NormalMethod::analytic, NormalMethod::central, NormalMethod::forward};
  e.info.params = reference_params().declarations();
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const ReferenceParams rp = reference_params().bind(p);
    if (ctx.kind() == DataKind::tetrahedral) {
      if (rp.analytic)
        throw Error(Errc::unsupported, "analytic = 1 renders grids made from a procedural field; a mesh's reference is "
                                       "its own linear interpolant")
            .with_file(ctx.dataset().name)
            .with_field("backend.params.analytic");
      if (ctx.scene().shading.normals != NormalMethod::analytic)
        throw Error(Errc::unsupported, "on a tetrahedral mesh the normal is the tet's gradient: shading.normals "
                                       "must be analytic")
            .with_file(ctx.scene().file)
            .with_field("shading.normals");
      return make_tet_reference(ctx);
    }
    std::unique_ptr<AnalyticTruth> truth;
    if (rp.analytic) {
      truth = AnalyticTruth::from_source(ctx.dataset().source, ctx.grid().shape().type);
      if (!truth)
        throw Error(Errc::invalid_argument, "analytic = 1 needs a store made from a procedural field "
                                            "(brickyard import field:NAME, or a raw file from brickyard generate)")
            .with_file(ctx.dataset().name)
            .with_field("backend.params.analytic");
    }
    return dispatch_value_type(ctx.bricks().shape().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      return std::make_unique<ReferenceRenderer<decltype(stored)>>(ctx, rp, std::move(truth));
    });
  };
  return e;
}

}  // namespace brickyard
