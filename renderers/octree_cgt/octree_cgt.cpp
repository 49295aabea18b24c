// octree_cgt's parameters, its frame (the major axis and the transition slices, once per
// frame) and its registration; the parts are listed in renderer.h.

#include <cmath>
#include <limits>
#include <memory>

#include <fmt/format.h>

#include "core/error.h"
#include "dataset/grid.h"
#include "renderers/octree_cgt/renderer.h"
#include "renderers/octree_cgt/tracer.h"

namespace brickyard {
namespace octree_cgt {

const ParamTable<Params>& params_table() {
  static const ParamTable<Params> table{
      {"packet", &Params::packet, 8, 1, 16,
       "packets of packet x packet rays traverse the octree together (2, 4, 8 or 16); 1: single-ray mode"},
      {"packlet", &Params::packlet, 0, 0, 16,
       "packets' lanes are tested together in packlets of this many SIMD lanes (4, 8 or 16); 0: the build's width"},
      {"mcell", &Params::mcell, 1, 0, 1, "1: skip octree nodes and pages whose range holds no isovalue; 0: visit them (Table II)"},
      {"cell", &Params::cell, 1, 0, 1, "1: skip cells whose corners' range holds no isovalue; 0: solve every cell's cubic"},
      {"slice", &Params::slice, 1, 0, 1,
       "packets, 1: a cap's 3x3x3 voxels gathered once for its cells; 0: every cell looks up its 8 corners"},
      {"dpdv", &Params::dpdv, 0.0, 0.0, 64.0,
       "level of detail (the paper's dP/dV): a node's own coarser voxels are used where one covers at most this many pixels "
       "at the node's nearest slice along K; 0: always the finest"},
      {"multires", &Params::multires, 1, 0, 1,
       "1: levels of detail at dpdv (the paper's multiresolution); 0: the finest level everywhere (Table II)"},
      {"smooth", &Params::smooth, 1, 0, 1,
       "1: smooth transitions: cells between a level of detail and the coarser one beyond it, so that their surfaces meet "
       "without cracks; 0: none (cracks where levels meet)"},
      {"shadow_dpdv", &Params::shadow_dpdv, 2.0, 1.0, 64.0,
       "shadow rays are traced through a coarser level of detail: dP/dV this many times the primary rays'"},
      {"show_levels", &Params::show_levels, 0, 0, 1, "1: colour each hit by the level of detail it was found at"},
      {"pinned_pages", &Params::pinned_pages, 64, 4, 4096,
       "octree pages one tile keeps pinned in the cache's L1 while it renders (then released, and fetched again)"},
      {"root_tolerance", &Params::root_tolerance, 1e-12, 0.0, 1e-3,
       "a tangent touch of the isosurface counts as a hit where the cell's cubic comes this close to zero (relative)"},
  };
  return table;
}

Shared::Shared(const RenderContext& context, const Params& params)
    : ctx(context), scene(context.scene()), geo(context.geometry()), view(context.octree()), layout(view.layout()),
      p(params), shading(scene.shading, geo) {
  for (const auto& s : scene.isosurfaces) iso.push_back(s.value);
  for (int d = 0; d < layout.depth; ++d) nodes_at.push_back(layout.nodes_at(d));
  for (int l = 0; l < layout.depth; ++l) level_dims.push_back(layout.level_dims(l));
}

void Shared::plan_frame(const FrameSetup& setup) {
  // The major axis K, once per frame: the camera's forward direction's largest component in
  // voxel coordinates (packets whose rays disagree with it along K go ray by ray).
  Vec3d f, right, up;
  setup.camera.basis(f, right, up);
  const Vec3d fv = f / geo.spacing;
  major_axis = std::abs(fv.x) >= std::abs(fv.y) && std::abs(fv.x) >= std::abs(fv.z) ? 0 : std::abs(fv.y) >= std::abs(fv.z) ? 1 : 2;
  // The transition slices (the paper's Algorithm 2): a node at depth d is drawn with its own
  // level-L voxels from K distance lod_k[d] on, where one of them covers dpdv pixels. A pixel
  // covers z * pixel_angle of world at view depth z, and a slice k voxels away along K lies at
  // z = k * spacing_K / |forward_K|.
  packlet_lanes = p.packlet ? p.packlet : kBuildPackletLanes;
  const int K = major_axis;
  eye_k = geo.to_voxel(setup.camera.eye)[K];
  const double pixel_angle = 2.0 * std::tan(setup.camera.fov_degrees * M_PI / 360.0) / double(std::max(setup.height, 1));
  const double fk = std::max(std::abs(f[K]), 1e-12);
  lod = p.multires && p.dpdv > 0;
  lod_k.assign(size_t(layout.depth), std::numeric_limits<double>::infinity());
  shadow_lod_k = lod_k;
  // A level coarser than the grid's resolving steps (dataset/grid.h) has collapsed a short
  // axis of a very anisotropic grid: it is never drawn (its transition slice stays infinite).
  const int coarsest = resolving_steps(layout.dims);
  if (lod)
    for (int d = 0; d < layout.depth; ++d) {
      if (layout.level_of_depth(d) > coarsest) continue;
      const double voxel = double(int64_t(1) << layout.level_of_depth(d)) * geo.voxel_size;
      lod_k[size_t(d)] = voxel / (p.dpdv * pixel_angle) * fk / geo.spacing[K];
      shadow_lod_k[size_t(d)] = lod_k[size_t(d)] / p.shadow_dpdv;
    }
}

namespace {

template <typename T>
class OctreeCgtRenderer final : public Renderer {
 public:
  OctreeCgtRenderer(const RenderContext& ctx, const Params& p) : shared_(ctx, p) {}

  void begin_frame(const FrameSetup& setup) override { shared_.plan_frame(setup); }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    Tracer<T> t(shared_, setup, counters);
    if (shared_.p.packet > 1) return t.render_packets(tile, shared_.p.packet, out);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) t.pixel(x, y, out);
  }

 private:
  Shared shared_;
};

}  // namespace
}  // namespace octree_cgt

BackendEntry octree_cgt_backend() {
  BackendEntry e;
  e.info.name = "octree_cgt";
  e.info.description = "Knoll et al.: isosurfaces of an octree volume (brickyard build-octree), exact trilinear "
                       "roots, octree pages through the cache; single-ray mode";
  e.info.kinds = {DataKind::structured};
  e.info.records = {RecordKind::octree_page};
  e.info.modes = {RenderMode::iso};
  e.info.shadows = true;
  e.info.normals = {NormalMethod::analytic, NormalMethod::central, NormalMethod::forward};
  e.info.params = octree_cgt::params_table().declarations();
  e.info.quality_param = "dpdv";
  e.info.quality_sweep = {4.0, 2.0, 1.0, 0.5, 0.0};
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const octree_cgt::Params op = octree_cgt::params_table().bind(p);
    if (op.packet & (op.packet - 1))
      throw Error(Errc::invalid_argument, fmt::format("packet {} is not 1, 2, 4, 8 or 16", op.packet)).with_field("packet");
    if (op.packlet != 0 && op.packlet != 4 && op.packlet != 8 && op.packlet != 16)
      throw Error(Errc::invalid_argument, fmt::format("packlet {} is not 0, 4, 8 or 16", op.packlet)).with_field("packlet");
    return dispatch_value_type(ctx.octree().layout().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      return std::make_unique<octree_cgt::OctreeCgtRenderer<decltype(stored)>>(ctx, op);
    });
  };
  return e;
}

}  // namespace brickyard
