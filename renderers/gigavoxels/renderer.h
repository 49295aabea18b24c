#pragma once
/// @file renderer.h
/// @brief `gigavoxels`: GigaVoxels (Crassin, Neyret, Lefebvre and Eisemann 2009) on the CPU,
/// keeping its GPU structure: a node pool and a brick pool of fixed size (node_tree.h), rays
/// that decide by their own traversal what is used, what must be subdivided and what is
/// missing, per-pixel feedback lists compacted before the loader sees them (feedback.h), and a
/// loader that only reads the compacted lists.
///
/// Per ray: from the volume's entry point, kd-restart descent from the root at every new
/// position, stopping at the node whose voxels match the ray's cone footprint there (a voxel
/// covers at most lod_ratio pixels), collecting the bricks of the last 3 levels met. The
/// footprint is no coarser than the voxels of the coarsest level that still resolves every
/// axis (dataset/grid.h): on a very anisotropic store the coarse levels have collapsed its
/// short axes to a voxel or two, and are never used. Constant
/// nodes are integrated in closed form; brick nodes are marched with a step and a mip level
/// chosen from the footprint, blending the two nearest levels (quadrilinear filtering). A node
/// that should be finer asks to be subdivided, a node without its brick asks for it (at most one
/// request per ray); the ray goes on with coarser data (approximate mode) or stops and resumes
/// after the loader has served the pass (exact mode).
/// Two CPU economies that change no image: a descent resumes from the deepest node of the last
/// one (the ray's own, or the tile's previous ray's) that still contains the new position (the
/// nodes it then passes are the ones a descent from the root would), and inside a brick, rays
/// leap the 4^3-cell groups that hold nothing visible, as many at once as their distance to a
/// visible group allows (cell_groups.h), to the first sample position past them.
/// DVR's step grows as the ray gathers opacity (adaptive_step): a sample behind it counts less.
/// Between frames (end_frame, one thread): compaction, usage stamps, LRU order, then the
/// requests within the per-frame budgets.
///
/// The parts, one translation unit each: sources.cpp (where bricks come from), frame.cpp (the
/// frame, its passes and the loader), descent.cpp (a ray's node-by-node march: tracer.h),
/// iso.cpp (surfaces), dvr.cpp (volume rendering), gigavoxels.cpp (parameters, registration).
/// Each .cpp explicitly instantiates what it defines for the brick pool's three voxel types.
///
/// Thread safety: during a pass, render_tile() runs on many threads: each pixel's RayState is
/// written by the one thread that renders it, and the node tree, the pools and everything
/// else are read-only. begin_frame(), end_frame() (the loader) and another_pass() run on one
/// thread between passes.

#include <atomic>
#include <cassert>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <set>
#include <tuple>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "core/pool_memory.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"
#include "renderers/gigavoxels/cell_groups.h"
#include "renderers/gigavoxels/feedback.h"
#include "renderers/gigavoxels/field_bounds.h"
#include "renderers/gigavoxels/node_tree.h"
#include "renderers/gigavoxels/preintegrated.h"
#include "renderers/gigavoxels/sources.h"

namespace brickyard::gigavoxels {

/// The brick pool's voxel types (a store's own, or float for produced bricks): each .cpp
/// explicitly instantiates what it defines, X(type) for each.
#define BRICKYARD_GIGAVOXELS_FOR_VOXELS(X) X(uint8_t) X(int8_t) X(uint16_t) X(int16_t) X(float)

inline constexpr double kInf = std::numeric_limits<double>::infinity();
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Feedback entries: a node address and what the ray wants of it.
inline constexpr uint32_t kAddressMask = 0x3fffffffu;
inline constexpr uint32_t kWantsSubdivision = 0x80000000u;
inline constexpr uint32_t kWantsBrick = 0x40000000u;

/// @brief The parameters (gigavoxels.cpp declares them, with their defaults and docs).
struct GigaVoxelsParams {
  double lod_ratio{};          // 0: the scene's quality.lod_ratio
  double step{};               // in voxels of the level sampled
  bool exact{};
  bool quadrilinear{};
  int slots_per_pixel{};
  int subdivide_budget{};      // subdivisions per frame
  int upload_budget{};         // bricks written into the pool per frame
  uint32_t brick_slots{};      // 0: what the L1 budget holds beside the cache's staging L1
  uint32_t node_blocks{};      // 0: twice the brick slots
  int source{};                // 0 store, 1 Menger sponge (N = 3), 2 the store amplified
  int menger_brick{};
  int amplify_levels{};
  double amplify_amplitude{}, amplify_gain{};
  int amplify_seed{};
  int max_passes{};            // exact mode
  int refine{};
  bool skip_cells{};           // leap the cells of a brick that hold nothing visible
  int hidden_crossings{};      // iso: a step is searched for a crossing pair it may hide, down to 2^-this voxels (0: none)
  double adaptive_step{};      // DVR: the most a step grows where a sample counts less (1: fixed)
  bool face_lighting{};        // DVR: a segment's end lightings weighted by the cell faces it crosses
  bool middle_lighting{};      // and the cells between its first and last faces lit at their middle
  bool sample_runs{};          // DVR at one level: runs of samples taken side by side (sample_run)
  bool termination_fill{};     // DVR: a terminated ray's light left takes its last segment's colour
  bool leap_chains{};          // DVR at one level: leaps follow each other with no sample between (chain_leaps)
};

/// @brief The cache's L1 slots the loader stages its copies through when the brick pool shares
/// the L1 budget (BackendInfo::l1_staging_slots): a pass's loads beside the last pass's, the
/// amplified store's coarse sampler beside them; one for the sponge, which reads no stored
/// brick. 0 for a pool sized by hand (brick_slots), which leaves the cache the whole budget.
inline uint32_t l1_staging_slots(const GigaVoxelsParams& p) {
  if (p.brick_slots != 0) return 0;
  if (p.source == 1) return 1;
  return uint32_t(2 * p.upload_budget) + (p.source == 2 ? kCoarseSamplerSlots : 0);
}

/// @brief The fewest brick slots a pool sized from the L1 budget may have: the root's and a
/// few to refine into. A budget that leaves the pool fewer is refused, naming the L1 that
/// gives it these, rather than a pool allocated past the budget.
inline constexpr uint32_t kMinBrickSlots = 8;

/// N^depth, as an unevaluated sum hi + lo of two doubles: exact while N^depth < 2^106 (the
/// integer fits 64 bits up to 3^40 and 2^63).
struct Scale {
  double hi = 1, lo = 0;
};

/// What a ray has done so far: exact mode interrupts rays at missing data and resumes them.
struct RayState {
  enum Status : uint8_t { fresh, interrupted, done } status = fresh;
  double t = 0;         // where the next descent locates the ray's node
  double t_sample = 0;  // where the next sample goes: past t when the step outreaches the node
  Vec3d accum{0.0};
  double alpha = 0;
  double step_scale = 1;  // DVR: the next step's length, in base steps (adaptive_step)
  double prev_t = 0;
  float prev_value = 0;
  bool have_prev = false;
  // DVR: the previous sample's gradient and, once computed, its lighting: a segment is
  // shaded with its two ends' lighting (face_lighting.h), each computed once.
  bool have_prev_gradient = false, have_prev_lighting = false;
  Vec3d prev_gradient{0.0};
  ShadingModel::Lighting prev_lighting;
  Vec3f last_color{0.0f};  // DVR: the last segment composited, shaded (termination_fill)

  /// The next segment starts at `at` with `value`, where no gradient was taken.
  void start_segment(float value, double at) {
    prev_value = value, prev_t = at, have_prev = true;
    have_prev_gradient = have_prev_lighting = false;
  }
};

template <typename Voxel>
struct Tracer;

/// Voxel: the brick pool's type, the store's own for a store (a copy of its bricks, 1 byte
/// per voxel for 8-bit data: the samples are memory-bound) and float for produced bricks.
template <typename Voxel>
class GigaVoxelsRenderer final : public Renderer {
 public:
  GigaVoxelsRenderer(const RenderContext& ctx, const GigaVoxelsParams& p, std::unique_ptr<Source> source);

  // The frame and its passes (frame.cpp); its tiles' rays (descent.cpp).
  void begin_frame(const FrameSetup& setup) override;
  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override;
  void end_frame(const FrameSetup& setup, const FrameBuffers& out) override;
  bool another_pass() override;
  void add_statistics(FrameStats& stats) const override;

  /// An approximate frame: its rays needed nothing (or nothing could be served for 3 frames);
  /// an exact one (exact=1, or complete frames): its last pass needed nothing, or could not be
  /// served. Judged by the mode the last frame was rendered in, whatever was asked since.
  bool converged() const override {
    return frame_exact_ ? last_pass_requests_ == 0 || last_pass_progress_ == 0 : frame_requests_ == 0 || stalled_frames_ >= 3;
  }

  /// Frames nobody sees are rendered in exact mode: approximate frames are each drawn whole
  /// while at most upload_budget more bricks arrive, so a cold start over a large store draws
  /// tens of them where exact passes redraw only the rays that stopped.
  void set_complete_frames(bool complete) override { complete_frames_ = complete; }

  const NodeTree& tree() const { return tree_; }
  const Voxel* brick(uint32_t slot) const { return pool_.get() + size_t(slot) * tree_.brick_values(); }
  const uint8_t* group_distances(uint32_t slot) const { return group_distances_.data() + size_t(slot) * group_count_; }
  const BrickDifferences& brick_differences_of(uint32_t slot) const {
    assert(slot < brick_differences_.size());  // kept only where keeps_differences()
    return brick_differences_[slot];
  }

 private:
  friend struct Tracer<Voxel>;  // a pass's rays read the pools and the frame's constants

  // Sizes and constants, fixed at construction (frame.cpp).
  /// The brick pool: what the L1 budget holds once the cache's L1 has the slots the loader
  /// stages its copies through (l1_staging_slots), with each slot's bounds.
  /// @throws Error(invalid_argument) naming cache.l1 and the least L1 that gives the pool
  /// kMinBrickSlots, for a budget that gives it fewer.
  static uint32_t brick_slots(const RenderContext& ctx, const GigaVoxelsParams& p, const Source& s);
  static uint32_t node_blocks(const RenderContext& ctx, const GigaVoxelsParams& p, const Source& s);
  static uint64_t slot_bytes(int m, bool with_differences);
  /// Whether bricks keep their differences: only iso's search for hidden crossings reads them,
  /// where it halves a step at least once (search_hidden_crossings_).
  static bool keeps_differences(const RenderContext& ctx, const GigaVoxelsParams& p);
  /// The base step, in voxels of the level sampled.
  static double base_step(const Scene& scene, const GigaVoxelsParams& p);
  /// Halvings of a step down to parts of 2^-hidden_crossings voxels whatever the step, so that a
  /// coarser step costs fewer samples, not thinner features missed (0: none).
  static int search_halvings(const Scene& scene, const GigaVoxelsParams& p);
  /// Cell groups per axis: the cells start at sample coordinates 0 .. M (M + 1 of them, the
  /// border included), kCellGroup to a group.
  static int groups_per_axis(int m) { return m / kCellGroup + 1; }
  static size_t group_count(int m) {
    const size_t g = size_t(groups_per_axis(m));
    return g * g * g;
  }
  /// N^depth for every depth up to max_depth.
  static std::vector<Scale> node_scales(int n, int max_depth);

  // The loader (frame.cpp).
  /// What rays may assume about a freshly written brick: its group distances (a group shows
  /// something when the range of its voxels, the corners of its cells up to the brick's last
  /// voxel, does) and its differences (BrickDifferences), which bound its field along a ray.
  void set_brick_bounds(uint32_t slot);
  Node node_for(const NodeContent& c, int depth) const;
  Node root_node() const { return node_for(source_->classify(NodeAddress{}), 0); }
  /// Writes a brick for the node if its data is available (or shared and resident already).
  Source::Fill upload(uint32_t address, bool wait);
  /// Compacts the pass's feedback, stamps what it used, then serves the bricks in transit, the
  /// bricks asked for and the subdivisions asked for, in that order, within the budgets.
  void serve_feedback();

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  GigaVoxelsParams p_;
  ShadingModel shading_;
  std::unique_ptr<Source> source_;
  NodeTree tree_;
  PoolArray<Voxel> pool_;  // the brick pool's voxels, brick_capacity() x (M + 2)^3
  std::optional<float> outside_value_;  // the value outside the volume, where it is defined
  std::vector<Scale> scales_;  // N^depth
  std::vector<double> inv_scales_;  // 1 / N^depth, rounded
  double unit_offset_ = 0.5;   // unit = (voxel + unit_offset) / extent
  // A level's dims in voxels, per depth (difference normals stop at the volume's faces, as
  // the reference's do); empty for the sponge, whose nodes' bricks bound its differences.
  std::vector<Vec3s> level_dims_;
  double lod_ratio_ = 1, extent_ = 1, step_ = 0.5, finest_voxel_unit_ = 1;
  Vec3d unit_gradient_to_world_{1.0};  // a gradient per unit-cube length to one per world length
  double footprint_per_t_ = 0;  // a pixel's footprint per unit distance, unit coordinates, times lod_ratio
  // The largest footprint (unit coordinates): the voxel of the coarsest depth whose level still
  // resolves every axis of the store (GridLayout::coarsest_resolving); infinite where level 0 does.
  double max_footprint_ = kInf;
  bool wide_values_ = false;  // needs_wide_interpolation: values near the largest float
  double inv_log2_arity_ = 1;
  int n_ = 2, m_ = 32;
  double inv_m_ = 1.0 / 32;
  int groups_ = 9;            // cell groups per brick axis
  size_t group_count_ = 729;  // cell groups per brick
  std::vector<uint8_t> group_distances_;  // brick_capacity() x group_count_
  std::vector<BrickDifferences> brick_differences_;  // per slot (set_brick_bounds), where keeps_differences
  int search_halvings_ = 0;                // of a step: to parts of 2^-hidden_crossings voxels
  bool search_hidden_crossings_ = false;  // iso with search_halvings_ > 0
  PreintegratedTf preintegrated_;

  // Per frame: the feedback buffer and the rays' states, written by the render threads (each
  // pixel by one thread), read by the loader between passes.
  uint64_t frame_ = 0;
  std::unique_ptr<UseBuffer> uses_;
  mutable std::vector<RayState, PoolAllocator<RayState>> states_;
  bool allow_interrupt_ = false;
  bool complete_frames_ = false;  // set_complete_frames()
  bool frame_exact_ = false;      // the frame under way (or the last one) takes exact passes
  Compactor compactor_;
  std::vector<uint32_t> used_list_, request_list_;
  /// A brick the loader asked the store for, copied into the pool when it arrives whether or
  /// not a ray asks for it again: a ray asks only for the first thing it misses, which moves
  /// as other data arrives, and loaded bricks left waiting for the ray to ask again were pushed
  /// out of the cache's L1 stages by later ones (on fBm 1024^3 at 256x256, a cold start took
  /// 463 frames to converge before, 76 now).
  struct InTransit {
    uint32_t address;
    NodeAddress node;  // whose brick: the address may be reused by then
    uint64_t since;    // the frame it was first asked for
  };
  /// A load normally arrives the next frame (the cache's p99 latency was 23-88 ms against
  /// frames of 0.1-1 s); one this late is left to the rays to ask for again.
  static constexpr uint64_t kTransitFrames = 16;
  std::vector<InTransit> in_transit_;
  std::unordered_set<uint32_t> transit_addresses_;  // in_transit_'s, rebuilt each pass (a member for its buckets)
  std::vector<uint32_t> wanted_bricks_;   // a pass's nodes whose bricks the loader serves, in order
  std::vector<NodeAddress> read_ahead_;   // the first of them, read side by side in an exact pass
  std::vector<float> scratch_;
  std::unordered_map<uint64_t, uint32_t> shared_;  // instanced brick id -> slot
  // Nodes whose brick could not be read (corrupt or missing in the store): drawn from the
  // bricks above them and never asked for again. Changed between passes only.
  std::set<std::tuple<int, int64_t, int64_t, int64_t>> damaged_;
  bool damaged(int depth, const int64_t c[3]) const {
    return !damaged_.empty() && damaged_.contains({depth, c[0], c[1], c[2]});
  }
  CompactionReport compaction_;
  uint64_t passes_ = 0, interrupted_ = 0, frame_subdivisions_ = 0, frame_uploads_ = 0, frame_requests_ = 0, frame_uses_ = 0;
  uint64_t last_pass_progress_ = 0, last_pass_requests_ = 0;
  // Exact mode: the rays still waiting when the frame stopped interrupting them (passes used
  // up, or a pass that served nothing), which took coarser data; and which of the two it was.
  uint64_t rays_cut_short_ = 0;
  bool out_of_passes_ = false;
  uint64_t produced_before_ = 0, loaded_before_ = 0, failed_before_ = 0;
  mutable std::atomic<uint64_t> samples_in_runs_{0};  // this frame's samples that sample_run took, added once per tile
  mutable std::atomic<uint64_t> leaps_chained_{0};    // this frame's leaps that chain_leaps took on, added once per tile
  int stalled_frames_ = 0;
  int frames_loading_ = 0;  // first passes in a row that only waited on loads
  double loader_seconds_ = 0;
};

}  // namespace brickyard::gigavoxels
