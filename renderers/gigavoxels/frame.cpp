// The frame, its passes and the loader of gigavoxels (renderer.h): a frame's setup, the
// pass loop's questions (another_pass, converged) and statistics, and between passes the
// loader, which compacts the rays' feedback and serves it within the per-frame budgets:
// uploads of bricks into the pool (with the bounds rays leap by) and subdivisions.

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/timing.h"
#include "core/units.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/gigavoxels/renderer.h"

namespace brickyard::gigavoxels {

template <typename Voxel>
GigaVoxelsRenderer<Voxel>::GigaVoxelsRenderer(const RenderContext& ctx, const GigaVoxelsParams& p, std::unique_ptr<Source> source)
    : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), p_(p), shading_(scene_.shading, geo_), source_(std::move(source)),
      tree_(source_->arity(), node_blocks(ctx, p, *source_), brick_slots(ctx, p, *source_), source_->brick_size()),
      pool_(make_pool_array<Voxel>(size_t(tree_.brick_capacity()) * tree_.brick_values())) {
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
  // A store's levels halve every axis alike, so on a very anisotropic one the coarse levels
  // have collapsed its short axes (3x3x300: 2x2x150, 1x1x75, ...) and hold nothing of the data
  // across them: footprints go no coarser than the voxels of the coarsest depth that resolves
  // every axis, so that neither a descent nor a sample's level or step goes past it (a node
  // above it asks to be subdivided). A power of two, so a descent stops exactly at that depth.
  if (p.source != 1)
    if (const int d = layout.coarsest_resolving(); d > 0) max_footprint_ = 1.0 / (double(m_) * double(int64_t(1) << d));
  if (p.source != 1) wide_values_ = needs_wide_interpolation(ctx.bricks().grid());
  scales_ = node_scales(n_, source_->max_depth() + 1);
  for (const Scale& sc : scales_) inv_scales_.push_back(1.0 / sc.hi);
  if (p.source == 1) outside_value_ = 0.0f;
  if (scene_.mode == RenderMode::dvr) preintegrated_ = PreintegratedTf(scene_.transfer_function);
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

template <typename Voxel>
void GigaVoxelsRenderer<Voxel>::begin_frame(const FrameSetup& setup) {
  ++frame_;
  passes_ = 0;
  interrupted_ = 0;
  rays_cut_short_ = 0;
  out_of_passes_ = false;
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
    uses_ = std::make_unique<UseBuffer>(setup.width, setup.height, p_.slots_per_pixel);
  uses_->begin_frame(frame_);
  states_.assign(size_t(setup.width) * size_t(setup.height), RayState{});
  frame_exact_ = p_.exact || complete_frames_;
  allow_interrupt_ = frame_exact_;
  const double pixel_angle = 2 * std::tan(setup.camera.fov_degrees * kPi / 360.0) / double(setup.height);
  footprint_per_t_ = pixel_angle / geo_.voxel_size / extent_ * lod_ratio_;
}

template <typename Voxel>
void GigaVoxelsRenderer<Voxel>::end_frame(const FrameSetup& setup, const FrameBuffers& out) {
  (void)setup, (void)out;
  ++passes_;
  Stopwatch watch;
  serve_feedback();
  loader_seconds_ += watch.seconds();
}

template <typename Voxel>
bool GigaVoxelsRenderer<Voxel>::another_pass() {
  if (!frame_exact_) return false;
  interrupted_ = 0;
  for (const RayState& s : states_) interrupted_ += s.status == RayState::interrupted;
  if (interrupted_ == 0) return false;
  // A pass that served nothing cannot make progress: the rest of the frame takes coarser data.
  if (allow_interrupt_ && (last_pass_progress_ == 0 || passes_ >= uint64_t(p_.max_passes))) {
    allow_interrupt_ = false;
    rays_cut_short_ = interrupted_;
    out_of_passes_ = last_pass_progress_ != 0;
  }
  uses_->begin_frame(frame_);
  tree_.begin_feedback(frame_);
  return true;
}

template <typename Voxel>
void GigaVoxelsRenderer<Voxel>::add_statistics(FrameStats& stats) const {
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
  // Below the quality asked: what was refused for want of room in the pools, and exact mode's
  // rays that stopped waiting (a frame still refining as bricks arrive is not).
  if (const uint64_t refused = tree_.counters().failed_allocations - failed_before_)
    stats.add_below_quality(fmt::format("gigavoxels' pools held back refinement: allocations refused {} times, all {} brick "
                                        "slots or all {} node blocks in use this frame (cache.l1)",
                                        refused, tree_.brick_capacity(), tree_.block_capacity()));
  if (rays_cut_short_)
    stats.add_below_quality(fmt::format("gigavoxels' exact mode {}: rays that took coarser data: {}",
                                        out_of_passes_ ? fmt::format("ran out of passes (max_passes {})", p_.max_passes)
                                                       : std::string("could serve nothing more"),
                                        rays_cut_short_));
}

// --- sizes ----------------------------------------------------------------------------------

template <typename Voxel>
uint32_t GigaVoxelsRenderer<Voxel>::brick_slots(const RenderContext& ctx, const GigaVoxelsParams& p, const Source& s) {
  if (p.brick_slots) return p.brick_slots;
  const uint64_t slot = slot_bytes(s.brick_size(), keeps_differences(ctx, p));
  const uint64_t slots = ctx.backend_pool_bytes() / slot;
  if (slots >= kMinBrickSlots) return uint32_t(std::min<uint64_t>(slots, 1u << 20));
  // Too small: the least L1 budget, in the cache's bricks, whose share leaves the pool
  // kMinBrickSlots (share_l1_budget; unshared, the pool has the whole budget).
  const CacheConfig& c = ctx.pages().config();
  const uint64_t brick_bytes = ctx.bricks().shape().bytes();
  const bool shared = c.backend_pool_bytes.has_value();
  const uint64_t staging = l1_staging_slots(p);
  const auto pool_slots = [&](uint64_t n) { return (n - (shared ? l1_staging_share(staging, n) : 0)) * brick_bytes / slot; };
  uint64_t least = 1;
  while (pool_slots(least) < kMinBrickSlots) ++least;
  const uint64_t given = shared ? uint64_t(c.l1_slots) * brick_bytes + *c.backend_pool_bytes : c.l1_bytes;
  throw Error(Errc::invalid_argument,
              fmt::format("gigavoxels needs an L1 of at least {} bricks ({}) for a brick pool of {} slots{}: cache.l1 holds {} ({})",
                          least, format_bytes(double(least * brick_bytes)), kMinBrickSlots,
                          shared ? " beside the cache's staging slots" : "", given / brick_bytes, format_bytes(double(given))))
      .with_file(ctx.scene().file)
      .with_field("cache.l1");
}

template <typename Voxel>
uint32_t GigaVoxelsRenderer<Voxel>::node_blocks(const RenderContext& ctx, const GigaVoxelsParams& p, const Source& s) {
  return p.node_blocks ? p.node_blocks : 2 * brick_slots(ctx, p, s) + 16;
}

template <typename Voxel>
uint64_t GigaVoxelsRenderer<Voxel>::slot_bytes(int m, bool with_differences) {
  const uint64_t e = uint64_t(m + 2);
  return e * e * e * sizeof(Voxel) + group_count(m) + (with_differences ? sizeof(BrickDifferences) : 0);
}

template <typename Voxel>
bool GigaVoxelsRenderer<Voxel>::keeps_differences(const RenderContext& ctx, const GigaVoxelsParams& p) {
  return ctx.scene().mode == RenderMode::iso && search_halvings(ctx.scene(), p) > 0;
}

template <typename Voxel>
double GigaVoxelsRenderer<Voxel>::base_step(const Scene& scene, const GigaVoxelsParams& p) {
  return p.step * (scene.mode == RenderMode::iso ? scene.quality.step_factor : scene.quality.step_factor / scene.sampling_rate);
}

template <typename Voxel>
int GigaVoxelsRenderer<Voxel>::search_halvings(const Scene& scene, const GigaVoxelsParams& p) {
  return p.hidden_crossings > 0 ? p.hidden_crossings + int(std::ceil(std::log2(base_step(scene, p)) - 1e-9)) : 0;
}

template <typename Voxel>
std::vector<Scale> GigaVoxelsRenderer<Voxel>::node_scales(int n, int max_depth) {
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

// --- the loader ---------------------------------------------------------------------------

template <typename Voxel>
void GigaVoxelsRenderer<Voxel>::set_brick_bounds(uint32_t slot) {
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
  chessboard_distances(groups_, distance);
  if (search_hidden_crossings_)  // only the search reads them
    brick_differences_[slot] = brick_differences(v, size_t(e));
}

template <typename Voxel>
Node GigaVoxelsRenderer<Voxel>::node_for(const NodeContent& c, int depth) const {
  if (c.kind == NodeContent::constant) return Node::make_constant(c.value);
  return Node::make_data(depth >= source_->max_depth());
}

template <typename Voxel>
Source::Fill GigaVoxelsRenderer<Voxel>::upload(uint32_t address, bool wait) {
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
  if (filled == Source::Fill::failed) damaged_.insert({a.depth, a.x, a.y, a.z});
  if (filled != Source::Fill::filled) return filled;
  const uint32_t slot = tree_.allocate_brick(address);
  if (slot == kNoAddress) return Source::Fill::missing;
  std::transform(scratch_.begin(), scratch_.end(), pool_.get() + size_t(slot) * tree_.brick_values(),
                 [](float v) { return Voxel(v); });  // exact: the values came from Voxel (or are float)
  set_brick_bounds(slot);
  if (const uint64_t id = source_->shared_id(a)) {
    tree_.keep_brick(slot);
    shared_[id] = slot;
  }
  ++frame_uploads_;
  return Source::Fill::filled;
}

template <typename Voxel>
void GigaVoxelsRenderer<Voxel>::serve_feedback() {
  const CompactionReport report = compactor_.compact(*uses_, used_list_, request_list_);
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
  // The nodes are listed first and served after, so that a blocking pass (exact mode) can
  // have all their bricks read side by side (Source::read_ahead).
  std::vector<uint32_t>& wanted = wanted_bricks_;
  wanted.clear();
  for (uint32_t e : request_list_) {
    const uint32_t address = e & kAddressMask;
    const Node n = tree_.node(address);
    if (!(e & kWantsBrick) || n.has_brick() || n.constant() || transit_addresses_.contains(address)) continue;
    wanted.push_back(address);
  }
  for (uint32_t e : request_list_) {
    const uint32_t address = e & kAddressMask;
    const Node n = tree_.node(address);
    if (!(e & kWantsSubdivision) || n.has_children() || n.max_refined() || n.constant()) continue;
    if (subdivisions >= p_.subdivide_budget) break;
    const uint32_t base = tree_.subdivide(address);
    if (base == kNoAddress) continue;
    ++subdivisions, ++frame_subdivisions_, ++last_pass_progress_;
    for (int i = 0; i < tree_.block_nodes(); ++i) {
      const NodeAddress a = tree_.address_of(base + uint32_t(i));
      tree_.set_node(base + uint32_t(i), node_for(source_->classify(a), a.depth));
      // The children's bricks come with the subdivision when the data is at hand; the rest
      // are requested now and copied when they arrive.
      if (!tree_.node(base + uint32_t(i)).constant()) wanted.push_back(base + uint32_t(i));
    }
  }
  if (wait && uploads < p_.upload_budget) {  // the ones the budget serves, each once
    std::vector<uint32_t> ahead(wanted.begin(), wanted.begin() + std::ptrdiff_t(std::min(wanted.size(), size_t(p_.upload_budget - uploads))));
    std::sort(ahead.begin(), ahead.end());
    ahead.erase(std::unique(ahead.begin(), ahead.end()), ahead.end());
    read_ahead_.clear();
    for (uint32_t address : ahead) read_ahead_.push_back(tree_.address_of(address));
    source_->read_ahead(read_ahead_);
  }
  for (uint32_t address : wanted) {
    if (uploads >= p_.upload_budget) break;
    const Node n = tree_.node(address);
    if (n.has_brick() || n.constant() || transit_addresses_.contains(address)) continue;  // listed twice, or shared
    loading += serve(address) == Source::Fill::requested;
  }
  // A load asked for is not a stall: it arrives in a later frame. Unless nothing has for
  // kTransitFrames (a brick that never becomes resident must not keep the frame unconverged).
  if (passes_ == 1) {
    frames_loading_ = last_pass_progress_ > 0 || loading == 0 ? 0 : frames_loading_ + 1;
    const bool progress = last_pass_progress_ > 0 || (loading > 0 && frames_loading_ <= int(kTransitFrames));
    stalled_frames_ = progress || request_list_.empty() ? 0 : stalled_frames_ + 1;
  }
}

// The class and every member defined so far; render_tile is descent.cpp's.
#define BRICKYARD_GIGAVOXELS_RENDERER(V) template class GigaVoxelsRenderer<V>;
BRICKYARD_GIGAVOXELS_FOR_VOXELS(BRICKYARD_GIGAVOXELS_RENDERER)
#undef BRICKYARD_GIGAVOXELS_RENDERER

}  // namespace brickyard::gigavoxels
