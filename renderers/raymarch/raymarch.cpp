// `raymarch`: the baseline. Plain single-resolution, fixed-step ray marching through the
// finest level in single precision, with empty-space skipping from the node table: the ray
// walks the finest level's bricks (3D DDA) and samples only bricks whose value range can
// contribute (an isovalue inside it, non-zero opacity by the transfer function's summed-area
// table). Samples sit at fixed positions t0 + (k + 1/2) dt along the ray whatever is skipped,
// so skipping changes the cost, never the image. Data comes through the cache with blocking
// fetches. It is the yardstick the paper back ends must beat at equal error.

#include <cmath>
#include <limits>
#include <memory>

#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/common/grid_walk.h"
#include "renderers/common/params.h"
#include "renderers/common/pixel.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"

namespace brickyard {
namespace {

struct RaymarchParams {
  double step{};  // voxels, before the scene's step_factor and sampling_rate
  int refine{};   // bisection steps refining an isosurface crossing
};

const ParamTable<RaymarchParams>& raymarch_params() {
  static const ParamTable<RaymarchParams> table{
      {"step", &RaymarchParams::step, 0.5, 1e-3, 16.0,
       "sampling step in voxels (times the scene's quality.step_factor; DVR/MIP: divided by sampling_rate)"},
      {"refine", &RaymarchParams::refine, 6, 0, 40, "bisection steps refining an isosurface crossing between two samples"},
  };
  return table;
}

template <typename Stored>
class RaymarchRenderer final : public Renderer {
 public:
  RaymarchRenderer(const RenderContext& ctx, const RaymarchParams& p)
      : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), p_(p), shading_(scene_.shading, geo_) {
    finest_ = ctx.layout().finest();
    bricks_ = ctx.layout().level_bricks(finest_);
    M_ = double(ctx.layout().brick_size);
    step_ = p.step * scene_.quality.step_factor / (scene_.mode == RenderMode::iso ? 1.0 : scene_.sampling_rate);
    // Node visibility per finest brick, decided once: the render loop reads a byte.
    const auto& level = ctx.nodes().level(finest_);
    visible_.resize(level.size());
    for (size_t i = 0; i < level.size(); ++i) visible_[i] = ctx.node_visible(level[i]);
    if (scene_.mode == RenderMode::dvr) tf_table_ = TfTable(scene_.transfer_function, step_);
  }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    Marcher m(*this, setup, counters);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) m.pixel(x, y, out);
  }

 private:
  struct Marcher {
    const RaymarchRenderer& r;
    const FrameSetup& setup;
    const ImageRays rays;
    RayCounters& counters;
    TrilinearSampler<Stored, float> sampler;
    const bool gradients;
    CrossingBracket hit_bracket;  // the last bracket of crossing()'s hit

    Marcher(const RaymarchRenderer& renderer, const FrameSetup& s, RayCounters& c)
        : r(renderer), setup(s), rays(s.camera, s.width, s.height), counters(c), sampler(r.ctx_.bricks(), c, r.finest_), gradients(r.ctx_.needs_gradients(s.outputs)) {}

    /// Calls f(t) at every fixed sample position t0 + (k + 1/2) dt inside a visible brick,
    /// in order, until f returns false. `entered(t)` is called when the ray enters a visible
    /// brick after skipping (the last sample before it is unknown). Returns whether the ray
    /// left the region from a visible brick without being stopped (a last part-step remains).
    template <typename OnSample, typename OnEnter>
    bool march(const Vec3d& o, const Vec3d& d, double t0, double t1, double dt, OnSample&& on_sample, OnEnter&& entered) {
      const double inv_m = 1.0 / r.M_;
      bool skipped = true, stopped = false;
      walk_cells(o * inv_m, d * inv_m, t0, t1, r.bricks_, [&](const int64_t b[3], double ta, double tb) {
        ++counters.nodes;
        const size_t index = size_t((b[2] * r.bricks_.y + b[1]) * r.bricks_.x + b[0]);
        if (!r.visible_[index]) {
          skipped = true;
          return true;
        }
        if (skipped && !entered(ta)) return !(stopped = true);
        skipped = false;
        double k = std::ceil((ta - t0) / dt - 0.5);
        for (double t = t0 + (std::max(k, 0.0) + 0.5) * dt; t < tb; t += dt)
          if (!on_sample(t)) return !(stopped = true);
        return true;
      });
      return !skipped && !stopped;
    }

    float sample(const Vec3d& o, const Vec3d& d, double t) {
      ++counters.samples;
      return sampler.sample(Vec3f(o + d * t));
    }

    /// The gradient at q, where sampler.sample(q) was the last sample taken: analytic ones from
    /// that sample's cell (last_sample_gradient), the others by differences as ever.
    Vec3d gradient_world_at_last_sample(const Vec3f& q) {
      if (r.scene_.shading.normals != NormalMethod::analytic) return gradient_world(Vec3d(q));
      ++counters.gradients;
      return Vec3d(sampler.last_sample_gradient()) / r.geo_.spacing;
    }

    Vec3d gradient_world(const Vec3d& q) {
      ++counters.gradients;
      const Vec3f p(q);
      Vec3f g;
      switch (r.scene_.shading.normals) {
        case NormalMethod::analytic: sampler.sample(p, g); break;
        case NormalMethod::central:
          g = sampler.difference_gradient(p, true, int64_t(r.M_));
          counters.samples += 6;
          break;
        case NormalMethod::forward:
          g = sampler.difference_gradient(p, false, int64_t(r.M_));
          counters.samples += 4;
          break;
      }
      return Vec3d(g) / r.geo_.spacing;
    }

    void pixel(int x, int y, FrameBuffers& out) {
      ++counters.rays;
      const PrimaryRay ray = primary_ray(rays, r.geo_, x, y);
      PixelResult px;
      px.color = r.scene_.background;
      if (ray.hits()) {
        const double dt = r.step_ / length(ray.dir);
        switch (r.scene_.mode) {
          case RenderMode::iso: iso(ray.world, ray.org, ray.dir, ray.span, dt, px.color, px.alpha, px.depth, px.normal); break;
          case RenderMode::dvr: dvr(ray.world, ray.org, ray.dir, ray.span, dt, px.color, px.alpha, px.depth, px.normal); break;
          case RenderMode::mip: mip(ray.org, ray.dir, ray.span, dt, px); break;
        }
      }
      write_pixel(out, x, y, px);
    }

    /// First crossing of any isosurface in [t0, t1]: t and surface index, or surface -1.
    std::pair<double, int> crossing(const Vec3d& o, const Vec3d& d, double t0, double t1, double dt) {
      const auto& surfaces = r.scene_.isosurfaces;
      const size_t ns = surfaces.size();
      float prev[4];
      double t_prev = 0;
      bool have_prev = false;
      double hit_t = std::numeric_limits<double>::infinity();
      int hit_s = -1;
      auto take = [&](double t) {
        const float v = sample(o, d, t);
        for (size_t s = 0; s < ns; ++s) {
          const float g = v - float(surfaces[s].value);
          if (have_prev && ((prev[s] < 0) != (g < 0) || g == 0)) {
            const float iso = float(surfaces[s].value);
            CrossingBracket bracket;
            const double th = bisect_crossing([&](double m) { return sample(o, d, m) - iso; }, t_prev, t, prev[s], g,
                                              r.p_.refine, &bracket);
            if (th < hit_t) hit_t = th, hit_s = int(s), hit_bracket = bracket;
          }
          prev[s] = g;
        }
        t_prev = t;
        have_prev = true;
        return hit_s < 0;
      };
      const bool open_end = march(o, d, t0, t1, dt, take, [&](double ta) {
        have_prev = false;
        return take(ta + 1e-4 * dt);  // just inside the visible brick
      });
      // The part-step between the last sample and the exit: a crossing there is still seen.
      if (open_end && have_prev && t1 - t_prev > 1e-3 * dt) take(t1 - 1e-4 * dt);
      return {hit_t, hit_s};
    }

    void iso(const Rayd& world_ray, const Vec3d& o, const Vec3d& d, Interval<double> span, double dt, Vec3f& color,
             float& alpha, double& depth, Vec3d& normal) {
      const auto [t, s] = crossing(o, d, span.t0, span.t1, dt);
      if (s < 0) return;
      depth = t;
      alpha = 1;
      color = r.scene_.isosurfaces[size_t(s)].color;
      if (!gradients) return;
      // (The world gradient's rate along the world ray has the voxel one's sign.)
      const Vec3d g = crossing_gradient([&](double u) { return gradient_world(o + d * u); }, t, hit_bracket, world_ray.dir);
      const Vec3d n = facing_normal(g, world_ray.dir);
      if (setup.outputs.normals) normal = n;
      if (!r.shading_.lit()) return;
      const Vec3d p_world = world_ray.at(t);
      double light_distance;
      const Vec3d l = r.shading_.to_light(p_world, setup.camera.eye, light_distance);
      bool shadowed = false;
      if (r.scene_.shading.casts_shadows()) {
        ++counters.shadow_rays;
        const Vec3d so = r.geo_.to_voxel(p_world), sd = l / r.geo_.spacing;
        Interval<double> ss = intersect(Rayd(so, sd), r.geo_.voxel_clip);
        ss.t0 = std::max(ss.t0, r.step_ * r.geo_.voxel_size);  // leave the surface: one step
        ss.t1 = std::min(ss.t1, light_distance);
        shadowed = !ss.empty() && crossing(so, sd, ss.t0, ss.t1, r.step_ / length(sd)).second >= 0;
      }
      color = r.shading_.shade(color, n, -world_ray.dir, l, shadowed);
    }

    void dvr(const Rayd& world_ray, const Vec3d& o, const Vec3d& d, Interval<double> span, double dt, Vec3f& color,
             float& alpha, double& depth, Vec3d& normal) {
      const float stop = float(r.scene_.quality.termination_opacity);
      Vec3f accum(0.0f);
      float a_acc = 0;
      const bool lit = r.shading_.lit();
      march(o, d, span.t0, span.t1, dt, [&](double t) {
        const Vec3f q(o + d * t);
        ++counters.samples;
        const float v = sampler.sample(q);
        Vec3f c;
        float a;
        r.tf_table_.lookup(v, c, a);
        if (!(a > 0)) return true;
        Vec3d n(0.0);
        if (gradients) n = facing_normal(gradient_world_at_last_sample(q), world_ray.dir);
        if (lit) {
          double light_distance;
          c = r.shading_.shade(c, n, -world_ray.dir, r.shading_.to_light(world_ray.at(t), setup.camera.eye, light_distance), false);
        }
        accum += c * ((1 - a_acc) * a);
        a_acc += (1 - a_acc) * a;
        if (depth == std::numeric_limits<double>::infinity() && a_acc >= 0.5f) {
          depth = t;
          if (setup.outputs.normals) normal = n;
        }
        return a_acc < stop;
      }, [](double) { return true; });
      color = accum + r.scene_.background * (1 - a_acc);
      alpha = a_acc;
    }

    void mip(const Vec3d& o, const Vec3d& d, Interval<double> span, double dt, PixelResult& px) {
      float best = -std::numeric_limits<float>::infinity();
      double best_t = 0;
      march(o, d, span.t0, span.t1, dt, [&](double t) {
        const float v = sample(o, d, t);
        if (v > best) best = v, best_t = t;
        return true;
      }, [](double) { return true; });
      if (best == -std::numeric_limits<float>::infinity()) return;
      px.depth = best_t;
      mip_color(r.ctx_, double(best), px);
    }
  };

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  RaymarchParams p_;
  ShadingModel shading_;
  int finest_ = 0;
  Vec3s bricks_;
  double M_ = 32;
  double step_ = 0.5;
  std::vector<uint8_t> visible_;
  TfTable tf_table_;  // opacity corrected for step_
};

}  // namespace

BackendEntry raymarch_backend() {
  BackendEntry e;
  e.info.name = "raymarch";
  e.info.description = "baseline: single-resolution fixed-step ray marching at the finest level, float, "
                       "empty-space skipping by the node table";
  e.info.kinds = {DataKind::structured};
  e.info.modes = {RenderMode::iso, RenderMode::dvr, RenderMode::mip};
  e.info.shadows = true;
  e.info.normals = {NormalMethod::analytic, NormalMethod::central, NormalMethod::forward};
  e.info.params = raymarch_params().declarations();
  e.info.quality_param = "step";
  e.info.quality_sweep = {2.0, 1.0, 0.5, 0.25, 0.125};
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const RaymarchParams rp = raymarch_params().bind(p);
    return dispatch_value_type(ctx.bricks().shape().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      return std::make_unique<RaymarchRenderer<decltype(stored)>>(ctx, rp);
    });
  };
  return e;
}

}  // namespace brickyard
