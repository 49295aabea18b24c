#pragma once
/// @file renderer.h
/// @brief The interface every back end implements, what it is given (RenderContext) and how
/// it declares itself (BackendInfo).
///
/// Life of a back end (STYLE.md 4, configure, commit, then render read-only):
/// 1. its factory is called with the RenderContext and its resolved parameters: it builds
///    whatever the scene needs, and nothing else;
/// 2. per frame, begin_frame() runs once on one thread (level-of-detail refinement, uploads);
/// 3. render_tile() runs concurrently on disjoint tiles: it is const and must be safe to call
///    from many threads; a pixel's value must not depend on which thread or in which order
///    tiles are rendered, so the image is independent of the thread count;
/// 4. end_frame() runs once after every tile (visibility and usage feedback).
/// Virtual calls happen per tile, never per sample (STYLE.md 3).

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cache/brick_cache.h"
#include "cache/page_cache.h"
#include "core/camera.h"
#include "dataset/dataset.h"
#include "renderers/common/frame.h"
#include "renderers/common/scene.h"

namespace brickyard {

/// @brief One declared parameter; ParamTable (params.h) writes them from the field each binds to.
struct BackendParam {
  std::string name;
  double default_value = 0;
  double lo = 0, hi = 0;  ///< accepted range
  std::string doc;
  bool integer = false;   ///< a count or a switch: fractions are refused
};

class BackendParams;

/// @brief What a back end declares about itself.
struct BackendInfo {
  std::string name;
  std::string description;
  std::vector<DataKind> kinds;
  /// The record kinds it reads through the cache: the session gives the cache's budgets to
  /// these, and a page of each other kind the store holds (an octree beside a grid read by a
  /// brick back end costs one slot, not half the budget).
  std::vector<RecordKind> records = {RecordKind::brick, RecordKind::tet_cluster};
  std::vector<RenderMode> modes;
  bool shadows = false;  ///< casts shadow rays (scenes with `shading.shadows` need it)
  /// How it can compute normals (`shading.normals`); the exact gradient of the interpolant
  /// alone unless it says more. A scene asking for another is refused, not given other normals.
  std::vector<NormalMethod> normals = {NormalMethod::analytic};
  std::vector<BackendParam> params;
  /// The parameter `brickyard bench` sweeps, and its default sweep from fast to accurate.
  std::string quality_param;
  std::vector<double> quality_sweep;
  /// A back end that keeps a fixed brick pool of its own, copied from the cache's L1 (the
  /// GigaVoxels brick pool): the L1 slots it needs to stage one frame's copies. The scene's L1
  /// budget is then shared, not spent twice: the cache's L1 takes these slots (at most a quarter
  /// of the budget, under LRU) and RenderContext::backend_pool_bytes() is the rest. Unset, or 0
  /// for some parameters (a pool sized by hand): the cache's L1 is the whole budget.
  std::function<uint32_t(const BackendParams&)> l1_staging_slots;
  /// Bytes it keeps per pixel across a frame beyond the frame buffers (GigaVoxels' ray states,
  /// carried from pass to pass): `render` and `bench` count them before they start.
  uint32_t pixel_state_bytes = 0;

  bool accepts(DataKind kind, RenderMode mode) const;
};

/// @brief The slots the cache's L1 keeps of an L1 budget of `budget_slots` bricks shared with a
/// back end's own pool (BackendInfo::l1_staging_slots): the `staging` slots asked for, at most a
/// quarter of the budget and at least one. The pool has the rest (share_l1_budget; a back end
/// naming the least budget it can work with counts the same way).
uint64_t l1_staging_share(uint64_t staging, uint64_t budget_slots);

/// @brief Resolved parameter values of one back end: every declared parameter, by name.
class BackendParams {
 public:
  /// @brief Defaults overridden by `given`; an undeclared name or an out-of-range value is
  /// Error(invalid_argument) naming it (and `file`, when the values came from a scene).
  BackendParams(const BackendInfo& info, const std::map<std::string, double>& given, const std::string& file = "");
  double operator[](const std::string& name) const;
  const std::map<std::string, double>& values() const { return values_; }

 private:
  std::map<std::string, double> values_;
};

/// @brief Where the data sits, in the terms rays use. For a grid, the finest level's geometry:
/// world <-> voxel coordinates (voxel i of axis a sits at origin[a] + i * spacing[a]; the volume
/// spans voxel coordinates [0, dims - 1]). For a mesh, "voxel" coordinates are world
/// coordinates from the mesh box's low corner (dims 0, spacing 1).
struct VolumeGeometry {
  Vec3s dims{0};
  Vec3d origin{0.0}, spacing{1.0};
  Box3d world;       ///< the dataset's bounding box in world coordinates
  Box3d voxel_clip;  ///< the region rendered, in voxel coordinates (volume box and clip box)
  double voxel_size = 1;  ///< the dataset's unit length: depth errors are reported in these units

  Vec3d to_voxel(const Vec3d& w) const { return (w - origin) / spacing; }
  Vec3d to_world(const Vec3d& v) const { return origin + v * spacing; }
  /// @brief A point in coordinates normalised to the volume's box, in world coordinates.
  Vec3d from_normalised(const Vec3d& n) const { return world.lo + n * world.extent(); }
};

/// @brief Everything shared by the back ends of one scene, immutable while frames render: the
/// scene, the dataset's generic part and its typed views, and the cache (the only way to the
/// data: no store is reachable from here).
///
/// Lifetime: the scene, the dataset and the caches are the caller's (a RenderSession's) and
/// must outlive the context and every back end built on it.
class RenderContext {
 public:
  /// @param bricks  the grid's bricks in `pages`, for a dataset with a grid view; else null.
  RenderContext(const Scene& scene, const Dataset& dataset, PageCache& pages, BrickCache* bricks);

  const Scene& scene() const { return scene_; }
  /// @brief The generic part: kind, world box, value range, time steps, provenance.
  const DatasetInfo& dataset() const { return dataset_.info(); }
  DataKind kind() const { return dataset_.kind(); }
  /// @brief The grid view. @throws Error(unsupported) naming the dataset when it has none: a
  /// back end that asks for it in its factory is refused before the first frame.
  const GridView& grid() const { return dataset_.grid(); }
  /// @brief The tetrahedral mesh's view (cluster table). @throws Error(unsupported) when none.
  const TetView& tets() const { return dataset_.tets(); }
  /// @brief The octree volume beside the grid. @throws Error(unsupported) when it has none,
  /// naming the command that builds one.
  const OctreeView& octree() const { return dataset_.octree(); }
  /// @brief Every record kind through one cache.
  PageCache& pages() const { return *pages_; }
  /// @brief The grid's bricks in the cache. @throws Error(unsupported) when the dataset has no grid.
  BrickCache& bricks() const {
    if (!bricks_) (void)dataset_.grid();  // throws, naming the dataset
    return *bricks_;
  }
  const GridLayout& layout() const { return grid().layout(); }
  const NodeTable& nodes() const { return grid().nodes(); }
  const VolumeGeometry& geometry() const { return geometry_; }
  /// @brief Whether a node can contribute to the image: its value range meets an isovalue or
  /// the transfer function's non-zero opacity (the scene's value filter). Nodes that cannot are
  /// never fetched.
  bool node_visible(const NodeRecord& n) const { return scene_.value_range_visible(n.min, n.max); }
  /// @brief The value range of a node and of every node below it, down to the finest level.
  /// A node's own range is its level's, which averaging narrows: a feature finer than the level
  /// (a small object, a sheet thinner than its voxels) can be missing from it altogether, so a
  /// back end that stops above the finest level decides what it can skip by this range.
  /// Computed on first use (one pass over the node table), then read by any thread.
  struct ValueSpan {
    float lo = 0, hi = 0;
  };
  const ValueSpan& range_below(const BrickKey& k) const;
  /// @brief node_visible() for a node and everything below it (range_below()).
  bool subtree_visible(const BrickKey& k) const {
    const ValueSpan& r = range_below(k);
    return scene_.value_range_visible(r.lo, r.hi);
  }
  /// @brief Whether the renderer must compute gradients: shading is on, or normals are asked for.
  bool needs_gradients(const FrameOutputs& outputs) const {
    return outputs.normals || (scene_.shading.lit() && scene_.mode != RenderMode::mip);
  }
  /// @brief What a back end that keeps its own brick pool (BackendInfo::l1_staging_slots) may
  /// allocate for it: the part of the L1 budget the cache's L1 left (share_l1_budget), or the
  /// cache's whole L1 budget for a cache built without sharing it.
  uint64_t backend_pool_bytes() const;
  /// @brief Points the context at a new cache (a session's reset_cache()), between frames and
  /// with no back end alive that was built on the old one.
  void rebind_cache(PageCache& pages, BrickCache* bricks);

 private:
  const Scene& scene_;
  const Dataset& dataset_;
  PageCache* pages_;
  BrickCache* bricks_;
  VolumeGeometry geometry_;
  mutable std::once_flag ranges_below_once_;
  mutable std::vector<std::vector<ValueSpan>> ranges_below_;  // per level, per node
};

/// @brief One frame to render: the camera in world coordinates and what to produce.
struct FrameSetup {
  Camera camera;
  int width = 0, height = 0;
  int frame = 0;
  int time_step = 0;  ///< the dataset's time step this frame draws (Scene::step_of)
  FrameOutputs outputs;
};

struct Tile {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  ///< pixels [x0, x1) x [y0, y1)
};

class Renderer {
 public:
  virtual ~Renderer() = default;
  virtual void begin_frame(const FrameSetup& setup) { (void)setup; }
  virtual void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const = 0;
  virtual void end_frame(const FrameSetup& setup, const FrameBuffers& out) { (void)setup, (void)out; }
  /// @brief After end_frame(): whether rays stopped at missing data and the tiles must be
  /// rendered again, resuming them (an exact mode that loads between passes). Each further
  /// pass is followed by end_frame() again.
  virtual bool another_pass() { return false; }
  /// @brief Adds the back end's own figures (phases, working-set sizes) to the frame's statistics.
  virtual void add_statistics(FrameStats& stats) const { (void)stats; }
  /// @brief Whether the last frame showed everything the back end wants to show: false while
  /// an asynchronous back end is still refining or waiting for data (the image converges over
  /// frames). Benchmarks settle back ends before timing warm frames.
  virtual bool converged() const { return true; }
  /// @brief On while the caller renders frames it will not show, only the converged one
  /// after them (a still image, a benchmark's warm-up): a back end that refines over frames
  /// as its data arrives may complete each frame instead, waiting for its data. Off for
  /// frames that are shown, and where the frames to converge are what is measured.
  virtual void set_complete_frames(bool complete) { (void)complete; }
};

using BackendFactory = std::function<std::unique_ptr<Renderer>(const RenderContext&, const BackendParams&)>;

struct BackendEntry {
  BackendInfo info;
  BackendFactory create;
};

/// @brief Back ends by name (STYLE.md 2): explicitly registered, an unknown name is an error
/// listing the known ones.
class BackendRegistry {
 public:
  /// @throws Error(invalid_argument) when a back end of that name is registered already.
  void add(BackendEntry entry);
  const BackendEntry& find(const std::string& name) const;
  bool contains(const std::string& name) const;
  const std::vector<BackendEntry>& entries() const { return entries_; }
  std::vector<std::string> names() const;

 private:
  std::vector<BackendEntry> entries_;
};

/// @brief The built-in back ends (registered on first use, in renderers/common/registry.cpp).
const BackendRegistry& builtin_backends();
/// @brief The process's back ends: the built-in ones, then those that modules loaded
/// (session/modules.h) registered. Modules are loaded before any session is built; after
/// that the registry is only read, from any thread.
BackendRegistry& backends();

}  // namespace brickyard
