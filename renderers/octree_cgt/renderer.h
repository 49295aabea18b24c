#pragma once
/// @file renderer.h
/// @brief `octree_cgt`: isosurface ray tracing of an octree volume (Knoll, Hijazi, Kensler,
/// Schott, Hansen, Hagen, "Interactive isosurface ray tracing of large octree volumes"), its
/// pages read through the cache.
///
/// Two modes of one structure. Packets (the default, 8 x 8 rays): a packet descends the
/// octree's implicit macrocells once, nearer half along the frame's major axis K first, culled
/// by its frustum over K and by node ranges (cells of every finer level, forward neighbours
/// included); each node keeps the lanes whose ray crosses it before their hit so far; in a cap,
/// each lane visits the cells its ray crosses slice by slice along K, corners read from the
/// cap's 3x3x3 voxels gathered once. The single-ray mode (`packet` 1), which the paper measures
/// the coherent one against: a front-to-back descent per ray, children in entry order. In both,
/// each cell's trilinear cubic along the ray is solved exactly (first root, tangent roots
/// included), and consolidated subtrees are walked only along their forward faces, where their
/// cells meet other values. `mcell`, `cell` and `slice` switch the culling and the shared
/// gathering off, for the paper's Table II; the image does not change.
///
/// The parts: tracer.h (a tile's traversal state), nodes.h (the octree's nodes on the way
/// down), cells.h (a leaf's cells and their roots), descent.cpp (single rays, shading),
/// packets.cpp (packets), octree_cgt.cpp (parameters, the frame, registration). Each .cpp
/// explicitly instantiates what it defines for the store's three value types.

#include <cstdint>
#include <vector>

#include "dataset/octree.h"
#include "renderers/common/params.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"

namespace brickyard::octree_cgt {

/// The store's value types: each .cpp explicitly instantiates what it defines, X(type) for each.
#define BRICKYARD_OCTREE_CGT_FOR_VOXELS(X) X(uint8_t) X(int8_t) X(uint16_t) X(int16_t) X(float)

/// The SIMD lanes of the build's target, in float: a packlet's width by default.
#if defined(__AVX512F__)
inline constexpr int kBuildPackletLanes = 16;
#elif defined(__AVX__)
inline constexpr int kBuildPackletLanes = 8;
#else
inline constexpr int kBuildPackletLanes = 4;
#endif

/// Lanes reaching a leaf from which its cells are tested a packlet at a time rather than lane
/// by lane.
inline constexpr int kPackletCellsLanes = 8;

struct Params {
  int packet{};             // rays per side of a packet; 1: the single-ray mode
  int packlet{};            // lanes a packet's tests run on together (4, 8, 16); 0: the build's SIMD width
  bool mcell{};             // cull macrocells (octree nodes, pages) by their range
  bool cell{};              // cull cells by their corners' range before solving their cubic
  bool slice{};             // packets: a cap's voxels gathered once for all its cells
  double dpdv{};            // level of detail: pixels a coarse voxel may cover; 0: the finest level
  bool multires{};          // levels of detail on (at dpdv); 0: the finest level whatever dpdv says
  bool smooth{};            // cells between levels of detail, so that their surfaces meet
  double shadow_dpdv{};     // shadow rays' dP/dV as a multiple of the primary rays'
  bool show_levels{};       // colour hits by the level they were found at
  int pinned_pages{};       // pages a tile keeps pinned before it lets them go
  double root_tolerance{};  // relative |g| at an extremum of the cell's cubic that counts as a touching root
};

const ParamTable<Params>& params_table();

/// What every tile of a frame reads: the scene, the octree, and the frame's plan (written by
/// begin_frame() on one thread, read-only while tiles render).
struct Shared {
  Shared(const RenderContext& context, const Params& params);

  const RenderContext& ctx;
  const Scene& scene;
  const VolumeGeometry& geo;
  const OctreeView& view;
  OctreeLayout layout;
  Params p;
  ShadingModel shading;
  std::vector<double> iso;
  std::vector<Vec3s> nodes_at;    // per depth
  std::vector<Vec3s> level_dims;  // per level of detail
  int major_axis = 0;             // K, chosen by plan_frame()
  int packlet_lanes = kBuildPackletLanes;  // W, chosen by plan_frame()
  double eye_k = 0;               // the eye's K coordinate, finest voxels
  bool lod = false;               // levels of detail this frame (multires and dpdv > 0)
  std::vector<double> lod_k;      // per depth: the K distance from which a node is drawn at its own level
  std::vector<double> shadow_lod_k;  // the same for shadow rays (at shadow_dpdv x dpdv: nearer)

  /// The frame's major axis and transition slices.
  void plan_frame(const FrameSetup& setup);
};

}  // namespace brickyard::octree_cgt
