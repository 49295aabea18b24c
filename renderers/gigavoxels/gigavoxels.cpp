// `gigavoxels`: GigaVoxels (Crassin, Neyret, Lefebvre and Eisemann 2009) on the CPU, keeping
// its GPU structure: a node pool and a brick pool of fixed size (node_tree.h), rays that decide
// by their own traversal what is used, what must be subdivided and what is missing, per-pixel
// feedback lists compacted before the loader sees them (feedback.h), and a loader that only
// reads the compacted lists.
//
// Per ray: from the volume's entry point, kd-restart descent from the root at every new
// position, stopping at the node whose voxels match the ray's cone footprint there (a voxel
// covers at most lod_ratio pixels), collecting the bricks of the last 3 levels met. Constant
// nodes are integrated in closed form; brick nodes are marched with a step and a mip level
// chosen from the footprint, blending the two nearest levels (quadrilinear filtering). A node
// that should be finer asks to be subdivided, a node without its brick asks for it (at most one
// request per ray); the ray goes on with coarser data (approximate mode) or stops and resumes
// after the loader has served the pass (exact mode).
// Two CPU economies that change no image: a descent resumes from the deepest node of the last
// one (the ray's own, or the tile's previous ray's) that still contains the new position (the
// nodes it then passes are the ones a descent from the root would), and inside a brick, rays
// leap the 4^3-cell groups that hold nothing visible, as many at once as their distance to a
// visible group allows (cell_groups.h), to the first sample position past them.
// DVR's step grows as the ray gathers opacity (adaptive_step): a sample behind it counts less.
// Between frames (end_frame, one thread): compaction, usage stamps, LRU order, then the
// requests within the per-frame budgets.

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <unordered_map>
#include <unordered_set>

#include <fmt/format.h>

#include "core/timing.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/common/params.h"
#include "renderers/common/pixel.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"
#include "renderers/gigavoxels/cell_groups.h"
#include "renderers/gigavoxels/corner_lanes.h"
#include "renderers/gigavoxels/face_lighting.h"
#include "renderers/gigavoxels/feedback.h"
#include "renderers/gigavoxels/field_bounds.h"
#include "renderers/gigavoxels/node_tree.h"
#include "renderers/gigavoxels/preintegrated.h"
#include "renderers/gigavoxels/procedural.h"

namespace brickyard {
namespace {

using gigavoxels::Node;
using gigavoxels::NodeAddress;
using gigavoxels::NodeContent;
using gigavoxels::NodeTree;
using gigavoxels::BrickDifferences;
using gigavoxels::FieldBounds;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Feedback entries: a node address and what the ray wants of it.
constexpr uint32_t kAddressMask = 0x3fffffffu;
constexpr uint32_t kWantsSubdivision = 0x80000000u;
constexpr uint32_t kWantsBrick = 0x40000000u;
// The amplified store's coarse sampler reads stored bricks through the cache's L1 beside the
// loader's staged ones: the slots kept for it.
constexpr uint32_t kCoarseSamplerSlots = 64;

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


using gigavoxels::CellPoint;
using gigavoxels::kCellGroup;

/// Where bricks come from: the store through the cache, or a procedural producer.
class Source {
 public:
  virtual ~Source() = default;
  virtual int arity() const = 0;
  virtual int brick_size() const = 0;
  virtual int max_depth() const = 0;
  virtual NodeContent classify(const NodeAddress& a) const = 0;
  /// What fill() did: wrote the values; found the data missing and asked the store for it (or
  /// joined a request already made: it arrives in a later pass); found it missing past the
  /// request budget (asked for in a later pass); or found that it cannot be read (a blocking
  /// fill throws the load's error instead: exact mode stops at a corrupt brick, naming it).
  enum class Fill { filled, requested, missing, failed };
  /// Writes the node's (M + 2)^3 values if the data is resident. With wait, blocks until it is.
  virtual Fill fill(const NodeAddress& a, float* out, bool wait, float priority) = 0;
  /// Bricks shared by many nodes (instancing): an id, or 0 for a brick of its own.
  virtual uint64_t shared_id(const NodeAddress& a) const { (void)a; return 0; }
  /// Bricks computed so far, and bricks read from the store.
  virtual uint64_t produced() const { return 0; }
  virtual uint64_t loaded() const { return 0; }
  /// How many missing bricks fill() may ask the store for until the next call, new requests and
  /// renewals alike: it bounds the loads outstanding. Lookups that hit are not limited: a hit
  /// is copied at once and adds nothing to the cache's L1. Requests are, to at most half the
  /// L1 stages (at least one): a pass's loads must fit beside the last pass's until both are
  /// copied, or they push each other out first (and are loaded again).
  virtual void set_request_budget(uint32_t requests) { (void)requests; }
};

/// A store's brick octree is the N = 2 tree: a node at depth d is the brick of level d.
BrickKey store_key(const NodeAddress& a) { return {uint32_t(a.depth), uint32_t(a.x), uint32_t(a.y), uint32_t(a.z)}; }

template <typename Stored>
class StoreSource final : public Source {
 public:
  /// @param reserved_slots L1 slots another reader keeps pinned beside the loader's stages.
  explicit StoreSource(const RenderContext& ctx, uint32_t reserved_slots = 0)
      : ctx_(ctx), layout_(ctx.layout()), reserved_slots_(reserved_slots) {}
  int arity() const override { return 2; }
  int brick_size() const override { return layout_.brick_size; }
  int max_depth() const override { return layout_.finest(); }
  NodeContent classify(const NodeAddress& a) const override {
    const BrickKey k = store_key(a);
    NodeContent c;
    if (!layout_.contains(k)) return c;  // outside the volume: nothing
    const NodeRecord& n = ctx_.nodes().at(k);
    const RenderContext::ValueSpan& below = ctx_.range_below(k);
    c.lo = below.lo, c.hi = below.hi;
    // A constant node is a constant region only when everything below it is that constant too.
    // Nodes this scene cannot see, down to the finest level, are constants that contribute
    // nothing (no isovalue in their range, or zero opacity all over it).
    if (n.is_constant() && below.lo == below.hi) c.value = n.constant;
    else if (!ctx_.scene().value_range_visible(below.lo, below.hi)) c.value = std::numeric_limits<float>::quiet_NaN();
    else c.kind = NodeContent::brick;
    return c;
  }
  Fill fill(const NodeAddress& a, float* out, bool wait, float priority) override {
    const BrickKey k = store_key(a);
    // Past the budget a miss is not requested: the loader or the rays ask for it again later.
    const bool may_request = requests_left_ > 0;
    BrickHandle h = wait ? ctx_.bricks().fetch(k) : ctx_.bricks().lookup(k, priority, may_request);
    const int64_t m = layout_.brick_size, e = m + 2;
    if (h.constant()) {  // a level's constant over a subtree that is not
      std::fill_n(out, e * e * e, h.constant_value());
      ++loaded_;
      return Fill::filled;
    }
    if (!h.resident()) {
      if (h.failed()) return Fill::failed;
      if (!may_request) return Fill::missing;
      --requests_left_;
      return Fill::requested;
    }
    const Stored* src = h.template voxels<Stored>();
    const int64_t es = ctx_.bricks().shape().edge(), skip = ctx_.bricks().shape().apron - 1;
    for (int64_t z = 0; z < e; ++z)
      for (int64_t y = 0; y < e; ++y) {
        const Stored* row = src + ((z + skip) * es + (y + skip)) * es + skip;
        float* dst = out + (z * e + y) * e;
        for (int64_t x = 0; x < e; ++x) dst[x] = float(row[x]);
      }
    ++loaded_;
    return Fill::filled;
  }
  uint64_t loaded() const override { return loaded_; }
  void set_request_budget(uint32_t requests) override {
    const uint32_t slots = ctx_.bricks().pool_slots(), stages = slots - std::min(reserved_slots_, slots / 2);
    requests_left_ = std::min(requests, std::max(1u, stages / 2));
  }

 private:
  const RenderContext& ctx_;
  const GridLayout& layout_;
  uint32_t reserved_slots_;
  uint64_t loaded_ = 0;
  uint32_t requests_left_ = std::numeric_limits<uint32_t>::max();
};

/// The store down to its finest level, then Perlin-noise amplification of it (procedural.h)
/// for `levels` more: stored and produced bricks in one tree. The coarse field the producer
/// amplifies is the finest stored level, trilinear, read through the cache by the loader.
template <typename Stored>
class AmplifiedSource final : public Source {
 public:
  AmplifiedSource(const RenderContext& ctx, const GigaVoxelsParams& p)
      : ctx_(ctx), layout_(ctx.layout()), stored_(ctx, kCoarseSamplerSlots), coarse_(ctx.bricks(), coarse_counters_, ctx.layout().finest()) {
    const NodeRecord& root = ctx.nodes().at(BrickKey{0, 0, 0, 0});
    gigavoxels::AmplifiedParams ap;
    ap.brick_size = layout_.brick_size;
    ap.stored_depth = layout_.finest();
    ap.max_depth = layout_.finest() + p.amplify_levels;
    ap.amplitude = p.amplify_amplitude * std::max(double(root.max - root.min), 1e-30);  // a fraction of the value range
    ap.gain = p.amplify_gain;
    ap.seed = uint64_t(p.amplify_seed);
    ap.lo = root.min, ap.hi = root.max;
    const double extent = double(layout_.brick_size) * double(int64_t(1) << layout_.finest());
    producer_ = std::make_unique<gigavoxels::AmplifiedProducer>(
        [this, extent](double ux, double uy, double uz) {
          // Unit cube -> finest voxel centres; the sampler clamps into the volume (the root
          // brick's padding beyond the last voxel repeats it). Only fill() calls the producer,
          // holding coarse_mutex_ for the whole brick (a lock per voxel cost more than the
          // trilinear sample).
          return float(coarse_.sample(Vec3d(ux, uy, uz) * extent - Vec3d(0.5)));
        },
        ap);
  }
  int arity() const override { return 2; }
  int brick_size() const override { return layout_.brick_size; }
  int max_depth() const override { return producer_->max_depth(); }
  NodeContent classify(const NodeAddress& a) const override {
    const int s = layout_.finest();
    const int above = std::max(a.depth - s, 0);  // levels below the stored depth
    const BrickKey k{uint32_t(std::min(a.depth, s)), uint32_t(a.x >> above), uint32_t(a.y >> above), uint32_t(a.z >> above)};
    NodeContent c;
    if (!layout_.contains(k)) return c;  // outside the volume: nothing
    // The stored node's range covers its cells up to the forward neighbours; an amplified
    // brick also reads the backward half-cell and its border, so the backward neighbours
    // count too. The detail still to come (down to max_depth for a stored node) widens it.
    float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
    for (int n = 0; n < 8; ++n) {
      const BrickKey b{k.level, k.x - ((n & 1) && k.x > 0), k.y - ((n & 2) && k.y > 0), k.z - ((n & 4) && k.z > 0)};
      const RenderContext::ValueSpan& r = ctx_.range_below(b);
      lo = std::min(lo, r.lo), hi = std::max(hi, r.hi);
    }
    const double detail = producer_->detail_bound(a.depth > s ? a.depth : max_depth());
    c.lo = float(lo - detail), c.hi = float(hi + detail);
    const NodeRecord& n = ctx_.nodes().at(k);
    const RenderContext::ValueSpan& below = ctx_.range_below(k);
    if (!ctx_.scene().value_range_visible(c.lo, c.hi)) c.value = std::numeric_limits<float>::quiet_NaN();
    else if (a.depth <= s && n.is_constant() && below.lo == below.hi && detail == 0) c.value = n.constant;
    else c.kind = NodeContent::brick;
    return c;
  }
  Fill fill(const NodeAddress& a, float* out, bool wait, float priority) override {
    if (a.depth > layout_.finest()) {
      std::lock_guard lock(coarse_mutex_);
      producer_->produce(a, out);
      ++produced_;
      return Fill::filled;
    }
    const NodeRecord& n = ctx_.nodes().at(store_key(a));
    if (n.is_constant()) {  // a constant stored node with detail below it
      const size_t e = size_t(layout_.brick_size + 2);
      std::fill_n(out, e * e * e, n.constant);
      return Fill::filled;
    }
    return stored_.fill(a, out, wait, priority);
  }
  uint64_t produced() const override { return produced_; }
  uint64_t loaded() const override { return stored_.loaded(); }
  void set_request_budget(uint32_t requests) override { stored_.set_request_budget(requests); }

 private:
  const RenderContext& ctx_;
  const GridLayout& layout_;
  StoreSource<Stored> stored_;
  RayCounters coarse_counters_;
  std::mutex coarse_mutex_;
  TrilinearSampler<Stored, double> coarse_;
  std::unique_ptr<gigavoxels::AmplifiedProducer> producer_;
  uint64_t produced_ = 0;
};

class ProducerSource final : public Source {
 public:
  ProducerSource(std::unique_ptr<gigavoxels::BrickProducer> p, bool instanced) : p_(std::move(p)), instanced_(instanced) {}
  int arity() const override { return p_->arity(); }
  int brick_size() const override { return p_->brick_size(); }
  int max_depth() const override { return p_->max_depth(); }
  NodeContent classify(const NodeAddress& a) const override { return p_->classify(a); }
  Fill fill(const NodeAddress& a, float* out, bool, float) override {
    p_->produce(a, out);
    ++produced_;
    return Fill::filled;
  }
  uint64_t produced() const override { return produced_; }
  uint64_t shared_id(const NodeAddress& a) const override { return instanced_ ? p_->brick_id(a) + 1 : 0; }

 private:
  std::unique_ptr<gigavoxels::BrickProducer> p_;
  bool instanced_;
  uint64_t produced_ = 0;
};

/// Voxel: the brick pool's type, the store's own for a store (a copy of its bricks, 1 byte
/// per voxel for 8-bit data: the samples are memory-bound) and float for produced bricks.
template <typename Voxel>
class GigaVoxelsRenderer final : public Renderer {
 public:
  GigaVoxelsRenderer(const RenderContext& ctx, const GigaVoxelsParams& p, std::unique_ptr<Source> source)
      : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), p_(p), shading_(scene_.shading, geo_), source_(std::move(source)),
        tree_(source_->arity(), node_blocks(ctx, p, *source_), brick_slots(ctx, p, *source_), source_->brick_size()),
        pool_(size_t(tree_.brick_capacity()) * tree_.brick_values()) {
    lod_ratio_ = p.lod_ratio > 0 ? p.lod_ratio : scene_.quality.lod_ratio;
    n_ = source_->arity();
    inv_log2_arity_ = 1.0 / std::log2(double(n_));
    m_ = source_->brick_size();
    inv_m_ = 1.0 / double(m_);
    groups_ = groups_per_axis(m_);
    group_count_ = group_count(m_);
    group_distances_.assign(size_t(tree_.brick_capacity()) * group_count_, 0);
    // The tree's unit cube: for a store, the root brick's extent in finest voxel-edge
    // coordinates (its levels halve up to one brick; voxel i's cell starts at i - 0.5); for the
    // sponge, the volume's box (voxel centres 0 to dims - 1).
    const GridLayout& layout = ctx.layout();
    if (p.source != 1)  // the amplified store's levels past the finest stored one halve its voxels
      for (int d = 0; d <= source_->max_depth(); ++d)
        level_dims_.push_back(d <= layout.finest() ? layout.level_dims(d) : layout.dims * (int64_t(1) << (d - layout.finest())));
    if (p.source == 1) {
      if (geo_.dims.y != geo_.dims.x || geo_.dims.z != geo_.dims.x || geo_.dims.x < 2)
        throw Error(Errc::unsupported, "gigavoxels source=menger needs a cubic volume of at least 2 voxels per axis (its box is the sponge)")
            .with_file(ctx.dataset().name);
      extent_ = double(geo_.dims.x - 1), unit_offset_ = 0;
    } else {
      extent_ = double(layout.brick_size) * double(int64_t(1) << layout.finest()), unit_offset_ = 0.5;
    }
    scales_ = node_scales(n_, source_->max_depth() + 1);
    for (const Scale& sc : scales_) inv_scales_.push_back(1.0 / sc.hi);
    if (p.source == 1) outside_value_ = 0.0f;
    if (scene_.mode == RenderMode::dvr) preintegrated_ = gigavoxels::PreintegratedTf(scene_.transfer_function);
    step_ = base_step(scene_, p);
    search_halvings_ = search_halvings(scene_, p);
    search_hidden_crossings_ = keeps_differences(ctx, p);
    if (search_hidden_crossings_) brick_differences_.assign(size_t(tree_.brick_capacity()), BrickDifferences{});
    finest_voxel_unit_ = 1.0 / extent_;  // one finest voxel in unit coordinates (opacity reference)
    unit_gradient_to_world_ = Vec3d(1.0) / (geo_.spacing * extent_);
    tree_.set_root(root_node(), NodeAddress{});
    if (p.source != 1 && ctx.bricks().shape().apron < 1)  // the sponge reads no stored brick
      throw Error(Errc::unsupported, "gigavoxels copies bricks with a 1-voxel border: the store needs an apron of at least 1")
          .with_file(ctx.dataset().name);
  }

  void begin_frame(const FrameSetup& setup) override {
    ++frame_;
    passes_ = 0;
    interrupted_ = 0;
    frame_subdivisions_ = frame_uploads_ = 0;
    frame_requests_ = frame_uses_ = 0;
    produced_before_ = source_->produced(), loaded_before_ = source_->loaded();
    failed_before_ = tree_.counters().failed_allocations;
    compaction_ = {};
    loader_seconds_ = 0;
    samples_in_runs_ = 0;
    leaps_chained_ = 0;
    tree_.begin_feedback(frame_);
    if (!uses_ || uses_->width() != setup.width || uses_->height() != setup.height)
      uses_ = std::make_unique<gigavoxels::UseBuffer>(setup.width, setup.height, p_.slots_per_pixel);
    uses_->begin_frame(frame_);
    states_.assign(size_t(setup.width) * size_t(setup.height), RayState{});
    frame_exact_ = p_.exact || complete_frames_;
    allow_interrupt_ = frame_exact_;
    const double pixel_angle = 2 * std::tan(setup.camera.fov_degrees * kPi / 360.0) / double(setup.height);
    footprint_per_t_ = pixel_angle / geo_.voxel_size / extent_ * lod_ratio_;
  }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    Tracer t(*this, setup, counters);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) {
        RayState& s = states_[size_t(y) * size_t(setup.width) + size_t(x)];
        if (s.status == RayState::done) continue;
        t.pixel(x, y, s, out);
      }
    samples_in_runs_.fetch_add(t.samples_in_runs, std::memory_order_relaxed);
    leaps_chained_.fetch_add(t.leaps_chained, std::memory_order_relaxed);
  }

  void end_frame(const FrameSetup& setup, const FrameBuffers& out) override {
    (void)setup, (void)out;
    ++passes_;
    Stopwatch watch;
    serve_feedback();
    loader_seconds_ += watch.seconds();
  }

  bool another_pass() override {
    if (!frame_exact_) return false;
    interrupted_ = 0;
    for (const RayState& s : states_) interrupted_ += s.status == RayState::interrupted;
    if (interrupted_ == 0) return false;
    // A pass that served nothing cannot make progress: the rest of the frame takes coarser data.
    if (last_pass_progress_ == 0 || passes_ >= uint64_t(p_.max_passes)) allow_interrupt_ = false;
    uses_->begin_frame(frame_);
    tree_.begin_feedback(frame_);
    return true;
  }

  void add_statistics(FrameStats& stats) const override {
    stats.add_phase("loader", loader_seconds_);
    stats.backend = {{"passes", double(passes_)},
                     {"subdivisions", double(frame_subdivisions_)},
                     {"uploads", double(frame_uploads_)},
                     {"bricks_produced", double(source_->produced() - produced_before_)},
                     {"bricks_loaded", double(source_->loaded() - loaded_before_)},
                     {"feedback_uses", double(frame_uses_)},
                     {"feedback_requests", double(frame_requests_)},
                     {"compaction_slots", double(compaction_.uses.slots + compaction_.requests.slots)},
                     {"compaction_removed_duplicates", double(compaction_.uses.local_duplicates + compaction_.requests.local_duplicates)},
                     {"compaction_removed_empty", double(compaction_.uses.empty + compaction_.requests.empty)},
                     {"node_blocks_in_use", double(tree_.blocks_in_use())},
                     {"node_blocks", double(tree_.block_capacity())},
                     {"bricks_in_use", double(tree_.bricks_in_use())},
                     {"brick_slots", double(tree_.brick_capacity())},
                     {"brick_pool_bytes", double(uint64_t(tree_.brick_capacity()) * slot_bytes(m_, !brick_differences_.empty()))},
                     {"bricks_used", double(tree_.bricks_used_this_frame())},
                     {"samples_in_runs", double(samples_in_runs_.load(std::memory_order_relaxed))},
                     {"leaps_chained", double(leaps_chained_.load(std::memory_order_relaxed))},
                     {"failed_allocations", double(tree_.counters().failed_allocations - failed_before_)},
                     {"loader_ms", loader_seconds_ * 1e3}};
  }

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
  const Voxel* brick(uint32_t slot) const { return pool_.data() + size_t(slot) * tree_.brick_values(); }
  const uint8_t* group_distances(uint32_t slot) const { return group_distances_.data() + size_t(slot) * group_count_; }
  const BrickDifferences& brick_differences_of(uint32_t slot) const {
    assert(slot < brick_differences_.size());  // kept only where keeps_differences()
    return brick_differences_[slot];
  }

 private:
  /// The brick pool: what the L1 budget holds once the cache's L1 has the slots the loader
  /// stages its copies through (l1_staging_slots), with each slot's bounds.
  static uint32_t brick_slots(const RenderContext& ctx, const GigaVoxelsParams& p, const Source& s) {
    if (p.brick_slots) return p.brick_slots;
    return uint32_t(std::clamp<uint64_t>(ctx.backend_pool_bytes() / slot_bytes(s.brick_size(), keeps_differences(ctx, p)), 8, 1u << 20));
  }
  static uint64_t slot_bytes(int m, bool with_differences) {
    const uint64_t e = uint64_t(m + 2);
    return e * e * e * sizeof(Voxel) + group_count(m) + (with_differences ? sizeof(BrickDifferences) : 0);
  }
  /// Whether bricks keep their differences: only iso's search for hidden crossings reads them,
  /// where it halves a step at least once (search_hidden_crossings_).
  static bool keeps_differences(const RenderContext& ctx, const GigaVoxelsParams& p) {
    return ctx.scene().mode == RenderMode::iso && search_halvings(ctx.scene(), p) > 0;
  }
  /// The base step, in voxels of the level sampled.
  static double base_step(const Scene& scene, const GigaVoxelsParams& p) {
    return p.step * (scene.mode == RenderMode::iso ? scene.quality.step_factor : scene.quality.step_factor / scene.sampling_rate);
  }
  /// Halvings of a step down to parts of 2^-hidden_crossings voxels whatever the step, so that a
  /// coarser step costs fewer samples, not thinner features missed (0: none).
  static int search_halvings(const Scene& scene, const GigaVoxelsParams& p) {
    return p.hidden_crossings > 0 ? p.hidden_crossings + int(std::ceil(std::log2(base_step(scene, p)) - 1e-9)) : 0;
  }
  /// Cell groups per axis: the cells start at sample coordinates 0 .. M (M + 1 of them, the
  /// border included), kCellGroup to a group.
  static int groups_per_axis(int m) { return m / kCellGroup + 1; }
  static size_t group_count(int m) {
    const size_t g = size_t(groups_per_axis(m));
    return g * g * g;
  }

  /// What rays may assume about a freshly written brick: its group distances (a group shows
  /// something when the range of its voxels, the corners of its cells up to the brick's last
  /// voxel, does) and its differences (BrickDifferences), which bound its field along a ray.
  void set_brick_bounds(uint32_t slot) {
    const Voxel* v = brick(slot);
    uint8_t* distance = group_distances_.data() + size_t(slot) * group_count_;
    const int e = m_ + 2;
    for (int gz = 0, i = 0; gz < groups_; ++gz)
      for (int gy = 0; gy < groups_; ++gy)
        for (int gx = 0; gx < groups_; ++gx, ++i) {
          float lo = std::numeric_limits<float>::infinity(), hi = -lo;
          for (int z = gz * kCellGroup; z <= std::min((gz + 1) * kCellGroup, e - 1); ++z)
            for (int y = gy * kCellGroup; y <= std::min((gy + 1) * kCellGroup, e - 1); ++y) {
              const Voxel* row = v + (size_t(z) * size_t(e) + size_t(y)) * size_t(e);
              for (int x = gx * kCellGroup; x <= std::min((gx + 1) * kCellGroup, e - 1); ++x)
                lo = std::min(lo, float(row[x])), hi = std::max(hi, float(row[x]));
            }
          // A NaN voxel (never stored: the importers refuse it) is passed over by min and max; a group
          // of NaN alone compares false: kept visible.
          distance[i] = !(lo <= hi) || scene_.value_range_visible(lo, hi) ? 0 : 1;
        }
    gigavoxels::chessboard_distances(groups_, distance);
    if (search_hidden_crossings_)  // only the search reads them
      brick_differences_[slot] = gigavoxels::brick_differences(v, size_t(e));
  }
  static uint32_t node_blocks(const RenderContext& ctx, const GigaVoxelsParams& p, const Source& s) {
    return p.node_blocks ? p.node_blocks : 2 * brick_slots(ctx, p, s) + 16;
  }

  /// N^depth for every depth up to max_depth, each as an unevaluated sum hi + lo of two
  /// doubles: exact while N^depth < 2^106 (the integer fits 64 bits up to 3^40 and 2^63).
  struct Scale {
    double hi = 1, lo = 0;
  };
  static std::vector<Scale> node_scales(int n, int max_depth) {
    std::vector<Scale> scales(size_t(max_depth) + 1);
    uint64_t v = 1;
    for (size_t d = 0; d < scales.size(); ++d) {
      Scale& s = scales[d];
      s.hi = double(v);  // below 2^64, so it converts back
      const uint64_t h = uint64_t(s.hi);
      s.lo = h <= v ? double(v - h) : -double(h - v);
      if (d + 1 < scales.size() && v > std::numeric_limits<uint64_t>::max() / uint64_t(n))
        throw Error(Errc::unsupported, fmt::format("gigavoxels: {}^depth overflows 64 bits before the source's max depth {}", n, max_depth));
      v *= uint64_t(n);
    }
    return scales;
  }

  Node node_for(const NodeContent& c, int depth) const {
    if (c.kind == NodeContent::constant) return Node::make_constant(c.value);
    return Node::make_data(depth >= source_->max_depth());
  }
  Node root_node() const { return node_for(source_->classify(NodeAddress{}), 0); }

  // --- the loader ---------------------------------------------------------------------------
  /// Writes a brick for the node if its data is available (or shared and resident already).
  Source::Fill upload(uint32_t address, bool wait) {
    const NodeAddress a = tree_.address_of(address);
    if (const uint64_t id = source_->shared_id(a)) {
      auto it = shared_.find(id);
      if (it != shared_.end()) {
        Node n = tree_.node(address);
        n.set_brick(it->second);
        tree_.set_node(address, n);
        return Source::Fill::filled;
      }
    }
    if (address != 0 && !tree_.brick_slot_available()) return Source::Fill::missing;  // the root's slot is always there
    scratch_.resize(tree_.brick_values());
    const Source::Fill filled = source_->fill(a, scratch_.data(), wait, float(a.depth));
    if (filled != Source::Fill::filled) return filled;
    const uint32_t slot = tree_.allocate_brick(address);
    if (slot == gigavoxels::kNoAddress) return Source::Fill::missing;
    std::transform(scratch_.begin(), scratch_.end(), pool_.begin() + std::ptrdiff_t(size_t(slot) * tree_.brick_values()),
                   [](float v) { return Voxel(v); });  // exact: the values came from Voxel (or are float)
    set_brick_bounds(slot);
    if (const uint64_t id = source_->shared_id(a)) {
      tree_.keep_brick(slot);
      shared_[id] = slot;
    }
    ++frame_uploads_;
    return Source::Fill::filled;
  }

  void serve_feedback() {
    const gigavoxels::CompactionReport report = compactor_.compact(*uses_, used_list_, request_list_);
    compaction_ += report;
    frame_uses_ += used_list_.size();
    frame_requests_ += request_list_.size();
    last_pass_requests_ = request_list_.size();
    for (uint32_t e : used_list_) tree_.mark_used(e & kAddressMask);
    for (uint32_t e : request_list_) tree_.mark_used(e & kAddressMask);
    const bool wait = allow_interrupt_;
    // The bricks asked for in earlier passes stay the loader's while their node is in the tree
    // without one, and count as used, so that no subdivision takes their block once they are
    // copied. A blocking pass (exact mode) forgets them: it fetches what its rays ask for.
    if (wait) in_transit_.clear();
    std::erase_if(in_transit_, [&](const InTransit& b) {
      const Node n = tree_.node(b.address);
      return !tree_.holds(b.address, b.node) || n.has_brick() || n.constant() || frame_ - b.since > kTransitFrames;
    });
    for (const InTransit& b : in_transit_) tree_.mark_used(b.address);
    tree_.end_of_feedback();
    source_->set_request_budget(uint32_t(p_.upload_budget));
    int subdivisions = 0, uploads = 0;
    last_pass_progress_ = 0;
    transit_addresses_.clear();
    for (const InTransit& b : in_transit_) transit_addresses_.insert(b.address);
    // Uploads a node's brick if it is at hand; one asked for becomes the loader's until it
    // arrives (once: the compacted lists may name a node more than once).
    const auto serve = [&](uint32_t address) {
      const Source::Fill f = upload(address, wait);
      if (f == Source::Fill::filled) ++uploads, ++last_pass_progress_;
      if (f == Source::Fill::requested && transit_addresses_.insert(address).second)
        in_transit_.push_back({address, tree_.address_of(address), frame_});
      return f;
    };
    // First the loader's: copied once arrived, asked for again until then while the budget
    // allows (the cache drops a request not renewed; a later pass asks again), dropped when
    // they cannot be read.
    std::vector<InTransit> transit;
    transit.swap(in_transit_);
    int loading = 0;  // asked for again this pass: on its way
    for (const InTransit& b : transit) {
      const Source::Fill f = uploads < p_.upload_budget ? serve(b.address) : Source::Fill::missing;
      if (f == Source::Fill::requested || f == Source::Fill::missing) in_transit_.push_back(b);
      loading += f == Source::Fill::requested;
    }
    // Then the bricks the rays asked for, then subdivisions: a subdivision also asks for its
    // children's bricks before any ray needs them, which only the budget the rays left may pay.
    for (uint32_t e : request_list_) {
      const uint32_t address = e & kAddressMask;
      const Node n = tree_.node(address);
      if (!(e & kWantsBrick) || n.has_brick() || n.constant() || transit_addresses_.contains(address)) continue;
      if (uploads >= p_.upload_budget) break;
      loading += serve(address) == Source::Fill::requested;
    }
    for (uint32_t e : request_list_) {
      const uint32_t address = e & kAddressMask;
      const Node n = tree_.node(address);
      if (!(e & kWantsSubdivision) || n.has_children() || n.max_refined() || n.constant()) continue;
      if (subdivisions >= p_.subdivide_budget) break;
      const uint32_t base = tree_.subdivide(address);
      if (base == gigavoxels::kNoAddress) continue;
      ++subdivisions, ++frame_subdivisions_, ++last_pass_progress_;
      for (int i = 0; i < tree_.block_nodes(); ++i) {
        const NodeAddress a = tree_.address_of(base + uint32_t(i));
        tree_.set_node(base + uint32_t(i), node_for(source_->classify(a), a.depth));
      }
      // The children's bricks come with the subdivision when the data is at hand; the rest
      // are requested now and copied when they arrive.
      for (int i = 0; i < tree_.block_nodes() && uploads < p_.upload_budget; ++i) {
        const uint32_t child = base + uint32_t(i);
        if (!tree_.node(child).constant()) loading += serve(child) == Source::Fill::requested;
      }
    }
    // A load asked for is not a stall: it arrives in a later frame. Unless nothing has for
    // kTransitFrames (a brick that never becomes resident must not keep the frame unconverged).
    if (passes_ == 1) {
      frames_loading_ = last_pass_progress_ > 0 || loading == 0 ? 0 : frames_loading_ + 1;
      const bool progress = last_pass_progress_ > 0 || (loading > 0 && frames_loading_ <= int(kTransitFrames));
      stalled_frames_ = progress || request_list_.empty() ? 0 : stalled_frames_ + 1;
    }
  }

  // --- rays ----------------------------------------------------------------------------------
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

  /// A node as the ray sees it, in the node's own coordinates ([0, 1]^3 across the node): the
  /// eye there and the ray's direction per unit t there. Deep zoom needs these: an absolute
  /// unit-cube position has 53 bits, which is one voxel at depth 30 for N = 3, while the eye
  /// relative to a node is computed exactly (see local_eye) and is small wherever the
  /// footprint asks for that node's depth, so a sample is accurate to the last bit of
  /// *relative* position at any depth the tree reaches.
  struct NodeFrame {
    double eye[3] = {};
    double dir[3] = {};
    double inv_dir[3] = {};  // 1 / dir (infinite along an axis the ray is parallel to)
  };

  struct PathNode;
  /// The ray's bricks of the last levels met in the descent, coarsest first: nodes of its
  /// path, stable until the next descent.
  struct Levels {
    const PathNode* b[3] = {};
    int count = 0;
    void push(const PathNode& l) {
      if (count == 3) b[0] = b[1], b[1] = b[2], count = 2;
      b[count++] = &l;
    }
  };

  /// A node of a ray's descent, and its brick as a sample sees it.
  struct PathNode {
    uint32_t address = 0;
    Node node;
    int64_t c[3] = {};  // the node's integer coordinates at its depth
    int depth = 0;
    double scale = 1;  // N^depth, rounded (voxel sizes and gradients only)
    NodeFrame frame;
    const Voxel* brick = nullptr;              // null: no brick
    const uint8_t* group_distances = nullptr;  // per cell group (cell_groups.h)
    const BrickDifferences* differences = nullptr;  // set_brick_bounds
    Levels levels;  // the last 3 bricks down to and including this node's
    bool contains(double t) const {
      for (int a = 0; a < 3; ++a) {
        const double u = frame.eye[a] + frame.dir[a] * t;
        if (!(u >= 0 && u <= 1)) return false;
      }
      return true;
    }
  };

  struct Tracer {
    const GigaVoxelsRenderer& r;
    const FrameSetup& setup;
    const ImageRays rays;
    RayCounters& counters;
    const bool gradients;
    // DVR under a headlight or a directional light: the direction to the light and the half
    // vector are the same at every sample of a ray (past its origin), computed once per ray.
    const bool light_fixed;
    // DVR at one level takes runs of samples side by side (sample_run): with analytic normals
    // (or none), lit by a light fixed along rays (or unlit).
    const bool runs;
    Vec3d ray_light{0.0}, ray_half{0.0};
    uint64_t samples_in_runs = 0;  // of counters.samples
    uint64_t leaps_chained = 0;    // chain_leaps' leaps, each two samples fewer

    Tracer(const GigaVoxelsRenderer& renderer, const FrameSetup& s, RayCounters& c)
        : r(renderer), setup(s), rays(s.camera, s.width, s.height), counters(c), gradients(r.ctx_.needs_gradients(s.outputs)),
          light_fixed(r.scene_.mode == RenderMode::dvr && r.shading_.lit() && r.shading_.light_fixed_along_rays()),
          runs(r.p_.sample_runs && r.scene_.mode == RenderMode::dvr && (!gradients || r.scene_.shading.normals == NormalMethod::analytic) &&
               (!gradients || !r.shading_.lit() || light_fixed)),
          path(size_t(r.source_->max_depth()) + 1), scaled_eye(size_t(r.source_->max_depth()) + 1) {}

    /// The cell of brick b at brick coordinates l (voxel i + 1 at i; clamped into the brick):
    /// its corner values c, where in it l lies (u), and its lower corner.
    void brick_cell(const PathNode& b, const Vec3f& l, int64_t cell[3], float u[3], float c[8]) const {
      const int64_t e = r.m_ + 2;
      const float top = float(e - 1);
      for (int a = 0; a < 3; ++a) {
        const float x = l[a] > 0 ? std::min(l[a], top) : 0.0f;  // NaN: 0 (std::clamp keeps it)
        cell[a] = std::min<int64_t>(int64_t(x), e - 2);
        u[a] = x - float(cell[a]);
      }
      const Voxel* q = cell_voxels(b, cell);
      const int64_t dy = e, dz = e * e;
      c[0] = float(q[0]), c[1] = float(q[1]), c[2] = float(q[dy]), c[3] = float(q[dy + 1]);
      c[4] = float(q[dz]), c[5] = float(q[dz + 1]), c[6] = float(q[dz + dy]), c[7] = float(q[dz + dy + 1]);
    }
    /// The trilinear value of brick b at brick coordinates l.
    float brick_value(const PathNode& b, const Vec3f& l) const {
      int64_t cell[3];
      float u[3], c[8];
      brick_cell(b, l, cell, u, c);
      return trilinear(c, u[0], u[1], u[2]);
    }
    /// The lower corner voxel of a cell of brick b.
    const Voxel* cell_voxels(const PathNode& b, const int64_t cell[3]) const {
      const int64_t e = r.m_ + 2;
      return b.brick + (cell[2] * e + cell[1]) * e + cell[0];
    }
    /// DVR at one level: how many sample positions ahead a ray asks for their cells (8 gained
    /// nothing over 3).
    static constexpr int kPrefetchAhead = 3;
    /// Asks for the cache lines holding the first voxel of each of the four rows of the cell
    /// of brick b at brick coordinates l, ahead of a sample there, so that loading them
    /// overlaps the samples before it. A hint only: nothing read changes.
    void prefetch_cell(const PathNode& b, const double l[3]) const {
      const int e = r.m_ + 2;
      int64_t cell[3];
      for (int a = 0; a < 3; ++a) cell[a] = child_index(l[a], e - 1);  // as brick_cell clamps (NaN: 0)
      const Voxel* q = cell_voxels(b, cell);
      for (const Voxel* row : {q, q + e, q + e * e, q + e * e + e}) {
#if defined(__x86_64__) || defined(__i386__)
        // GCC 12 (-O3 -march=x86-64-v3) emitted no prefetch instruction for __builtin_prefetch
        // here (objdump of the object); an asm volatile statement cannot be removed. prefetcht0
        // never faults, and the "m" operand only supplies the address.
        asm volatile("prefetcht0 %0" : : "m"(*row));
#else
        __builtin_prefetch(row);
#endif
      }
    }
    /// DVR at one level: from what base step on (`step`, in voxels) a ray asks for the cells of
    /// a node's first samples as it enters it (prefetch_entry_samples).
    static constexpr double kEntryPrefetchStep = 2;
    /// How many sample positions from a node's entry that asks for, the exit sample's included.
    static constexpr int kEntryPrefetches = 5;
    /// Asks for the cells of the first kEntryPrefetches sample positions from t, one step dt
    /// apart (the step as it is at the entry: an adaptive step that grows on moves the later
    /// ones), the exit sample at t_face standing in for those at or past t_end. Each would
    /// otherwise wait for its rows only when reached; at a step of 2 voxels they are about half
    /// of the samples along a brick's mean chord (21 voxels at M = 32), from step 4 most or all.
    /// Measured on a lit 512x512 DVR frame of fBm 1024^3 u16: 3% less time at step 4, 8% at
    /// step 16; at step 1, where the 5 positions span 4 voxels and share their cache lines with
    /// what the first sample run reads at once, 1-2% more, so it is off there. A hint only:
    /// nothing read changes.
    void prefetch_entry_samples(const PathNode& b, double t, double dt, double t_end, double t_face) const {
      for (int k = 0; k < kEntryPrefetches; ++k) {
        double tk = t + k * dt;
        const bool at_exit = !(tk < t_end);
        if (at_exit) tk = t_face;
        double l[3];
        brick_coordinates(b, tk, l);
        prefetch_cell(b, l);
        if (at_exit) break;
      }
    }
    /// Trilinear value (and gradient per unit coordinate) of a brick at ray parameter t, and
    /// where in the brick's cells t fell (at).
    float sample_brick(const PathNode& b, double t, Vec3d* gradient, CellPoint* at = nullptr) const {
      double l[3];
      brick_coordinates(b, t, l);
      return sample_brick_at(b, l, gradient, at);
    }
    /// Where t lies in brick b, in brick coordinates (voxel i + 1 at i: the border voxel at 0).
    void brick_coordinates(const PathNode& b, double t, double l[3]) const {
      for (int a = 0; a < 3; ++a) l[a] = (b.frame.eye[a] + b.frame.dir[a] * t) * double(r.m_) + 0.5;
    }
    /// sample_brick at brick coordinates l (brick_coordinates), read in float.
    float sample_brick_at(const PathNode& b, const double l_at[3], Vec3d* gradient, CellPoint* at) const {
      const Vec3f l{float(l_at[0]), float(l_at[1]), float(l_at[2])};
      int64_t cell[3];
      float u[3], c[8];
      brick_cell(b, l, cell, u, c);
      if (at)
        for (int a = 0; a < 3; ++a) at->cell[a] = int32_t(cell[a]), at->u[a] = u[a];
      if (!gradient) return trilinear(c, u[0], u[1], u[2]);
      Vec3f g;
      float v;
      if (r.scene_.shading.normals == NormalMethod::analytic) {
        v = trilinear_with_gradient(c, u[0], u[1], u[2], g);
      } else {
        v = trilinear(c, u[0], u[1], u[2]);
        const Vec3f within{float(cell[0]) + u[0], float(cell[1]) + u[1], float(cell[2]) + u[2]};
        g = difference_gradient(b, within, v, r.scene_.shading.normals == NormalMethod::central);
      }
      *gradient = Vec3d(g) * (b.scale * double(r.m_));
      return v;
    }
    /// The gradient (brick voxels) at brick coordinates l, where the value is v, by central or
    /// forward differences one voxel apart, as the reference and raymarch take them: within
    /// the store brick that holds the cell at l, one-sided at its faces (forward turning
    /// backward at its upper face) and at the volume's. A node's brick starts half a voxel
    /// below its store brick's first voxel, and its 1-voxel border holds one voxel of the
    /// store brick below: in that half voxel, the lower difference reaches that voxel rather
    /// than one further down (the only place the two differ). For the sponge, within the
    /// node's brick. Samples count the values read besides v (raymarch counts 4 or 6 a gradient).
    Vec3f difference_gradient(const PathNode& b, const Vec3f& l, float v, bool central) const {
      const int m = r.m_;
      float lo[3], hi[3];  // where the differences may reach, in brick coordinates
      for (int a = 0; a < 3; ++a) {
        if (size_t(b.depth) < r.level_dims_.size()) {
          // The store brick holding the cell of l's voxel position p (clamped into the volume).
          const int64_t dims = r.level_dims_[size_t(b.depth)][a], base = b.c[a] * m - 1;  // p = base + l
          const double p = double(base) + double(l[a]);
          const int64_t cell = std::clamp<int64_t>(int64_t(std::max(p, 0.0)), 0, std::max<int64_t>(0, dims - 2));
          const int64_t brick_lo = cell / m * m, brick_hi = std::min(brick_lo + m, dims - 1);
          lo[a] = float(std::max<int64_t>(brick_lo - base, 0));
          hi[a] = float(std::min<int64_t>(brick_hi - base, m + 1));
        } else {
          lo[a] = l[a] >= 1 ? 1.0f : 0.0f;
          hi[a] = l[a] >= 1 ? float(m + 1) : 1.0f;
        }
      }
      return confined_difference_gradient(l, lo, hi, central, v, [&](const Vec3f& q) {
        ++counters.samples;
        return brick_value(b, q);
      });
    }

    /// The bricks a sample at depth lambda reads: one, or (quadrilinear) the two levels around
    /// lambda among those collected, blended with weight w on the finer.
    struct Blend {
      const PathNode* coarse = nullptr;  // null: `finer` alone
      const PathNode* finer = nullptr;
      double w = 1;
    };
    Blend blend(const Levels& lv, double lambda) const {
      const PathNode& fine = *lv.b[lv.count - 1];
      if (!r.p_.quadrilinear || lv.count == 1 || lambda >= fine.depth) return {nullptr, &fine, 1};
      int i = lv.count - 1;
      while (i > 0 && lv.b[i - 1]->depth > lambda) --i;  // b[i] finer than lambda, b[i-1] coarser
      if (i == 0) return {nullptr, lv.b[0], 1};
      const PathNode& coarse = *lv.b[i - 1];
      const PathNode& finer = *lv.b[i];
      return {&coarse, &finer, std::clamp((lambda - coarse.depth) / double(finer.depth - coarse.depth), 0.0, 1.0)};
    }

    /// Quadrilinear: the two levels around the footprint's depth lambda, among those collected.
    float sample(const Levels& lv, double lambda, double t, Vec3d* gradient) const { return sample(blend(lv, lambda), t, gradient); }
    /// at: where t fell among the finer brick's cells.
    float sample(const Blend& bl, double t, Vec3d* gradient, CellPoint* at = nullptr) const {
      if (!bl.coarse) return sample_brick(*bl.finer, t, gradient, at);
      Vec3d gc(0.0), gf(0.0);
      const float vc = sample_brick(*bl.coarse, t, gradient ? &gc : nullptr);
      const float vf = sample_brick(*bl.finer, t, gradient ? &gf : nullptr, at);
      if (gradient) *gradient = gc * (1 - bl.w) + gf * bl.w;
      return float(vc * (1 - bl.w) + vf * bl.w);
    }

    /// Whether the cell group of brick b at t is clear (holds nothing visible); where the ray
    /// leaves it, or when clear, the cube of clear groups around it; and, when clear, one of its
    /// voxels (every value in the cube is on that voxel's side of every isovalue).
    bool clear_group(const PathNode& b, double t, double& t_leave, float& voxel) const {
      int g[3];
      const int i = group_at(b, t, g);
      t_leave = cube_crossing(b, g, b.group_distances[i], true);
      if (b.group_distances[i] == 0) return false;
      voxel = group_voxel(b, g);
      return true;
    }
    /// A voxel of cell group g of brick b (its lowest corner). In a clear group, every value of
    /// the group, and of each clear group touching it (touching groups share their boundary
    /// voxels), lies in this voxel's interval of hidden values (or on its side of every isovalue).
    float group_voxel(const PathNode& b, const int g[3]) const {
      const size_t e = size_t(r.m_) + 2;
      return float(b.brick[(size_t(g[2]) * kCellGroup * e + size_t(g[1]) * kCellGroup) * e + size_t(g[0]) * kCellGroup]);
    }
    /// DVR: whether every value between two clear groups' voxels is hidden, so that all values
    /// of both groups lie in one interval the transfer function hides.
    bool same_hidden_interval(float a, float b) const { return !r.scene_.value_range_visible(std::min(a, b), std::max(a, b)); }
    /// How many steps dt a leap from t takes to the first sample position past where the clear
    /// groups end (t_leave) or the node does (t_face): 1 or less is a plain step.
    static double leap_steps(double t, double t_leave, double t_face, double dt) {
      return std::ceil((std::max(std::min(t_leave, t_face), t) - t) / dt);
    }

    /// Where a DVR leap goes on at one level. A leap that ends at t_next (its last position
    /// t_next - dt, in the clear groups it leapt) takes a sample there, then leaps again if t_next
    /// lies in clear groups. When the values at both ends lie in one interval the transfer
    /// function hides (their groups' voxels do: group_voxel), the pre-integrated segment between
    /// them is clear whatever they are, so the ray leaps on with no sample: while t_next's group
    /// is clear, in the interval of the group of the last position, and its clear groups reach
    /// 2 steps or more (a leap of one step is a plain step, which samples). Steps after the
    /// first leap are next_dt (the adaptive step as the sample before the first leap left it).
    /// The samples left out would have added only the pre-integration table's slight opacity
    /// next to a hidden range; the positions taken are those of leaping one leap at a time.
    /// Returns the last leap's end; dt becomes its step.
    double chain_leaps(const PathNode& b, double t_next, double& dt, double next_dt, double t_end, double t_face) {
      double t_leave;
      float voxel, next;
      while (t_next < t_end && clear_group(b, t_next - dt, t_leave, voxel) && clear_group(b, t_next, t_leave, next) &&
             !std::isnan(voxel) && !std::isnan(next) && (next == voxel || same_hidden_interval(voxel, next))) {
        const double steps = leap_steps(t_next, t_leave, t_face, next_dt);
        if (!(steps > 1)) break;
        t_next += steps * next_dt;
        dt = next_dt;
        ++leaps_chained;
      }
      return t_next;
    }

    /// The cell group of brick b at t: its index, and its coordinates in g.
    int group_at(const PathNode& b, double t, int g[3]) const {
      double l[3];
      brick_coordinates(b, t, l);
      return group_of(l, g);
    }
    /// The cell group holding brick coordinates l (clamped into the brick).
    int group_of(const double l[3], int g[3]) const {
      // The voxel clamped into the brick (NaN: 0), then its group by a shift (unsigned division
      // by the power of two). sample_run computes the same in lanes.
      for (int a = 0; a < 3; ++a) g[a] = int(unsigned(child_index(l[a], r.m_ + 2)) / unsigned(kCellGroup));
      return (g[2] * r.groups_ + g[1]) * r.groups_ + g[0];
    }
    /// Where the ray leaves (or enters) the cube of groups centred on group g that its distance
    /// says are clear (just g itself when the distance is 0 or 1).
    double cube_crossing(const PathNode& b, const int g[3], uint8_t distance, bool leaving) const {
      const int reach = std::max(int(distance) - 1, 0);  // clear groups on every side
      double t_cross = leaving ? kInf : -kInf;
      for (int a = 0; a < 3; ++a) {
        if (b.frame.dir[a] == 0) continue;
        const bool upper = (b.frame.dir[a] > 0) == leaving;  // the cube's face the ray crosses there
        const double face = double((upper ? g[a] + reach + 1 : g[a] - reach) * kCellGroup);
        const double ta = ((face - 0.5) * r.inv_m_ - b.frame.eye[a]) * b.frame.inv_dir[a];
        t_cross = leaving ? std::min(t_cross, ta) : std::max(t_cross, ta);
      }
      return t_cross;
    }
    /// Where the ray enters a node, in its frame (before the ray's start when it starts inside).
    static double node_entry(const NodeFrame& frame) {
      double t_entry = -kInf;
      for (int a = 0; a < 3; ++a)
        if (frame.dir[a] != 0) t_entry = std::max(t_entry, ((frame.dir[a] > 0 ? 0.0 : 1.0) - frame.eye[a]) * frame.inv_dir[a]);
      return t_entry;
    }
    /// Where the ray enters the cube of clear groups around t that clear_group leaps (t is in it).
    double clear_cube_entry(const PathNode& b, double t) const {
      int g[3];
      return cube_crossing(b, g, b.group_distances[group_at(b, t, g)], false);
    }

    /// clear_group for what a sample at lambda reads; t_leave is where the answer may change.
    /// Two blended levels are clear together when every blend of theirs is: iso, both clear on
    /// the same side of every isovalue; DVR, both in the same interval of values the transfer
    /// function hides (a clear group's values all lie in one such interval; when the interval
    /// between their voxels is hidden, both lie in the same one).
    bool clear(const Blend& bl, double t, bool iso, double& t_leave, float& voxel) const {
      const bool finer_clear = clear_group(*bl.finer, t, t_leave, voxel);
      if (!bl.coarse || !finer_clear) return finer_clear;
      double t_coarse;
      float coarse_voxel;
      const bool coarse_clear = clear_group(*bl.coarse, t, t_coarse, coarse_voxel);
      t_leave = std::min(t_leave, t_coarse);
      if (!coarse_clear) return false;
      return iso ? !crossing(coarse_voxel, voxel) : same_hidden_interval(coarse_voxel, voxel);
    }

    void pixel(int x, int y, RayState& s, FrameBuffers& out) {
      ++counters.rays;
      const PrimaryRay ray = primary_ray(rays, r.geo_, x, y);
      gigavoxels::RayRecorder rec = r.uses_->recorder(x, y);
      PixelResult px;
      px.color = r.scene_.background;
      if (ray.hits()) {
        if (s.status == RayState::fresh) {
          s.t = s.t_sample = ray.span.t0;
          // A procedural volume is empty outside its box: entering a solid region is a surface.
          if (r.outside_value_) s.start_segment(*r.outside_value_, s.t);
        }
        march(ray, s, rec, px);
      } else {
        s.status = RayState::done;
      }
      rec.finish();
      if (s.status == RayState::done) write_pixel(out, x, y, px);
    }

    /// A pixel's footprint at distance t, in unit coordinates, scaled by lod_ratio.
    double footprint(double t) const { return std::max(t, 1e-300) * r.footprint_per_t_; }
    /// The (fractional) depth whose voxels are as large as a footprint. Per sample wherever
    /// the footprint is coarser than the finest level met, so the log is inlined (log2_fast:
    /// the double log was a tenth of the amplified flight's time, frexp and a float log2 still
    /// 5% of an iso frame's).
    double depth_for(double footprint) const { return -log2_fast(double(r.m_) * footprint) * r.inv_log2_arity_; }

    /// The frame of node c at a depth. The eye's node coordinates e N^depth - c are computed
    /// exactly before one rounding: e times the double-double N^depth by an error-free product
    /// (fma), and the integer part subtracted in integers where doubles no longer hold c.
    NodeFrame node_frame(int depth, const int64_t c[3]) const {
      const ScaledEye& e = scaled_eye[size_t(depth)];
      NodeFrame f;
      if (e.small) {  // the common case, without a test per axis
        for (int a = 0; a < 3; ++a) f.eye[a] = (e.hi[a] - double(c[a])) + e.lo[a];
        aim(f, depth);
        return f;
      }
      for (int a = 0; a < 3; ++a) {
        const double hi = e.hi[a];
        double whole;
        if (std::abs(hi) < 0x1p53) whole = hi - double(c[a]);  // exact: both are multiples of ulp(hi)
        else if (std::abs(hi) < 0x1p62) whole = double(int64_t(hi) - c[a]);  // hi is an integer here
        else whole = hi - double(c[a]);  // an eye this far outside never descends this deep
        f.eye[a] = whole + e.lo[a];
      }
      aim(f, depth);
      return f;
    }
    /// clamp(floor(u), 0, n - 1) (NaN: 0), without floor: below n - 1 and above 0, truncation is it.
    static int64_t child_index(double u, int n) {
      if (u >= double(n - 1)) return n - 1;
      return u > 0 ? int64_t(u) : 0;
    }
    /// The eye times N^depth, hi + lo exactly (an error-free product by the double-double
    /// N^depth), for every depth. Every primary ray leaves the same eye, so a tile computes it
    /// once; node frames then only subtract their node's coordinates.
    struct ScaledEye {
      double hi[3] = {}, lo[3] = {};
      bool small = false;  // every |hi| < 2^53
    };
    void scale_eye() {
      if (eye[0] == scaled_eye_of[0] && eye[1] == scaled_eye_of[1] && eye[2] == scaled_eye_of[2]) return;
      for (size_t d = 0; d < scaled_eye.size(); ++d) {
        const Scale& s = r.scales_[d];
        for (int a = 0; a < 3; ++a) {
          const double hi = eye[a] * s.hi;
          scaled_eye[d].hi[a] = hi, scaled_eye[d].lo[a] = std::fma(eye[a], s.hi, -hi) + eye[a] * s.lo;
        }
        const double* hi = scaled_eye[d].hi;
        scaled_eye[d].small = std::abs(hi[0]) < 0x1p53 && std::abs(hi[1]) < 0x1p53 && std::abs(hi[2]) < 0x1p53;
      }
      std::copy_n(eye, 3, scaled_eye_of);
    }
    /// The ray's direction in the frame of a node at a depth.
    void aim(NodeFrame& f, int depth) const {
      const double s = r.scales_[size_t(depth)].hi, inv_s = r.inv_scales_[size_t(depth)];
      for (int a = 0; a < 3; ++a) f.dir[a] = dir[a] * s, f.inv_dir[a] = inv_dir[a] * inv_s;
    }

    /// A node the descent passes: its brick, if any, joins the levels collected.
    void enter(PathNode& q, Levels& lv) {
      ++counters.nodes;
      q.brick = nullptr;
      if (q.node.has_brick()) {
        q.brick = r.brick(q.node.brick()), q.group_distances = r.group_distances(q.node.brick());
        q.differences = r.search_hidden_crossings_ ? &r.brick_differences_of(q.node.brick()) : nullptr;
        lv.push(q);
      }
      q.levels = lv;
    }

    /// The rays of a tile leave one eye in nearby directions, so each starts from the last
    /// ray's descent: the nodes are this ray's too as far as they contain its start, and the
    /// eye's part of their frames does not depend on the direction, so only the direction's
    /// part is redone. Deep in a zoom, a descent from the root would be most of the tree.
    void aim_path_along_ray() {
      for (int d = 0; d < path_size; ++d) aim(path[size_t(d)].frame, d);
    }

    void march(const PrimaryRay& ray, RayState& s, gigavoxels::RayRecorder& rec, PixelResult& px) {
      const bool iso = r.scene_.mode == RenderMode::iso;
      for (int a = 0; a < 3; ++a) {
        eye[a] = (ray.org[a] + r.unit_offset_) / r.extent_, dir[a] = ray.dir[a] / r.extent_;
        inv_dir[a] = 1.0 / dir[a];
      }
      scale_eye();
      if (light_fixed) {
        double light_distance;
        ray_light = r.shading_.to_light_along(ray.world, 1.0, light_distance);  // the same at any t > 0
        ray_half = ShadingModel::half_vector(-ray.world.dir, ray_light);
      }
      const double unit_per_t = length(ray.dir) / r.extent_;  // unit-cube length per unit t
      const double stop = r.scene_.quality.termination_opacity;
      const int n = r.n_;
      // Descents and samples advance apart: a step may reach past the next node, which is still
      // entered (searched, its exit sampled), or a thin node would hide what is in it.
      double t_at = s.t, t = s.t_sample;
      double hit_t = kInf;
      bool requested = false;
      uint32_t prev_node = gigavoxels::kNoAddress;  // iso: whose brick s.prev_value was sampled from
      CachedBounds bounds;
      double clear_until = -kInf;  // iso: the clear groups the last leap passed end here
      int exit_axis = -1;
      aim_path_along_ray();
      while (t_at < ray.span.t1) {
        // DVR integrates between samples whatever lies between them: a node a step passes
        // whole adds nothing, so it descends where the next sample is; or, when that is past
        // the ray's exit, just before the exit, whose node closes the last part-step.
        if (!iso) {
          const bool close_at_exit = t >= ray.span.t1 && s.have_prev && s.prev_t < ray.span.t1;
          t_at = std::max(t_at, close_at_exit ? std::nextafter(ray.span.t1, -kInf) : t);
        }
        const double entry_fp = footprint(t_at);
        // kd-restart: the descent from the root to the node at t_at whose voxels match the
        // footprint. The nodes it passes through are the last descent's as far as they still
        // contain t_at (and are no coarser than the footprint asks), so it resumes from the
        // deepest of those; the path and the levels collected are the same as from the root.
        int restart = 0;
        for (int i = path_size - 1; i > 0; --i)
          if (path[i].contains(t_at)) {
            restart = i;
            break;
          }
        // The footprint grows along the ray: an ancestor may now be fine enough (the test is
        // monotone in depth, so the deepest says whether any does).
        if (restart > 0 && entry_fp * double(r.m_) * path[restart - 1].scale >= 1)
          for (int i = 0; i < restart; ++i)
            if (entry_fp * double(r.m_) * path[i].scale >= 1) {
              restart = i;
              break;
            }
        // The restart node was entered by an earlier descent (its brick and levels are set), or
        // this is the tile's first: the root.
        PathNode* p = &path[restart];
        Levels lv;
        if (path_size == 0) {
          p->address = 0;
          p->node = r.tree_.node(0);
          p->c[0] = p->c[1] = p->c[2] = 0;
          p->depth = 0;
          p->scale = 1;
          p->frame = node_frame(0, p->c);
          enter(*p, lv);
        } else {
          lv = p->levels;
        }
        int depth = restart;
        uint32_t want = 0;
        for (;;) {
          if (p->node.constant()) break;
          if (entry_fp * double(r.m_) * p->scale >= 1) break;  // its voxels cover at most lod_ratio pixels
          if (!p->node.has_children()) {
            if (!p->node.max_refined()) want = kWantsSubdivision;
            break;
          }
          PathNode& child = path[depth + 1];
          int index = 0, stride = 1;
          for (int a = 0; a < 3; ++a, stride *= n) {
            const int64_t ci = child_index((p->frame.eye[a] + p->frame.dir[a] * t_at) * n, n);
            child.c[a] = p->c[a] * n + ci;
            index += int(ci) * stride;
          }
          child.address = r.tree_.child_address(p->node, index);
          child.node = r.tree_.node(child.address);
          child.scale = p->scale * n;
          child.depth = ++depth;
          child.frame = node_frame(depth, child.c);
          p = &child;
          enter(*p, lv);
        }
        path_size = depth + 1;
        const uint32_t address = p->address;
        const Node node = p->node;
        const NodeFrame& frame = p->frame;
        const double scale = p->scale;
        if (!node.constant() && !node.has_brick()) want = kWantsBrick;
        // The node's exit along the ray, in the node's frame.
        double t_exit = ray.span.t1;
        const int entry_axis = exit_axis;
        for (int a = 0; a < 3; ++a) {
          if (frame.dir[a] == 0) continue;
          const double ta = ((frame.dir[a] > 0 ? 1.0 : 0.0) - frame.eye[a]) * frame.inv_dir[a];
          if (ta < t_exit) t_exit = ta, exit_axis = a;
        }
        const double t_face = std::min(std::max(t_exit, t_at), ray.span.t1);
        // A hair past the exit, so the next descent lands in the next node.
        const double node_t = 1.0 / scale / unit_per_t;
        t_exit = std::max(t_exit, t_at) + 1e-7 * node_t;
        rec.used(address);
        if (want && !requested) {
          rec.request(address | want);
          requested = true;
          if (r.allow_interrupt_) {
            s.t = t_at, s.t_sample = t;
            s.status = RayState::interrupted;
            return;
          }
        }
        const double t_end = std::min(t_exit, ray.span.t1);
        if (node.constant()) {
          const float v = node.value();
          if (std::isnan(v)) {  // a region this scene cannot see
            s.have_prev = false;
          } else if (iso) {
            // A constant region is a sample of known value all along it: the surface is at its
            // face when the value steps across an isovalue there.
            for (size_t k = 0; k < r.scene_.isosurfaces.size(); ++k)
              if (v == r.scene_.isosurfaces[k].value) hit_t = std::min(hit_t, t_at), hit_surface = int(k);
            const int crossed = hit_t == kInf && s.have_prev ? first_crossed(s.prev_value, v) : -1;
            if (crossed >= 0) hit_t = t_at, hit_surface = crossed;
            if (hit_t < kInf) {
              hit_levels.count = 0;  // a face: its normal is the axis the ray entered through
              face_axis = entry_axis;
              break;
            }
            s.start_segment(v, t_face);
            prev_node = gigavoxels::kNoAddress;
          } else {
            // DVR descends where its next sample is, which may lie inside the node: the ray
            // enters it at t_from. The part-step from the last sample to there goes from that
            // sample's value to the node's; the node is integrated whole from there; and its
            // value at its exit starts the next segment (each part of the ray counts once).
            double t_from = t_at;
            if (s.have_prev && s.prev_t < t_at) {
              t_from = std::clamp(node_entry(frame), s.prev_t, t_at);
              integrate(s, px, v, t_from, to_voxels(t_from - s.prev_t, unit_per_t), Vec3d(0.0), ray);
              if (s.alpha >= stop) break;
            }
            Vec3f col;
            float a;
            r.preintegrated_.segment(v, v, to_voxels(t_end - t_from, unit_per_t), col, a);
            composite(s, px, col, a, t_from, ShadingModel::Lighting{}, Vec3d(0.0), ray);  // no gradient: ambient light
            if (s.alpha >= stop) break;
            s.start_segment(v, t_end);
          }
          t = t_at = t_exit;
          continue;
        }
        if (lv.count == 0) {  // nothing resident yet, not even the root's brick
          s.have_prev = false;
          t = t_at = t_exit;
          continue;
        }
        ++counters.bricks;
        // March the node with a step from the footprint (never finer than the finest level met).
        const PathNode& fine = *lv.b[lv.count - 1];
        const double fine_voxel = 1.0 / (double(r.m_) * fine.scale);
        // Where the footprint stays finer than the finest level met up to the node's exit (it
        // only grows along the ray), every step has that level alone and the same base length.
        const bool finest_only = footprint(t_end) <= fine_voxel;
        t = std::max(t, t_at);
        if (!iso) {
          const bool finished_dvr = finest_only ? march_dvr<true>(lv, s, t, t_end, t_face, unit_per_t, stop, ray, px)
                                                : march_dvr<false>(lv, s, t, t_end, t_face, unit_per_t, stop, ray, px);
          if (finished_dvr) break;
          t_at = t_exit;
          continue;
        }
        // Iso from here.
        const double finest_dt = r.step_ * fine_voxel / unit_per_t;
        bool finished = false;
        double visible_until = -kInf;  // the cell group of the last look showed something
        // The first crossing the step from the previous sample to t hides (hit_t), if any.
        // The clear groups a leap passed, and those around t when a voxel stands in for its
        // value, are not searched: every value in them is on one side of every isovalue.
        // (Made once per node, not per sample: a closure of this many references made a sample
        // that never called it 5% more instructions.)
        const auto hidden_hit = [&](const Blend& bl, double lam, std::optional<float> value_at_t) {
          if (!r.search_hidden_crossings_ || !s.have_prev || bl.coarse) return false;
          const double from = std::max(s.prev_t, clear_until), to = value_at_t ? t : clear_cube_entry(*bl.finer, t);
          Bracket hidden;
          if (!hidden_crossing(*bl.finer, bounds.of(*bl.finer, *this), prev_node, from, to, s.prev_value, value_at_t, hidden))
            return false;
          hit_t = refine_hit(lv, lam, hidden.t0, hidden.t1, hidden.v0, hidden.v1);
          return true;
        };
        // One more sample at the node's exit, so that a crossing in the last part-step is
        // bracketed even when the next node is empty.
        for (bool last = false; !last;) {
          if (t >= t_end) {
            if (s.have_prev && s.prev_t >= t_face) break;
            t = t_face;
            last = true;
          }
          double lam = fine.depth, dt = finest_dt;
          Blend bl{nullptr, &fine, 1};
          if (!finest_only) {
            const double fp = footprint(t);
            // Finer than the finest level met: that level alone, without a log per sample.
            if (fp > fine_voxel) lam = depth_for(fp);
            dt = r.step_ * std::max(fp, fine_voxel) / unit_per_t;
            bl = blend(lv, lam);
          }
          // A clear cell group (nothing visible in it), and the clear groups around it, are
          // leapt to the first sample position past them, the group's voxel standing in for a
          // sample (DVR: see march_dvr).
          double t_leave = kInf, t_next = 0, t_before = 0;
          float voxel;
          bool leap = false;
          if (r.p_.skip_cells && t >= visible_until) {
            leap = clear(bl, t, true, t_leave, voxel);
            if (!leap) visible_until = t_leave;  // no need to look again before
          }
          if (leap) {  // a clear group's voxel stands in for a sample
            const double steps = leap_steps(t, t_leave, t_face, dt);
            t_next = t + std::max(steps, 1.0) * dt;
            t_before = t_next - dt;  // the last position in the clear groups
            // Every value in the clear groups is on the voxel's side of every isovalue.
            if (s.have_prev && crossing(s.prev_value, voxel)) {
              hit_t = refine_hit(lv, lam, s.prev_t, t, s.prev_value, voxel);
              finished = true;
              break;
            }
            // The step into the clear groups starts in visible ones, where it may graze a surface.
            if (hidden_hit(bl, lam, std::nullopt)) {
              finished = true;
              break;
            }
            s.start_segment(voxel, t_before);
            prev_node = gigavoxels::kNoAddress;
            clear_until = std::min(t_leave, t_face);  // the cube may reach far past this node
            t = t_next;
            continue;
          }
          ++counters.samples;
          const float v = sample(bl, t, nullptr);
          // A crossing since the last sample, or, with none before (the ray's first sample in
          // data it can see), a sample on the surface: the ray starts on it.
          if (s.have_prev ? crossing(s.prev_value, v) : crossing(v, v)) {
            hit_t = s.have_prev ? refine_hit(lv, lam, s.prev_t, t, s.prev_value, v) : refine_hit(lv, lam, t, t, v, v);
            finished = true;
            break;
          }
          if (hidden_hit(bl, lam, v)) {
            finished = true;
            break;
          }
          s.prev_value = v, s.prev_t = t, s.have_prev = true;
          prev_node = bl.coarse ? gigavoxels::kNoAddress : bl.finer->address;
          t += dt;
        }
        if (finished) break;
        t_at = t_exit;
      }
      s.status = RayState::done;
      if (iso) {
        if (hit_t == kInf) return;
        finish_iso(ray, hit_t, px);
      } else {
        if (r.p_.termination_fill && s.alpha >= stop && s.alpha > 0) {
          // Terminated: the light left would have met more of the medium than the background.
          // The last segment's colour is its best guess (the reference's image and raymarch's
          // converge as the termination opacity goes to 1; this estimate converges faster:
          // its error is the light left times how far the colour drifts behind, not times all
          // of it). A ray whose very last segment reaches the opacity is filled too, though
          // nothing lies behind it: an error of at most the light left (1 - the termination
          // opacity) times its colour's distance to the background's.
          px.color = Vec3f(s.accum + Vec3d(s.last_color) * (1 - s.alpha));
          px.alpha = 1;
        } else {
          px.color = Vec3f(s.accum + Vec3d(r.scene_.background) * (1 - s.alpha));
          px.alpha = float(s.alpha);
        }
      }
    }

    /// DVR through the node the descent stopped at, from t to its exit t_end (t_face: the
    /// exit within the ray), sampling the levels lv collected: march()'s loop for DVR, with
    /// the ray's state in locals so that a sample's value, segment, lighting and compositing
    /// stay in registers (7% less time per lit DVR frame than when it was one loop with iso,
    /// 165 -> 154 ms on fBm 256^3 at 256x256, with the same samples and arithmetic).
    /// kOneLevel: the footprint stays finer than the finest level met up to t_end, so every
    /// sample reads that level alone at one base step, with no footprint, log or blend per
    /// sample. Returns whether the ray is finished.
    template <bool kOneLevel>
    bool march_dvr(const Levels& lv, RayState& ray_state, double& t_io, double t_end, double t_face, double unit_per_t,
                   double stop, const PrimaryRay& ray, PixelResult& px) {
      const bool skip_cells = r.p_.skip_cells;
      const PathNode& fine = *lv.b[lv.count - 1];
      const double fine_voxel = 1.0 / (double(r.m_) * fine.scale);
      const double finest_dt = r.step_ * fine_voxel / unit_per_t;
      // The cell group of the last look showed something: before visible_until (!kOneLevel), or
      // while the sample's group index is visible_group (kOneLevel).
      double t = t_io, visible_until = -kInf;
      double prefetched_until = -kInf;  // kOneLevel: the farthest sample position whose cell was asked for
      int visible_group = -1;
      RayState s = ray_state;  // a copy the compiler keeps in registers
      bool finished = false;
      // Where the previous sample fell among the cells of its brick (prev_lattice), when it
      // was taken here, with a gradient, from that brick alone: a segment within one brick's
      // cells is lit by the faces it crosses. Where two levels blend, the coarser level's
      // gradient jumps at other faces, and the segment takes its ends' mean.
      CellPoint prev_at;
      const PathNode* prev_lattice = nullptr;
      // Difference normals are continuous across cell faces (they jump only at store-brick
      // faces, one in M, as the reference's do): their ends' mean serves.
      const bool face_lighting = r.p_.face_lighting && gradients && r.shading_.lit() && r.scene_.shading.normals == NormalMethod::analytic;
      if constexpr (kOneLevel)
        if (r.step_ >= kEntryPrefetchStep && t < t_end) prefetch_entry_samples(fine, t, finest_dt * s.step_scale, t_end, t_face);
      // One more sample at the node's exit, so that the part-step to it is integrated even
      // when the next node takes no samples (hidden, or past the ray's end: on Marschner-Lobb
      // 64^3 at step 1, leaving that out doubled the error).
      for (bool last = false; !last;) {
        if (t >= t_end) {
          if (!s.have_prev || s.prev_t >= t_face) break;
          t = t_face;
          last = true;
        }
        double dt = finest_dt;
        Blend bl{nullptr, &fine, 1};
        if constexpr (!kOneLevel) {
          const double fp = footprint(t);
          // Finer than the finest level met: that level alone, without a log per sample.
          const double lam = fp > fine_voxel ? depth_for(fp) : double(fine.depth);
          dt = r.step_ * std::max(fp, fine_voxel) / unit_per_t;
          bl = blend(lv, lam);
        }
        dt *= s.step_scale;
        // A clear cell group (nothing visible in it), and the clear groups around it, are
        // leapt to the first sample position past them: at one level, the samples taken are
        // the ones marching every step would take; where the step follows the footprint, later
        // samples move (another sampling, as accurate). A leap of one step is a plain step.
        double t_next = 0, t_leave = kInf;
        bool leap = false;
        // At one level, t's brick coordinates serve both the look and the sample; and the look
        // is skipped while the ray stays in the group the last look found visible, which its
        // index tells more cheaply than where the ray leaves that group.
        double l[3];
        if constexpr (kOneLevel) {
          if (runs && s.have_prev && !last) {
            const Run run = sample_run(fine, s, px, t, dt, t_end, t_face, unit_per_t, stop, visible_group, prev_at,
                                       prev_lattice, face_lighting, ray);
            if (run == Run::finished) {
              finished = true;
              break;
            }
            if (run == Run::exited) break;  // t is past the exit, as after the exit sample below
            if (run == Run::leapt) {  // as a leap below, whose first sample the run took
              if (r.p_.leap_chains) t = chain_leaps(fine, t, dt, finest_dt * s.step_scale, t_end, t_face);
              ++counters.samples;
              prev_lattice = nullptr;
              s.start_segment(sample(bl, t - dt, nullptr), t - dt);
              continue;
            }
            if (run == Run::advanced) continue;
          }
          brick_coordinates(fine, t, l);
          // At one level the step is known, so the next positions are: on a volume larger than
          // the caches a sample's rows often miss, and asking for them a few steps ahead hides
          // part of that: 3-5% of a lit 512x512 DVR frame of fBm 1024^3 u16 at step 1 (medians
          // 1.12-1.18 s -> 1.08-1.13 s, 6 alternations). Fragile: the same prefetches in a
          // counted loop from t, or left out where a leap starts and past the node's exit, lost
          // the gain. The frame is bound by instructions, not memory: a 64x64 crop of it that
          // stays in the caches costs as much per sample.
          prefetched_until = std::max(prefetched_until, t);
          for (int k = 0; k < kPrefetchAhead && prefetched_until < t + kPrefetchAhead * dt; ++k) {
            prefetched_until += dt;
            double ahead[3];
            for (int a = 0; a < 3; ++a) ahead[a] = l[a] + fine.frame.dir[a] * double(r.m_) * (prefetched_until - t);
            prefetch_cell(fine, ahead);
          }
          if (skip_cells) {
            int g[3];
            if (const int i = group_of(l, g); i != visible_group) {
              const uint8_t distance = fine.group_distances[i];
              if (distance == 0) visible_group = i;
              else leap = true, t_leave = cube_crossing(fine, g, distance, true);
            }
          }
        } else if (skip_cells && t >= visible_until) {
          float voxel;  // DVR samples where a leap ends instead
          leap = clear(bl, t, false, t_leave, voxel);
          if (!leap) visible_until = t_leave;  // no need to look again before
        }
        if (leap) {
          const double steps = leap_steps(t, t_leave, t_face, dt);
          leap = steps > 1;
          t_next = t + std::max(steps, 1.0) * dt;
        }
        // A sample at t, unless a leap starts there with no segment open (the clear groups add
        // nothing): then the leap's last value alone starts the next segment.
        if (!leap || s.have_prev) {
          ++counters.samples;
          Vec3d g(0.0);
          CellPoint at;
          const bool one_lattice = face_lighting && !bl.coarse;
          float v;
          if constexpr (kOneLevel) v = sample_brick_at(fine, l, gradients ? &g : nullptr, one_lattice ? &at : nullptr);
          else v = sample(bl, t, gradients ? &g : nullptr, one_lattice ? &at : nullptr);
          bool lit_here = false;
          if (s.have_prev) {
            lit_here = integrate(s, px, v, t, to_voxels(t - s.prev_t, unit_per_t), g, ray,
                                 one_lattice && prev_lattice == bl.finer ? &prev_at : nullptr, &at, bl.finer);
            if (s.alpha >= stop) {
              finished = true;
              break;
            }
          }
          s.prev_value = v, s.prev_t = t, s.have_prev = true;
          s.prev_gradient = g, s.have_prev_gradient = gradients, s.have_prev_lighting = lit_here;
          prev_at = at, prev_lattice = one_lattice ? bl.finer : nullptr;
        }
        if (leap) {  // the segment into the clear groups is closed: their last value starts the next
          if constexpr (kOneLevel)
            if (r.p_.leap_chains) t_next = chain_leaps(fine, t_next, dt, finest_dt * s.step_scale, t_end, t_face);
          ++counters.samples;
          prev_lattice = nullptr;  // no gradient at the segment's start
          s.start_segment(sample(bl, t_next - dt, nullptr), t_next - dt);
          t = t_next;
          continue;
        }
        t += dt;
      }
      ray_state = s;
      t_io = t;
      return finished;
    }

    /// How many samples sample_run takes side by side: AVX2's floats.
    static constexpr int kRunLanes = 8;
    // GCC's vector extension: AVX2 where the target has it (x86-64-v3 is the build's floor).
    using LaneFloats = float __attribute__((vector_size(32)));
    using LaneInts = int32_t __attribute__((vector_size(32)));
    /// How a run ended: none (t's group is clear: no run), advanced (t: the next sample
    /// position), finished (the ray is), exited (its last sample was the node's exit: t is past
    /// it), leapt (its last sample started a leap over clear groups: t is the first position
    /// past them, whose last position t - dt starts the next segment).
    enum class Run { none, advanced, finished, exited, leapt };
    /// march_dvr<true>'s samples from t on, up to kRunLanes of them, taken side by side in
    /// vector lanes (GCC's vector extension): positions and cell groups (then the looks at
    /// them one by one, as march_dvr's), cells, gathered corners, values and gradients,
    /// lighting, face weights and the lighting between faces (lighting_between), and segments
    /// (PreintegratedTf::segments); then the compositing
    /// in order. The same samples and arithmetic as one at a time, but for the step: it stays
    /// dt across the run, where the adaptive step would grow it after each visible segment.
    /// A run ends at the node's exit (t_end), whose sample at t_face (the exit within the ray)
    /// is its last, as one at a time takes it; and at a sample whose cell group is clear,
    /// which is its last when a leap starts there (march_dvr takes the leap's last position)
    /// and is left out otherwise. Needs a segment open (s.have_prev).
    Run sample_run(const PathNode& b, RayState& s, PixelResult& px, double& t, double dt, double t_end, double t_face,
                   double unit_per_t, double stop, int& visible_group, CellPoint& prev_at, const PathNode*& prev_lattice,
                   bool face_lighting, const PrimaryRay& ray) {
      constexpr int L = kRunLanes;
      // GCC 12's loop vectoriser left most of these lanes scalar, with their arrays spilled.
      using Floats = LaneFloats;
      using Ints = LaneInts;
      using Doubles = double __attribute__((vector_size(32)));  // half the lanes
      using Floats4 = float __attribute__((vector_size(16)));
      using Ints4 = int32_t __attribute__((vector_size(16)));
      constexpr int H = L / 2;
      static_assert(kCellGroup == 4, "a cell group's index is a shift by 2");
      // Positions one step after another, as march_dvr takes them; then their brick coordinates
      // (brick_coordinates, read in float as sample_brick_at reads them) and cell groups
      // (group_of) side by side.
      double tk[L];
      tk[0] = t;
      for (int k = 1; k < L; ++k) tk[k] = tk[k - 1] + dt;
      // The first position at or past the node's exit is the exit itself, when the sample before
      // lies before it (march_dvr's exit sample: t_end is a hair past t_face). The lanes after it
      // are not used.
      int exit_lane = L;
      for (int k = 1; k < L; ++k)
        if (!(tk[k] < t_end)) {
          if (tk[k - 1] < t_face) exit_lane = k, tk[k] = t_face;
          break;
        }
      const double m = double(r.m_);
      const Doubles group_top = Doubles{} + double(r.m_ + 1);
      float lf[3][L];
      int32_t group[L];
      for (int h = 0; h < L; h += H) {
        Doubles th;
        std::memcpy(&th, &tk[h], sizeof th);
        Ints4 g[3];
        for (int a = 0; a < 3; ++a) {
          const Doubles l = (b.frame.eye[a] + b.frame.dir[a] * th) * m + 0.5;
          const Floats4 f = __builtin_convertvector(l, Floats4);
          std::memcpy(&lf[a][h], &f, sizeof f);
          const Doubles clamped = l > 0 ? (l < group_top ? l : group_top) : Doubles{};  // NaN: 0
          g[a] = __builtin_convertvector(clamped, Ints4) >> 2;
        }
        const Ints4 index = (g[2] * r.groups_ + g[1]) * r.groups_ + g[0];
        std::memcpy(&group[h], &index, sizeof index);
      }
      int n = 0;
      Run ending = Run::advanced;
      std::optional<double> t_after;  // where the march goes on, when not one step past the run's last sample
      for (; n < L; ++n) {
        if (n == exit_lane) {  // its look may leap nothing (march_dvr's leap of 0 steps)
          ending = Run::exited;
          ++n;
          break;
        }
        if (!(tk[n] < t_end)) break;  // past the exit, with no exit sample
        if (r.p_.skip_cells && group[n] != visible_group) {
          if (const uint8_t distance = b.group_distances[group[n]]; distance != 0) {
            if (n == 0) return Run::none;
            // march_dvr's leap from here: a leap of one step is a plain step, which ends the run.
            double l[3];
            int g[3];
            brick_coordinates(b, tk[n], l);
            group_of(l, g);
            const double t_leave = cube_crossing(b, g, distance, true);
            const double steps = leap_steps(tk[n], t_leave, t_face, dt);
            ending = steps > 1 ? Run::leapt : Run::advanced;
            t_after = tk[n] + std::max(steps, 1.0) * dt;
            ++n;
            break;
          }
          visible_group = group[n];
        }
      }
      if (n == 0) return Run::none;
      // Cells and values: brick_cell and sample_brick_at. Point 0 is the previous sample (face
      // weights), the run's samples are points 1..L. Lanes past n sample past the run, inside
      // the brick (clamped as every sample is), and are not used.
      int32_t cell[3][L + 1];
      float u[3][L + 1];
      for (int a = 0; a < 3; ++a) cell[a][0] = prev_at.cell[a], u[a][0] = prev_at.u[a];
      Floats x[3], uf[3], corner[8];
      Ints cells[3];
      for (int a = 0; a < 3; ++a) std::memcpy(&x[a], lf[a], sizeof x[a]);
      cells_and_corners(b, x, cells, uf, corner);
      for (int a = 0; a < 3; ++a) std::memcpy(&cell[a][1], &cells[a], sizeof cells[a]), std::memcpy(&u[a][1], &uf[a], sizeof uf[a]);
      float value[L + 1];  // point 0: the previous sample's
      value[0] = s.prev_value;
      double gradient[3][L];
      bool normal[L];
      const double to_unit = b.scale * m;  // brick voxels to unit coordinates
      if (gradients) {
        Vec3<Floats> g;
        const Floats v = trilinear_with_gradient(corner, uf[0], uf[1], uf[2], g);
        std::memcpy(&value[1], &v, sizeof v);
        gradients_in_doubles(g, to_unit, gradient, normal);
      } else {
        const Floats v = trilinear(corner, uf[0], uf[1], uf[2]);
        std::memcpy(&value[1], &v, sizeof v);
        std::fill_n(&gradient[0][0], 3 * L, 0.0);
        std::fill_n(normal, L, false);
      }
      // Segments from each sample's predecessor.
      Vec3f color[L];
      float alpha[L];
      double length[L];
      for (int k = 0; k < n; ++k) length[k] = to_voxels(tk[k] - (k == 0 ? s.prev_t : tk[k - 1]), unit_per_t);
      r.preintegrated_.segments<L>(value, length, n, color, alpha);
      // Lighting at each sample (lighting_at), and each segment's face weight.
      float diffuse[L] = {}, specular[L] = {};
      const bool lit = gradients && r.shading_.lit();
      if (lit) {
        double world[3][L];
        for (int a = 0; a < 3; ++a)
          for (int k = 0; k < L; ++k) world[a][k] = gradient[a][k] * r.unit_gradient_to_world_[a];
        r.shading_.lighting_of_gradients(world, ray_light, ray_half, diffuse, specular);
        // Zero gradients have no lighting; the rest are lit as lighting_at would light them
        // but for a gradient too small or too large to normalise, or a sample at the eye.
        bool any_falls_back = false;
        bool falls_back[L];
        for (int k = 0; k < n; ++k) {
          const double length2 = world[0][k] * world[0][k] + world[1][k] * world[1][k] + world[2][k] * world[2][k];
          falls_back[k] = !(normal[k] && length2 > 0 && length2 < kInf && tk[k] > 0);
          any_falls_back |= falls_back[k];
        }
        for (int k = 0; any_falls_back && k < n; ++k) {
          if (!falls_back[k]) continue;
          const Vec3d g(gradient[0][k], gradient[1][k], gradient[2][k]);
          const ShadingModel::Lighting l = normal[k] ? lighting_at(tk[k], g, ray) : ShadingModel::Lighting{};
          counters.gradients -= normal[k];  // counted below, as for every lane
          diffuse[k] = l.diffuse, specular[k] = l.specular;
        }
      }
      gigavoxels::FaceCrossings crossings[L];  // none crossed (front weight 1/2) without face lighting
      bool middle[L] = {};  // lit between its first and last faces by the lighting at their middle
      float middle_diffuse[L] = {}, middle_specular[L] = {};
      bool middle_normal[L] = {};
      if (face_lighting) {
        gigavoxels::face_crossings(cell, u, crossings);
        if (prev_lattice != &b) crossings[0] = {};  // its front end lies in another lattice
        bool any_middle = false;
        for (int k = 0; k < L; ++k) {
          middle[k] = lit && r.p_.middle_lighting && k < n && alpha[k] > 0 && crossings[k].has_middle();
          any_middle |= middle[k];
        }
        if (any_middle) lighting_between(b, cell, u, crossings, middle, tk, s.prev_t, ray, middle_diffuse, middle_specular, middle_normal);
      }
      // Compositing, in order (integrate and composite).
      const ShadingModel::Lighting none{};
      for (int k = 0; k < n; ++k) {
        if (alpha[k] > 0) {
          const ShadingModel::Lighting here{diffuse[k], specular[k]};
          counters.gradients += normal[k];
          ShadingModel::Lighting light = here;
          const bool front_gradient = k > 0 ? gradients : s.have_prev_gradient;
          if (front_gradient) {
            const bool front_lit = k > 0 ? alpha[k - 1] > 0 : s.have_prev_lighting;
            if (k == 0 && !front_lit) s.prev_lighting = lighting_at(s.prev_t, s.prev_gradient, ray);
            if (k > 0 && !front_lit) counters.gradients += normal[k - 1];
            const ShadingModel::Lighting front_light =
                k == 0 ? s.prev_lighting : ShadingModel::Lighting{diffuse[k - 1], specular[k - 1]};
            if (middle[k]) {
              counters.gradients += middle_normal[k];
              light = across_faces(front_light, {middle_diffuse[k], middle_specular[k]}, here, crossings[k]);
            } else {
              light = front_light.mix(here, crossings[k].front_weight());
            }
          }
          const Vec3f c = r.shading_.apply(color[k], lit ? light : none);
          s.last_color = c;
          const double a = alpha[k];
          s.accum += Vec3d(c) * ((1 - s.alpha) * a);
          s.alpha += (1 - s.alpha) * a;
          if (px.depth == kInf && s.alpha >= 0.5) {
            px.depth = tk[k];
            if (setup.outputs.normals) px.normal = normal_of(Vec3d(gradient[0][k], gradient[1][k], gradient[2][k]), ray);
          }
        }
        // After every sample, as march_dvr checks (a termination opacity of 0 ends at the first).
        if (s.alpha >= stop) {
          // The samples past it were not the ray's. The state keeps the run's start: a
          // finished ray reads only its colour and opacity.
          counters.samples += uint64_t(k + 1);
          samples_in_runs += uint64_t(k + 1);
          return Run::finished;
        }
      }
      counters.samples += uint64_t(n);
      samples_in_runs += uint64_t(n);
      if (r.p_.adaptive_step > 1) s.step_scale = adaptive_step_scale(s.alpha);
      const int last = n - 1;
      s.prev_value = value[n], s.prev_t = tk[last], s.have_prev = true;
      s.prev_gradient = Vec3d(gradient[0][last], gradient[1][last], gradient[2][last]);
      s.have_prev_gradient = gradients, s.have_prev_lighting = alpha[last] > 0;
      if (s.have_prev_lighting) s.prev_lighting = {diffuse[last], specular[last]};
      for (int a = 0; a < 3; ++a) prev_at.cell[a] = cell[a][n], prev_at.u[a] = u[a][n];
      prev_lattice = face_lighting ? &b : nullptr;
      t = t_after ? *t_after : tk[last] + dt;
      return ending;
    }

    /// brick_cell for kRunLanes points of brick b at brick coordinates x, side by side: their
    /// cells c (clamped as brick_cell clamps; NaN: 0), the positions uf in them, and the cells'
    /// corners.
    [[gnu::always_inline]] void cells_and_corners(const PathNode& b, const LaneFloats (&x)[3], LaneInts (&c)[3],
                                                  LaneFloats (&uf)[3], LaneFloats (&corner)[8]) const {
      constexpr int L = kRunLanes;
      const int32_t e = r.m_ + 2;
      const LaneFloats cell_top = LaneFloats{} + float(e - 1);
      const LaneInts last_cell = LaneInts{} + (e - 2);
      LaneInts offset = {};
      for (int a = 2; a >= 0; --a) {
        const LaneFloats clamped = x[a] > 0.0f ? (x[a] < cell_top ? x[a] : cell_top) : LaneFloats{};
        c[a] = __builtin_convertvector(clamped, LaneInts);
        c[a] = c[a] < last_cell ? c[a] : last_cell;
        uf[a] = clamped - __builtin_convertvector(c[a], LaneFloats);
        offset = offset * e + c[a];  // (cell z * e + cell y) * e + cell x
      }
      int32_t offsets[L];
      std::memcpy(offsets, &offset, sizeof offsets);
      float corners[8][L];
      gigavoxels::load_cell_corners(b.brick, offsets, e, corners);
      for (int i = 0; i < 8; ++i) std::memcpy(&corner[i], corners[i], sizeof corner[i]);
    }
    /// Gradient lanes (brick voxels) in doubles, in unit coordinates (to_unit), and whether
    /// each has a normal (is not zero).
    [[gnu::always_inline]] static void gradients_in_doubles(const Vec3<LaneFloats>& g, double to_unit,
                                                            double (&gradient)[3][kRunLanes], bool (&normal)[kRunLanes]) {
      using Doubles = double __attribute__((vector_size(32)));  // half the lanes
      using Floats4 = float __attribute__((vector_size(16)));
      constexpr int H = kRunLanes / 2;
      for (int h = 0; h < kRunLanes; h += H) {
        Doubles gd[3];
        for (int a = 0; a < 3; ++a) {
          const Floats4 part = h == 0 ? __builtin_shufflevector(g[a], g[a], 0, 1, 2, 3) : __builtin_shufflevector(g[a], g[a], 4, 5, 6, 7);
          gd[a] = __builtin_convertvector(part, Doubles) * to_unit;
          std::memcpy(&gradient[a][h], &gd[a], sizeof gd[a]);
        }
        const auto has = (gd[0] != 0) | (gd[1] != 0) | (gd[2] != 0);
        for (int k = 0; k < H; ++k) normal[h + k] = has[k] != 0;
      }
    }

    /// The lighting in the middle of the cells each segment of a run crosses between its first
    /// and last faces (crossings), as integrate() takes it one at a time: its point in brick
    /// coordinates from its ends' cells (points k and k + 1 of cell and u), then brick_cell,
    /// the corners, the analytic gradient and lighting_of_gradients, side by side; lighting_at
    /// where that cannot light a lane it is used for. Its gradient is counted where it is used.
    [[gnu::always_inline]] void lighting_between(const PathNode& b, const int32_t (&cell)[3][kRunLanes + 1],
                                                 const float (&u)[3][kRunLanes + 1],
                                                 const gigavoxels::FaceCrossings (&crossings)[kRunLanes],
                                                 const bool (&used)[kRunLanes], const double (&tk)[kRunLanes], double prev_t, const PrimaryRay& ray,
                                                 float (&diffuse)[kRunLanes], float (&specular)[kRunLanes],
                                                 bool (&normal)[kRunLanes]) {
      constexpr int L = kRunLanes;
      using Floats = LaneFloats;
      using Ints = LaneInts;
      float fraction[L];
      for (int k = 0; k < L; ++k) fraction[k] = crossings[k].middle();
      Floats at;
      std::memcpy(&at, fraction, sizeof at);
      Floats x[3], uf[3], corner[8];
      Ints c[3];
      for (int a = 0; a < 3; ++a) {
        Ints c0, c1;
        Floats u0, u1;
        std::memcpy(&c0, &cell[a][0], sizeof c0), std::memcpy(&c1, &cell[a][1], sizeof c1);
        std::memcpy(&u0, &u[a][0], sizeof u0), std::memcpy(&u1, &u[a][1], sizeof u1);
        const Floats l0 = __builtin_convertvector(c0, Floats) + u0, l1 = __builtin_convertvector(c1, Floats) + u1;
        x[a] = l0 + at * (l1 - l0);
      }
      cells_and_corners(b, x, c, uf, corner);
      Vec3<Floats> g;
      trilinear_with_gradient(corner, uf[0], uf[1], uf[2], g);
      double gradient[3][L], world[3][L];
      gradients_in_doubles(g, b.scale * double(r.m_), gradient, normal);
      for (int a = 0; a < 3; ++a)
        for (int k = 0; k < L; ++k) world[a][k] = gradient[a][k] * r.unit_gradient_to_world_[a];
      r.shading_.lighting_of_gradients(world, ray_light, ray_half, diffuse, specular);
      for (int k = 0; k < L; ++k) {
        if (!used[k]) continue;
        const double length2 = world[0][k] * world[0][k] + world[1][k] * world[1][k] + world[2][k] * world[2][k];
        const double t_middle = (k == 0 ? prev_t : tk[k - 1]) + double(fraction[k]) * (tk[k] - (k == 0 ? prev_t : tk[k - 1]));
        if (normal[k] && length2 > 0 && length2 < kInf && t_middle > 0) continue;
        const ShadingModel::Lighting l =
            normal[k] ? lighting_at(t_middle, Vec3d(gradient[0][k], gradient[1][k], gradient[2][k]), ray) : ShadingModel::Lighting{};
        counters.gradients -= normal[k];  // counted where used, as for every lane
        diffuse[k] = l.diffuse, specular[k] = l.specular;
      }
    }

    /// The first isosurface whose value going from value a to value b crosses (or lands on);
    /// -1 when none does.
    int first_crossed(float a, float b) const {
      const double da = a, db = b;
      const auto& surfaces = r.scene_.isosurfaces;
      for (size_t k = 0; k < surfaces.size(); ++k)
        if ((da < surfaces[k].value) != (db < surfaces[k].value) || db == surfaces[k].value) return int(k);
      return -1;
    }
    bool crossing(float a, float b) const { return first_crossed(a, b) >= 0; }

    /// Two samples on the same side of every isovalue can hide an even number of crossings
    /// between them (a ray grazing a surface, a sheet thinner than the step). A crossing pair
    /// needs both: the ends near enough to an isovalue for the field to reach it and come back
    /// (FieldBounds::slope), and the chord between them near enough for the field to stray to
    /// it (FieldBounds::stray). Where both allow one, the step is halved until each part is
    /// cleared or shows a crossing, or is 2^-hidden_crossings voxels long (search_halvings_).
    struct Bracket {
      double t0 = 0, t1 = 0;
      float v0 = 0, v1 = 0;
    };
    FieldBounds field_bounds(const PathNode& b) const {
      double w[3];  // voxels of b's level per unit t, per axis
      for (int a = 0; a < 3; ++a) w[a] = b.frame.dir[a] * double(r.m_);
      return gigavoxels::field_bounds(*b.differences, w);
    }
    /// The bounds of the brick last searched: a node's level fixes its direction's scale, so
    /// they hold until the brick changes (per ray: the direction does).
    struct CachedBounds {
      const PathNode* node = nullptr;
      const BrickDifferences* differences = nullptr;
      FieldBounds bounds;
      const FieldBounds& of(const PathNode& b, const Tracer& tracer) {
        if (&b != node || b.differences != differences) node = &b, differences = b.differences, bounds = tracer.field_bounds(b);
        return bounds;
      }
    };
    /// The first crossing hidden between the samples v0 at t0 and v1 at t1 of brick b's node.
    /// v0 may be something else's (prev_node: another node's brick, a clear group's voxel), and
    /// t0 in nodes the step went past: then only the part of the step in b's node is searched,
    /// from this brick's own value where the ray enters it. Without v1 (t1 where the clear
    /// groups a voxel stands in for begin), this brick's value there ends the step.
    bool hidden_crossing(const PathNode& b, const FieldBounds& f, uint32_t prev_node, double t0, double t1, float v0,
                         std::optional<float> v1, Bracket& out) {
      const bool own_v0 = prev_node == b.address;
      if (!(t0 < t1)) return false;
      if (own_v0 && v1) return search_halves(b, f, t0, t1, v0, *v1, r.search_halvings_, out);
      if (!own_v0) t0 = std::max(t0, node_entry(b.frame));
      if (!(t0 < t1)) return false;
      if (!own_v0 && !v1) {  // between clear groups (or from another node into them): neither end known
        counters.samples += 2;
        v0 = sample_brick(b, t0, nullptr), v1 = sample_brick(b, t1, nullptr);
        if (crossing(v0, *v1)) return out = {t0, t1, v0, *v1}, true;
        return search_halves(b, f, t0, t1, v0, *v1, r.search_halvings_, out);
      }
      // With one end known, f must still get from an isovalue to it within the step.
      const double known = own_v0 ? v0 : *v1;
      bool reachable = false;
      for (const auto& surface : r.scene_.isosurfaces) reachable |= std::abs(known - surface.value) <= f.slope * (t1 - t0);
      if (!reachable) return false;
      ++counters.samples;
      if (own_v0) v1 = sample_brick(b, t1, nullptr);
      else v0 = sample_brick(b, t0, nullptr);
      if (crossing(v0, *v1)) return out = {t0, t1, v0, *v1}, true;
      return search_halves(b, f, t0, t1, v0, *v1, r.search_halvings_, out);
    }
    /// Whether f can cross an isovalue twice between the values v0 and v1, dt apart, both on
    /// the same side of every isovalue.
    bool may_hide(const FieldBounds& f, double dt, float v0, float v1) const {
      for (const auto& surface : r.scene_.isosurfaces) {
        const double g0 = std::abs(double(v0) - surface.value), g1 = std::abs(double(v1) - surface.value);
        if (g0 + g1 <= f.slope * dt && std::min(g0, g1) <= f.stray(dt)) return true;
      }
      return false;
    }
    bool search_halves(const PathNode& b, const FieldBounds& f, double t0, double t1, float v0, float v1, int halvings,
                       Bracket& out) {
      if (halvings == 0 || !may_hide(f, t1 - t0, v0, v1)) return false;
      const double tm = 0.5 * (t0 + t1);
      ++counters.samples;
      const float vm = sample_brick(b, tm, nullptr);
      if (crossing(v0, vm)) return out = {t0, tm, v0, vm}, true;
      if (search_halves(b, f, t0, tm, v0, vm, halvings - 1, out)) return true;
      if (crossing(vm, v1)) return out = {tm, t1, vm, v1}, true;
      return search_halves(b, f, tm, t1, vm, v1, halvings - 1, out);
    }

    double refine_hit(const Levels& lv, double lambda, double t0, double t1, float v0, float v1) {
      // Bisected down to 2^-refine voxels of the level sampled, whatever the bracket's length.
      const NodeFrame& frame = blend(lv, lambda).finer->frame;
      const double voxels = (t1 - t0) * double(r.m_) * length(Vec3d(frame.dir[0], frame.dir[1], frame.dir[2]));
      const int steps = voxels > 0 ? int(std::clamp(double(r.p_.refine) + std::ceil(std::log2(voxels)), 0.0, 60.0)) : 0;
      // The first surface crossed between the two samples.
      double best = t1;
      for (const auto& surface : r.scene_.isosurfaces) {
        const double g0 = v0 - surface.value, g1 = v1 - surface.value;
        if (!((g0 < 0) != (g1 < 0) || g1 == 0)) continue;
        const double iso = surface.value;
        const double th = bisect_crossing(
            [&](double m) {
              ++counters.samples;
              return double(sample(lv, lambda, m, nullptr)) - iso;
            },
            t0, t1, g0, g1, steps);
        if (th < best) best = th, hit_surface = int(&surface - r.scene_.isosurfaces.data());
      }
      hit_levels = lv;
      hit_lambda = lambda;
      return best;
    }

    void finish_iso(const PrimaryRay& ray, double hit_t, PixelResult& px) {
      px.depth = hit_t;
      px.alpha = 1;
      const int surface = std::max(0, hit_surface);
      px.color = r.scene_.isosurfaces[size_t(surface)].color;
      if (!gradients) return;
      Vec3d g(0.0);
      if (hit_levels.count > 0) {
        sample(hit_levels, hit_lambda, hit_t, &g);
      } else if (face_axis >= 0) {
        g[face_axis] = ray.dir[face_axis] > 0 ? 1.0 : -1.0;  // the value rises into the region entered
      }
      // Unit-cube gradient to world: unit = voxel / extent, voxel = world / spacing.
      ++counters.gradients;
      const Vec3d n = facing_normal(g / (r.geo_.spacing * r.extent_), ray.world.dir);
      if (setup.outputs.normals) px.normal = n;
      if (!r.shading_.lit()) return;
      double light_distance;
      const Vec3d l = r.shading_.to_light_along(ray.world, hit_t, light_distance);
      px.color = r.shading_.shade(px.color, n, -ray.world.dir, l, false);
    }

    /// A segment's lighting from its ends' and its middle's (face_lighting.h): each end's
    /// stands for the part in its own cell, the middle's for the cells between.
    static ShadingModel::Lighting across_faces(const ShadingModel::Lighting& front, const ShadingModel::Lighting& middle,
                                               const ShadingModel::Lighting& back, const gigavoxels::FaceCrossings& f) {
      const float between = f.last - f.first, after = 1 - f.last;
      return {f.first * front.diffuse + between * middle.diffuse + after * back.diffuse,
              f.first * front.specular + between * middle.specular + after * back.specular};
    }

    /// Whether a sample's gradient (per unit coordinate) gives it a normal: a zero gradient
    /// gives none, and so the ambient term alone.
    bool has_normal(const Vec3d& gradient) const { return gradients && (gradient.x != 0 || gradient.y != 0 || gradient.z != 0); }
    /// The normal of a sample's gradient (zero where it has none), facing the ray.
    Vec3d normal_of(const Vec3d& gradient, const PrimaryRay& ray) const {
      return has_normal(gradient) ? facing_normal(gradient * r.unit_gradient_to_world_, ray.world.dir) : Vec3d(0.0);
    }
    /// The lighting at t for the field's gradient there.
    ShadingModel::Lighting lighting_at(double t, const Vec3d& gradient, const PrimaryRay& ray) {
      const bool normal = has_normal(gradient);
      counters.gradients += normal;
      if (!r.shading_.lit()) return {};
      if (light_fixed && t > 0) {
        if (normal) {
          // Without forming the unit normal: |n.l| and |n.h| do not depend on which way it faces.
          const Vec3d g = gradient * r.unit_gradient_to_world_;
          const double length2 = dot(g, g);
          if (length2 > 0 && length2 < kInf) return r.shading_.lighting_of_gradient(g, 1 / std::sqrt(length2), ray_light, ray_half);
        }
        return r.shading_.lighting_with_half(normal_of(gradient, ray), ray_light, ray_half, false);
      }
      double light_distance;
      return r.shading_.lighting(normal_of(gradient, ray), -ray.world.dir, r.shading_.to_light_along(ray.world, t, light_distance), false);
    }
    /// DVR: integrates the segment from the previous sample to t, where the value is v and the
    /// gradient g (zero: ambient light alone at that end), `voxels` finest voxels long. Shaded
    /// with its ends' lighting, weighted by the cell faces between them where both lie in one
    /// brick (prev_at and at of `lattice`: face_crossings), the cells between its first and
    /// last faces lit at their middle (middle_lighting) or by the ends' mean; else their mean (the back end's alone is
    /// half a segment off; the lighting of a mean gradient is not the mean lighting where
    /// normals turn). Returns whether the segment showed anything, and so whether t's lighting
    /// was computed (s.prev_lighting) for the next segment.
    [[gnu::always_inline]] bool integrate(RayState& s, PixelResult& px, float v, double t, double voxels, const Vec3d& g,
                                          const PrimaryRay& ray, const CellPoint* prev_at = nullptr,
                                          const CellPoint* at = nullptr, const PathNode* lattice = nullptr) {
      Vec3f col;
      float a;
      r.preintegrated_.segment(s.prev_value, v, voxels, col, a);
      if (!(a > 0)) return false;
      const ShadingModel::Lighting back = lighting_at(t, g, ray);
      if (!s.have_prev_lighting && s.have_prev_gradient) s.prev_lighting = lighting_at(s.prev_t, s.prev_gradient, ray);
      if (s.have_prev_gradient) {
        const gigavoxels::FaceCrossings f = prev_at ? gigavoxels::face_crossings(*prev_at, *at) : gigavoxels::FaceCrossings{};
        if (r.p_.middle_lighting && r.shading_.lit() && f.has_middle()) {
          // The lighting where the cells between lie (their middle), as sample_run takes it.
          double l[3];
          for (int k = 0; k < 3; ++k) {
            const float l0 = float(prev_at->cell[k]) + prev_at->u[k], l1 = float(at->cell[k]) + at->u[k];
            l[k] = double(l0 + f.middle() * (l1 - l0));
          }
          Vec3d middle_gradient;
          sample_brick_at(*lattice, l, &middle_gradient, nullptr);
          const ShadingModel::Lighting middle = lighting_at(s.prev_t + double(f.middle()) * (t - s.prev_t), middle_gradient, ray);
          composite(s, px, col, a, t, across_faces(s.prev_lighting, middle, back, f), g, ray);
        } else {
          composite(s, px, col, a, t, s.prev_lighting.mix(back, f.front_weight()), g, ray);
        }
      } else {
        composite(s, px, col, a, t, back, g, ray);
      }
      s.prev_lighting = back;
      return true;
    }
    /// A stretch dt of ray parameter in finest voxels, opacity's unit (unit_per_t: unit-cube
    /// length per unit t).
    double to_voxels(double dt, double unit_per_t) const { return dt * unit_per_t / r.finest_voxel_unit_; }
    /// DVR's step, in base steps, where a sample counts less. A segment's error reaches the
    /// image through the light left to the ray, T = 1 - alpha; where the error per unit
    /// length grows with the step (lit DVR: the lighting of a segment's two ends stands for
    /// all of it), the fewest samples for a given image error take steps growing as T^-1/2,
    /// up to adaptive_step. With face_lighting the error falls faster than the step between
    /// steps 0.5 and 0.25 (as its 1.4th power on Marschner-Lobb 64^3), where a law of
    /// T^-1/2.4 would fit better; T^-1/2 still takes 0.84x a fixed step's samples at equal
    /// error there (AdaptiveStepSpendsSamplesWhereTheyCount; T^-1/2.5 and T^-1/3 saved 0-5%
    /// more, not worth a pow per sample). By T alone: weighting the extinction met as well,
    /// (T tau)^-1/2, saved 15% more samples on lit fBm but grew the step after every stretch of
    /// nothing visible, and stepped over a thin shell behind empty space
    /// (AdaptiveStepStillSeesAThinSheetPastEmptySpace: RMSE 0.021 against a fixed step's 0.0025).
    double adaptive_step_scale(double alpha) const {
      const double light_left = 1 - alpha, cap = r.p_.adaptive_step;
      return !(light_left * cap * cap > 1) ? cap : 1 / std::sqrt(light_left);  // NaN alpha: the cap, never a NaN step
    }
    /// Composites a segment of colour c (not premultiplied) and opacity a; t is where it
    /// counts for the depth output, and the gradient there its normal. The opacity gathered
    /// sets the next step (adaptive_step).
    [[gnu::always_inline]] void composite(RayState& s, PixelResult& px, Vec3f c, double a, double t, const ShadingModel::Lighting& light,
                   const Vec3d& gradient, const PrimaryRay& ray) {
      c = r.shading_.apply(c, light);
      s.last_color = c;
      s.accum += Vec3d(c) * ((1 - s.alpha) * a);
      s.alpha += (1 - s.alpha) * a;
      if (r.p_.adaptive_step > 1) s.step_scale = adaptive_step_scale(s.alpha);
      if (px.depth == kInf && s.alpha >= 0.5) {
        px.depth = t;
        if (setup.outputs.normals) px.normal = normal_of(gradient, ray);
      }
    }

    double eye[3] = {}, dir[3] = {}, inv_dir[3] = {};  // the ray in the unit cube, per unit t
    /// The last descent (of this ray, or of the tile's previous ray), root first.
    std::vector<PathNode> path;
    int path_size = 0;
    std::vector<ScaledEye> scaled_eye;  // per depth, for the eye scaled_eye_of
    double scaled_eye_of[3] = {kNaN, kNaN, kNaN};  // none yet
    int hit_surface = -1;
    int face_axis = -1;
    Levels hit_levels;
    double hit_lambda = 0;
  };

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  GigaVoxelsParams p_;
  ShadingModel shading_;
  std::unique_ptr<Source> source_;
  NodeTree tree_;
  std::vector<Voxel> pool_;  // the brick pool's voxels, brick_capacity() x (M + 2)^3
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
  double inv_log2_arity_ = 1;
  int n_ = 2, m_ = 32;
  double inv_m_ = 1.0 / 32;
  int groups_ = 9;            // cell groups per brick axis
  size_t group_count_ = 729;  // cell groups per brick
  std::vector<uint8_t> group_distances_;  // brick_capacity() x group_count_
  std::vector<BrickDifferences> brick_differences_;  // per slot (set_brick_bounds), where keeps_differences
  int search_halvings_ = 0;                // of a step: to parts of 2^-hidden_crossings voxels
  bool search_hidden_crossings_ = false;  // iso with search_halvings_ > 0
  gigavoxels::PreintegratedTf preintegrated_;

  // Per frame: the feedback buffer and the rays' states, written by the render threads (each
  // pixel by one thread), read by the loader between passes.
  uint64_t frame_ = 0;
  std::unique_ptr<gigavoxels::UseBuffer> uses_;
  mutable std::vector<RayState> states_;
  bool allow_interrupt_ = false;
  bool complete_frames_ = false;  // set_complete_frames()
  bool frame_exact_ = false;      // the frame under way (or the last one) takes exact passes
  gigavoxels::Compactor compactor_;
  std::vector<uint32_t> used_list_, request_list_;
  /// A brick the loader asked the store for, copied into the pool when it arrives whether or
  /// not a ray asks for it again: a ray asks only for the first thing it misses, which moves
  /// as other data arrives, and loaded bricks left waiting for the ray to ask again were pushed
  /// out of the cache's L1 stages by later ones (on fBm 1024^3 at 256x256, a cold start took
  /// 463 frames to converge before, 76 now).
  struct InTransit {
    uint32_t address;
    gigavoxels::NodeAddress node;  // whose brick: the address may be reused by then
    uint64_t since;                // the frame it was first asked for
  };
  /// A load normally arrives the next frame (the cache's p99 latency was 23-88 ms against
  /// frames of 0.1-1 s); one this late is left to the rays to ask for again.
  static constexpr uint64_t kTransitFrames = 16;
  std::vector<InTransit> in_transit_;
  std::unordered_set<uint32_t> transit_addresses_;  // in_transit_'s, rebuilt each pass (a member for its buckets)
  std::vector<float> scratch_;
  std::unordered_map<uint64_t, uint32_t> shared_;  // instanced brick id -> slot
  gigavoxels::CompactionReport compaction_;
  uint64_t passes_ = 0, interrupted_ = 0, frame_subdivisions_ = 0, frame_uploads_ = 0, frame_requests_ = 0, frame_uses_ = 0;
  uint64_t last_pass_progress_ = 0, last_pass_requests_ = 0;
  uint64_t produced_before_ = 0, loaded_before_ = 0, failed_before_ = 0;
  mutable std::atomic<uint64_t> samples_in_runs_{0};  // this frame's samples that sample_run took, added once per tile
  mutable std::atomic<uint64_t> leaps_chained_{0};    // this frame's leaps that chain_leaps took on, added once per tile
  int stalled_frames_ = 0;
  int frames_loading_ = 0;  // first passes in a row that only waited on loads
  double loader_seconds_ = 0;
};

}  // namespace

namespace {
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

  e.info.quality_param = "lod_ratio";
  e.info.quality_sweep = {4, 2, 1, 0.5, 0.25};
  // The loader has at most half the staging slots' worth of bricks asked for at a time
  // (StoreSource's request budget), so none it asked for leaves the cache's L1 before it is
  // copied; the amplified store's coarse sampler reads through L1 too, beside them; the sponge
  // reads no stored brick. A pool sized by hand (brick_slots) leaves the cache the whole budget.
  e.info.l1_staging_slots = [](const BackendParams& p) -> uint32_t {
    if (p["brick_slots"] != 0) return 0;
    if (p["source"] == 1) return 1;
    return uint32_t(2 * p["upload_budget"]) + (p["source"] == 2 ? kCoarseSamplerSlots : 0);
  };
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const GigaVoxelsParams gp = gigavoxels_params().bind(p);
    return dispatch_value_type(ctx.bricks().shape().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      using Stored = decltype(stored);
      std::unique_ptr<Source> source;
      if (gp.source == 1) {
        source = std::make_unique<ProducerSource>(std::make_unique<gigavoxels::MengerProducer>(gp.menger_brick), true);
      } else if (gp.source == 2) {
        source = std::make_unique<AmplifiedSource<Stored>>(ctx, gp);
      } else {
        source = std::make_unique<StoreSource<Stored>>(ctx);
      }
      if (gp.source == 0) return std::make_unique<GigaVoxelsRenderer<Stored>>(ctx, gp, std::move(source));
      return std::make_unique<GigaVoxelsRenderer<float>>(ctx, gp, std::move(source));
    });
  };
  return e;
}

}  // namespace brickyard
