// example-mip: a maximum-intensity projection that marches each ray through the finest level
// at a fixed step, reading bricks through the cache. A minimal back end built outside the
// brickyard tree, against the installed package, and loaded with `brickyard --module`.
// docs/writing-a-backend.md walks through it.

#include <brickyard/renderers/common/cell_accessor.h>
#include <brickyard/renderers/common/module.h>
#include <brickyard/renderers/common/params.h>
#include <brickyard/renderers/common/pixel.h>

#include <limits>
#include <memory>

namespace example {

using namespace brickyard;

// Step 1: the parameters, each declared once with the field it binds to.
struct MipParams {
  double step{};  // voxels of the finest level
};

const ParamTable<MipParams>& mip_params() {
  static const ParamTable<MipParams> table{
      {"step", &MipParams::step, 0.5, 1e-3, 8, "sampling step in voxels of the finest level"},
  };
  return table;
}

// Step 2: the renderer. Built once per session from the context (the scene, the dataset's
// views, the cache); render_tile() is const and runs on many threads at once.
template <typename Stored>
class MipMarch final : public Renderer {
 public:
  MipMarch(const RenderContext& ctx, const MipParams& p)
      : ctx_(ctx), geo_(ctx.geometry()), finest_(ctx.grid().layout().finest()), step_(p.step) {}

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    const ImageRays rays(setup.camera, setup.width, setup.height);
    // One sampler per tile: it remembers its last brick (and pins it), and it is not shared.
    // It reads with blocking fetches through the cache, as tools and reference renderers do.
    TrilinearSampler<Stored, float> sampler(ctx_.bricks(), counters, finest_);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) {
        ++counters.rays;
        const PrimaryRay ray = primary_ray(rays, geo_, x, y);
        PixelResult px;
        px.color = ctx_.scene().background;
        if (ray.hits()) march(ray, sampler, counters, px);
        write_pixel(out, x, y, px);
      }
  }

 private:
  void march(const PrimaryRay& ray, TrilinearSampler<Stored, float>& sampler, RayCounters& counters, PixelResult& px) const {
    // The ray's parameter t is world distance; the step is in voxels along the ray.
    const double dt = step_ / length(ray.dir);
    float best = -std::numeric_limits<float>::infinity();
    double best_t = 0;
    for (double t = ray.span.t0 + 0.5 * dt; t <= ray.span.t1; t += dt) {
      const Vec3d p = ray.org + ray.dir * t;
      const float v = sampler.sample(Vec3f(float(p.x), float(p.y), float(p.z)));
      ++counters.samples;
      if (v > best) best = v, best_t = t;
    }
    if (best == -std::numeric_limits<float>::infinity()) return;
    px.depth = best_t;
    mip_color(ctx_, double(best), px);  // the scene's transfer function, or grey over the value range
  }

  const RenderContext& ctx_;
  const VolumeGeometry& geo_;
  int finest_;
  double step_;
};

// Step 3: what the back end declares about itself, and its factory.
BackendEntry mip_march_backend() {
  BackendEntry e;
  e.info.name = "example-mip";
  e.info.description = "example module: maximum-intensity projection, fixed-step march at the finest level";
  e.info.kinds = {DataKind::structured};
  e.info.modes = {RenderMode::mip};
  e.info.params = mip_params().declarations();
  e.info.quality_param = "step";
  e.info.quality_sweep = {2, 1, 0.5, 0.25};
  e.create = [](const RenderContext& ctx, const BackendParams& values) -> std::unique_ptr<Renderer> {
    const MipParams p = mip_params().bind(values);
    // One instantiation per stored value type, chosen once here, never per sample.
    return dispatch_value_type(ctx.grid().shape().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      return std::make_unique<MipMarch<decltype(stored)>>(ctx, p);
    });
  };
  return e;
}

}  // namespace example

// Step 4: the module's entry point. The host calls it once, when --module loads the library.
BRICKYARD_MODULE(registry) { registry.add(example::mip_march_backend()); }
