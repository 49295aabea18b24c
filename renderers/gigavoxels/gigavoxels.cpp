// `gigavoxels`' parameters, declared once (ParamTable), and its registration: the back end's
// description, what it renders, and its factory, which picks the brick source and the brick
// pool's voxel type. The back end itself is renderer.h.

#include <memory>

#include "core/value_type.h"
#include "renderers/common/params.h"
#include "renderers/common/renderer.h"
#include "renderers/gigavoxels/renderer.h"
#include "renderers/gigavoxels/sources.h"

namespace brickyard {
namespace {

using gigavoxels::GigaVoxelsParams;

const ParamTable<GigaVoxelsParams>& gigavoxels_params() {
  using P = GigaVoxelsParams;
  static const ParamTable<P> table{
      {"lod_ratio", &P::lod_ratio, 0, 0, 1000, "target pixels per voxel; 0: the scene's quality.lod_ratio"},
      {"step", &P::step, 0.5, 1e-3, 16, "sampling step in voxels of the level sampled (times quality.step_factor; DVR: / sampling_rate)"},
      {"exact", &P::exact, 0, 0, 1, "1: exact mode (rays stop at missing data and resume once it is loaded, until the frame is complete); "
                         "0: approximate (coarser data meanwhile, converges over frames)"},
      {"quadrilinear", &P::quadrilinear, 1, 0, 1, "1: blend the two mip levels around the footprint; 0: the nearest finer level only"},
      {"slots_per_pixel", &P::slots_per_pixel, 4, 1, 16, "feedback list length per ray (shared by the rays of a 2x2 packet)"},
      {"subdivide_budget", &P::subdivide_budget, 512, 1, 1e6, "node subdivisions per frame"},
      {"upload_budget", &P::upload_budget, 512, 1, 1e6, "bricks written into the brick pool per frame"},
      {"brick_slots", &P::brick_slots, 0, 0, 1 << 20, "brick pool slots; 0: as many as the scene's cache.l1 budget holds beside the cache's L1, which then keeps 2 x upload_budget slots to stage copies (set: the cache's L1 keeps the whole budget)"},
      {"node_blocks", &P::node_blocks, 0, 0, 1 << 22, "node pool blocks of N^3 nodes; 0: twice the brick slots"},
      {"source", &P::source, 0, 0, 2, "0: the store; 1: an instanced Menger sponge (N = 3) filling the volume's box; "
                          "2: the store, amplified below its finest level by Perlin noise"},
      {"menger_brick", &P::menger_brick, 27, 9, 81, "source=1: brick size M (9, 27 or 81)"},
      {"amplify_levels", &P::amplify_levels, 3, 0, 10, "source=2: levels of noise detail below the finest stored level"},
      {"amplify_amplitude", &P::amplify_amplitude, 0.05, 0, 10, "source=2: the first octave's amplitude, a fraction of the store's value range"},
      {"amplify_gain", &P::amplify_gain, 0.5, 0, 4, "source=2: amplitude ratio between successive octaves"},
      {"amplify_seed", &P::amplify_seed, 1, 0, 1e9, "source=2: noise seed"},
      {"max_passes", &P::max_passes, 256, 1, 100000, "exact mode: passes per frame before the rest of the frame takes coarser data"},
      {"refine", &P::refine, 10, 0, 40, "iso: a crossing is bisected down to 2^-refine voxels, then placed by the secant"},
      {"skip_cells", &P::skip_cells, 1, 0, 1, "1: rays leap the 4^3-cell groups of a brick that hold nothing visible, as many at once as "
                              "their distance to a visible group allows; 0: every step samples"},
      {"hidden_crossings", &P::hidden_crossings, 5, 0, 20, "iso: a step is searched for a pair of crossings its two samples may hide, down to parts "
                                     "of 2^-hidden_crossings voxels, where the brick's bounds allow one (0: none)"},
      {"adaptive_step", &P::adaptive_step, 8, 1, 64, "DVR: the most a step grows, as T^-1/2 where T is the light left to the ray (a sample behind "
                                  "opacity counts less); 1: a fixed step"},
      {"face_lighting", &P::face_lighting, 1, 0, 1, "lit DVR: 1 weights a segment's two end lightings by where it crosses cell faces (where the "
                                 "analytic gradient jumps; analytic normals only); 0: their mean"},
      {"middle_lighting", &P::middle_lighting, 1, 0, 1, "lit DVR with face_lighting: 1 lights the cells a segment crosses between its first and "
                                   "last cell faces with the lighting at their middle (one more gradient per such visible "
                                   "segment); "
                                   "0: with the mean of its ends'"},
      {"sample_runs", &P::sample_runs, 1, 0, 1, "DVR at one level: 1 takes runs of up to 8 samples along a ray side by side (SIMD), the "
                               "adaptive step fixed for a run (not under a point light, nor with difference normals); 0: "
                               "one sample at a time"},
      {"termination_fill", &P::termination_fill, 1, 0, 1, "DVR: 1 gives the light left to a ray that early termination stops (quality."
                                    "termination_opacity) its last segment's colour, as if the medium went on alike; "
                                    "0: the background's, as if it ended there"},
      {"leap_chains", &P::leap_chains, 1, 0, 1, "DVR at one level: 1 leaps on, with no sample, from a leap that ends in clear cell groups "
                               "of the same hidden value interval whose own leap reaches 2 steps (the sample would add only "
                               "the pre-integration table's slight opacity next to a hidden range); 0: a sample at each "
                               "leap's end"},  };
  return table;
}

}  // namespace

BackendEntry gigavoxels_backend() {
  BackendEntry e;
  e.info.name = "gigavoxels";
  e.info.description = "Crassin et al. 2009: N^3-tree with node and brick pools under LRU, kd-restart cone-footprint "
                       "traversal with quadrilinear mipmap filtering, ray-guided feedback and loading, procedural bricks";
  e.info.kinds = {DataKind::structured};
  e.info.modes = {RenderMode::iso, RenderMode::dvr};
  e.info.normals = {NormalMethod::analytic, NormalMethod::central, NormalMethod::forward};
  e.info.params = gigavoxels_params().declarations();
  e.info.pixel_state_bytes = uint32_t(sizeof(gigavoxels::RayState));

  e.info.quality_param = "lod_ratio";
  e.info.quality_sweep = {4, 2, 1, 0.5, 0.25};
  // The loader has at most half the staging slots' worth of bricks asked for at a time
  // (StoreSource's request budget), so none it asked for leaves the cache's L1 before it is
  // copied; the amplified store's coarse sampler reads through L1 too, beside them; the sponge
  // reads no stored brick. A pool sized by hand (brick_slots) leaves the cache the whole budget.
  e.info.l1_staging_slots = [](const BackendParams& p) { return gigavoxels::l1_staging_slots(gigavoxels_params().bind(p)); };
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const GigaVoxelsParams gp = gigavoxels_params().bind(p);
    std::unique_ptr<gigavoxels::Source> source = gigavoxels::make_source(ctx, gp);
    return dispatch_value_type(ctx.bricks().shape().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      using Stored = decltype(stored);
      if (gp.source == 0) return std::make_unique<gigavoxels::GigaVoxelsRenderer<Stored>>(ctx, gp, std::move(source));
      return std::make_unique<gigavoxels::GigaVoxelsRenderer<float>>(ctx, gp, std::move(source));
    });
  };
  return e;
}

}  // namespace brickyard
