// The sources behind sources.h: StoreSource (a store's bricks through the cache, in the type it
// holds), AmplifiedSource (the store, then Perlin-noise detail below its finest level) and
// ProducerSource (a procedural producer alone).

#include "renderers/gigavoxels/sources.h"

#include <algorithm>
#include <limits>
#include <mutex>

#include "core/parallel.h"
#include "core/value_type.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/gigavoxels/renderer.h"  // GigaVoxelsParams

namespace brickyard::gigavoxels {
namespace {

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
    BrickHandle h = wait ? ctx_.bricks().fetch_or_failed(k) : ctx_.bricks().lookup(k, priority, may_request);
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
  void read_ahead(std::span<const NodeAddress> nodes) override {
    // Into the cache's L1 (and L2) and unpinned: a pass serves at most upload_budget bricks,
    // and the L1 keeps twice that beside the pool (l1_staging_slots). A brick that cannot be
    // read is remembered as failed, which its fill then reports (as is a key outside the grid).
    parallel_for<size_t>(0, nodes.size(), 1, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) (void)ctx_.bricks().fetch_or_failed(store_key(nodes[i]));
    });
  }
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
    AmplifiedParams ap;
    ap.brick_size = layout_.brick_size;
    ap.stored_depth = layout_.finest();
    ap.max_depth = layout_.finest() + p.amplify_levels;
    ap.amplitude = p.amplify_amplitude * std::max(double(root.max - root.min), 1e-30);  // a fraction of the value range
    ap.gain = p.amplify_gain;
    ap.seed = uint64_t(p.amplify_seed);
    ap.lo = root.min, ap.hi = root.max;
    const double extent = double(layout_.brick_size) * double(int64_t(1) << layout_.finest());
    producer_ = std::make_unique<AmplifiedProducer>(
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
  std::unique_ptr<AmplifiedProducer> producer_;
  uint64_t produced_ = 0;
};

class ProducerSource final : public Source {
 public:
  ProducerSource(std::unique_ptr<BrickProducer> p, bool instanced) : p_(std::move(p)), instanced_(instanced) {}
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
  std::unique_ptr<BrickProducer> p_;
  bool instanced_;
  uint64_t produced_ = 0;
};

}  // namespace

std::unique_ptr<Source> make_source(const RenderContext& ctx, const GigaVoxelsParams& p) {
  if (p.source == 1) return std::make_unique<ProducerSource>(std::make_unique<MengerProducer>(p.menger_brick), true);
  return dispatch_value_type(ctx.bricks().shape().type, [&](auto stored) -> std::unique_ptr<Source> {
    using Stored = decltype(stored);
    if (p.source == 2) return std::make_unique<AmplifiedSource<Stored>>(ctx, p);
    return std::make_unique<StoreSource<Stored>>(ctx);
  });
}

}  // namespace brickyard::gigavoxels
