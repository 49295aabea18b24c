// `gobbetti`: single-pass out-of-core ray casting after Gobbetti, Marton and Iglesias Guitian
// (2008), on the CPU, keeping the GPU design: the L1 pool is the "GPU texture cache", the L2
// host cache the "CPU cache", the store the out-of-core brick octree.
//
// Per frame (begin_frame, one thread):
//   1. Refine a cut of the brick octree from the root, largest projected voxel first. Leaves
//      are nodes that are empty for this scene (isovalue outside the node's range, zero opacity
//      by the transfer function's summed-area table), outside the frustum, adequate (a voxel
//      covers at most lod_ratio pixels, at a level that still resolves every axis: on a very
//      anisotropic grid the coarse levels have collapsed its short axes, dataset/grid.h),
//      occluded in the last query (visibility feedback), or
//      whose children are not resident yet: then requests are posted (within the per-frame
//      upload budget) and refinement goes on elsewhere; it never waits. The cut never holds
//      more data leaves than the L1 pool has slots.
//   2. Rebuild the spatial index from the cut (octree with neighbour links; spatial_index.h).
// Per tile (many threads): stackless traversal of the index, sampling each leaf's brick with a
// step matched to its level and opacity corrected per level (a transfer-function table per
// level), isosurface bracketing and bisection, or DVR with early termination.
// After the frame (end_frame): occlusion queries of the cut's leaf boxes against the frame's
// depth of opacity, for one group of screen tiles per frame, propagated to parents, recorded
// through the cache's visibility feedback.

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <queue>
#include <unordered_map>

#include <fmt/format.h>

#include "core/timing.h"
#include "renderers/common/cell_accessor.h"
#include "renderers/common/cubic.h"
#include "renderers/common/params.h"
#include "renderers/common/pixel.h"
#include "renderers/common/renderer.h"
#include "renderers/common/shading.h"
#include "renderers/gobbetti/spatial_index.h"

namespace brickyard {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr uint32_t kEmptyLeaf = 0xffffffffu;   // nothing to sample
constexpr uint32_t kConstantLeaf = 0x80000000u; // | index into the frame's constants
constexpr int32_t kNoData = -1;                 // a node's handle: no brick at hand
constexpr int32_t kDamaged = -2;                // acquire(): the brick cannot be read

struct GobbettiParams {
  double lod_ratio{};     // 0: the scene's quality.lod_ratio
  double step{};          // in voxels of the leaf's level
  int upload_budget{};    // new brick requests per frame
  bool visibility{};
  int visibility_pixels{};
  int visibility_groups{};  // screen-tile groups: every node is queried within this many frames
  int refine{};           // bisection steps refining an isosurface crossing
};

const ParamTable<GobbettiParams>& gobbetti_params() {
  using P = GobbettiParams;
  static const ParamTable<P> table{
      {"lod_ratio", &P::lod_ratio, 0, 0, 1000, "target pixels per voxel; 0: the scene's quality.lod_ratio"},
      {"step", &P::step, 0.5, 1e-3, 16,
       "sampling step in voxels of each leaf's level (times quality.step_factor; DVR: / sampling_rate)"},
      {"upload_budget", &P::upload_budget, 256, 1, 1e6, "new brick requests per frame"},
      {"visibility", &P::visibility, 1, 0, 1, "1: visibility feedback (occluded nodes are not refined)"},
      {"visibility_pixels", &P::visibility_pixels, 4, 1, 1e6, "pixels in front of the depth buffer that make a node visible"},
      {"visibility_groups", &P::visibility_groups, 4, 1, 64,
       "screen-tile groups: each frame queries one, all nodes within this many frames"},
      {"refine", &P::refine, 6, 0, 40, "bisection steps refining an isosurface crossing"},
  };
  return table;
}

template <typename Stored>
class GobbettiRenderer final : public Renderer {
 public:
  GobbettiRenderer(const RenderContext& ctx, const GobbettiParams& p)
      : ctx_(ctx), scene_(ctx.scene()), geo_(ctx.geometry()), layout_(ctx.layout()), p_(p), shading_(scene_.shading, geo_) {
    lod_ratio_ = p.lod_ratio > 0 ? p.lod_ratio : scene_.quality.lod_ratio;
    coarsest_level_ = layout_.coarsest_resolving();
    wide_values_ = needs_wide_interpolation(ctx.bricks().grid());
    clip_world_ = Box3d(geo_.to_world(geo_.voxel_clip.lo), geo_.to_world(geo_.voxel_clip.hi));
    M_ = layout_.brick_size;
    A_ = ctx.bricks().shape().apron;
    E_ = ctx.bricks().shape().edge();
    if (A_ < 1)
      throw Error(Errc::unsupported, "gobbetti samples bricks through their apron: the store needs an apron of at least 1")
          .with_file(ctx.dataset().name);
    const double factor = scene_.mode == RenderMode::iso ? scene_.quality.step_factor
                                                         : scene_.quality.step_factor / scene_.sampling_rate;
    for (int l = 0; l < layout_.levels; ++l) {
      const double step_finest = p.step * factor * double(int64_t(1) << layout_.steps(l));
      step_by_level_.push_back(step_finest);
      if (scene_.mode == RenderMode::dvr) tf_by_level_.emplace_back(scene_.transfer_function, step_finest);
    }
  }

  // --- per frame: refinement and the spatial index ---------------------------------------
  void begin_frame(const FrameSetup& setup) override {
    Stopwatch watch;
    ++frame_;
    refine(setup);
    refine_seconds_ = watch.seconds();
    watch.restart();
    index_.build(layout_, leaves_);
    index_seconds_ = watch.seconds();
    if (occlusion_.width() != setup.width || occlusion_.height() != setup.height)
      occlusion_ = FloatImage(setup.width, setup.height);
  }

  void render_tile(const FrameSetup& setup, const Tile& tile, FrameBuffers& out, RayCounters& counters) const override {
    Tracer t(*this, setup, counters);
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) t.pixel(x, y, out);
  }

  void end_frame(const FrameSetup& setup, const FrameBuffers& out) override {
    (void)out;
    Stopwatch watch;
    if (p_.visibility) query_visibility(setup);
    visibility_seconds_ = watch.seconds();
    // The cut stays pinned until the next one is built: uploads between frames go to the
    // slots it does not use, never evicting the working set or the top of the tree.
  }

  void add_statistics(FrameStats& stats) const override {
    stats.add_phase("refine", refine_seconds_);
    stats.add_phase("index", index_seconds_);
    stats.add_phase("visibility", visibility_seconds_);
    stats.backend = {{"leaves", double(leaves_.size())},
                     {"working_set", double(data_leaves_)},
                     {"constant_leaves", double(constant_leaves_)},
                     {"empty_leaves", double(leaves_.size() - data_leaves_ - constant_leaves_)},
                     {"index_nodes", double(index_.node_count())},
                     {"deferred_refinements", double(deferred_)},
                     {"occluded_not_refined", double(occluded_)},
                     {"pool_full_not_refined", double(pool_full_)},
                     {"damaged_stood_in_for", double(damaged_)},
                     {"requests_posted", double(requests_)},
                     {"visibility_queries", double(queries_)},
                     {"refine_ms", refine_seconds_ * 1e3},
                     {"index_ms", index_seconds_ * 1e3},
                     {"visibility_ms", visibility_seconds_ * 1e3}};
    if (pool_full_)  // the cut stops short of the level of detail asked for, however long it waits
      stats.add_below_quality(fmt::format("gobbetti's cut was held back by the L1 pool: no room in its {} slots (cache.l1) to "
                                          "refine {} of its nodes",
                                          ctx_.bricks().pool_slots(), pool_full_));
  }

  bool converged() const override { return deferred_ == 0 || stalled_frames_ >= 3; }

 private:
  struct Candidate {
    double pixels;  // projected size of one of the node's voxels
    BrickKey key;
    int32_t handle;  // index into handles_, -1 for none
    bool operator<(const Candidate& o) const { return pixels < o.pixels; }
  };

  Box3d world_box(const BrickKey& k) const { return ctx_.grid().brick_world_box(k); }
  double voxel_pixels(const BrickKey& k, const Camera& cam, int height) const {
    return ctx_.grid().brick_voxel_pixels(cam, k, world_box(k), height);
  }
  bool was_visible(const BrickKey& k) const {
    if (!p_.visibility) return true;
    const std::optional<bool> v = ctx_.bricks().visibility(k);
    return !v || *v;
  }

  /// What a node of the cut is for this frame, when it is a leaf.
  enum class NodeUse { empty, constant, data };
  NodeUse use_of(const BrickKey& k, const Camera& cam, int width, int height) const {
    if (!ctx_.bricks().layout().contains(k)) return NodeUse::empty;
    const NodeRecord& n = ctx_.nodes().at(k);
    if (!ctx_.subtree_visible(k)) return NodeUse::empty;  // its own level's range can miss finer detail
    const Box3d box = world_box(k);
    if (!cam.may_see(box, width, height)) return NodeUse::empty;
    if (scene_.clip && !box.overlaps(clip_world_)) return NodeUse::empty;
    return n.is_constant() ? NodeUse::constant : NodeUse::data;
  }

  void add_leaf(const BrickKey& k, NodeUse use, int32_t handle) {
    uint32_t payload = kEmptyLeaf;
    if (use == NodeUse::constant) {
      payload = kConstantLeaf | uint32_t(constants_.size());
      constants_.push_back(ctx_.nodes().at(k).constant);
      ++constant_leaves_;
    } else if (use == NodeUse::data && handle >= 0) {
      payload = uint32_t(handle);
      ++data_leaves_;
    }
    leaves_.push_back({k, payload});
  }

  void refine(const FrameSetup& setup) {
    BrickCache& cache = ctx_.bricks();
    const Camera& cam = setup.camera;
    // The previous cut stays pinned while this one is built (see end_frame()).
    std::vector<BrickHandle> previous = std::move(handles_);
    handles_.clear();
    leaves_.clear();
    inner_.clear();
    constants_.clear();
    data_leaves_ = constant_leaves_ = 0;
    deferred_ = occluded_ = requests_ = pool_full_ = damaged_ = 0;
    int budget = p_.upload_budget;
    // The cut keeps a quarter of the pool free: room for the loader's uploads and for the
    // uneven fill of the pool's shards, so that a full cut still lets new bricks in.
    const uint32_t capacity = cache.pool_slots() - cache.pool_slots() / 4;
    uint32_t pinned = 0;

    // Asks for a node's brick: a pinned handle when resident, else a request (budget allowing);
    // kDamaged for one that cannot be read, never asked for again.
    auto acquire = [&](const BrickKey& k, double pixels) -> int32_t {
      BrickHandle h = cache.lookup(k, float(pixels), /*request_on_miss=*/false);
      if (h.failed()) {
        ++damaged_;
        return kDamaged;
      }
      if (h.resident()) {
        handles_.push_back(std::move(h));
        ++pinned;
        return int32_t(handles_.size() - 1);
      }
      // The bricks pinned (by this cut, and by the last one, which the uploads must leave alone)
      // plus those asked for must fit the pool, or uploads would fail for want of a free slot.
      if (budget > 0 && pinned + requests_ < capacity && last_pinned_ + requests_ < capacity) {
        cache.request(k, float(pixels));
        --budget;
        ++requests_;
      }
      return -1;
    };

    std::priority_queue<Candidate> queue;
    const BrickKey root{0, 0, 0, 0};
    const NodeUse root_use = use_of(root, cam, setup.width, setup.height);
    if (root_use != NodeUse::data) {
      add_leaf(root, root_use, -1);
      return;
    }
    const double root_pixels = voxel_pixels(root, cam, setup.height);
    int32_t root_handle = acquire(root, root_pixels);
    if (root_handle == kDamaged) root_handle = kNoData;  // refined below: its children may be readable
    else if (root_handle < 0) {  // nothing to draw until the root arrives
      ++deferred_;
      add_leaf(root, NodeUse::empty, -1);
      return;
    }
    queue.push({root_pixels, root, root_handle});
    struct Child {
      BrickKey key;
      NodeUse use;
      double pixels;
      int32_t handle;
      bool stand_in = false;  // handle is an ancestor's: the child's brick cannot be read
    };
    std::vector<Child> children;
    while (!queue.empty()) {
      const Candidate n = queue.top();
      queue.pop();
      // A level above coarsest_level_ is refined however small its voxels look: it has
      // collapsed an axis (a 3x3x300 grid's 1x1x75 level drew nothing).
      // So is a node no readable brick stands in for (a damaged root): below it is data.
      const bool wants = int(n.key.level) < layout_.finest() &&
                         (n.pixels > lod_ratio_ || int(n.key.level) < coarsest_level_ || n.handle == kNoData);
      if (!wants) {
        add_leaf(n.key, NodeUse::data, n.handle);
        continue;
      }
      if (!was_visible(n.key)) {  // occluded in the last query: coarse data is enough
        ++occluded_;
        add_leaf(n.key, NodeUse::data, n.handle);
        continue;
      }
      // Refine only when every child that needs data is resident and the pool has room.
      children.clear();
      bool ready = true;
      uint32_t needed = 0;
      for (int c = 0; c < 8; ++c) {
        const BrickKey k = n.key.child(c);
        if (!layout_.contains(k)) continue;  // outside the volume: the index marks it
        const NodeUse use = use_of(k, cam, setup.width, setup.height);
        Child child{k, use, 0, -1};
        if (use == NodeUse::data) {
          ++needed;
          child.pixels = voxel_pixels(k, cam, setup.height);
        }
        children.push_back(child);
      }
      if (pinned + needed > capacity) {
        ++pool_full_;  // no room: adequate as far as this pool goes (not waiting for anything)
        add_leaf(n.key, NodeUse::data, n.handle);
        continue;
      }
      if (ready)
        for (Child& c : children)
          if (c.use == NodeUse::data) {
            c.handle = acquire(c.key, c.pixels);
            if (c.handle == kDamaged) c.handle = n.handle, c.stand_in = true;  // the nearest readable level above
            ready &= c.handle >= 0 || c.stand_in;
          }
      if (!ready) {
        ++deferred_;
        for (Child& c : children)
          if (c.handle >= 0 && !c.stand_in) {
            handles_[size_t(c.handle)].release();
            --pinned;
          }
        add_leaf(n.key, NodeUse::data, n.handle);
        continue;
      }
      inner_.push_back(n.key);  // stays pinned: next frame's refinement starts from it
      for (const Child& c : children) {
        if (c.use == NodeUse::data) queue.push({c.pixels, c.key, c.handle});
        else add_leaf(c.key, c.use, -1);
      }
    }
    // Usage feedback (protects the cut under lru-frame), then the previous cut's pins go.
    for (const BrickKey& k : inner_) cache.mark_used(k);
    for (const auto& leaf : leaves_)
      if (leaf.payload != kEmptyLeaf && !(leaf.payload & kConstantLeaf)) cache.mark_used(leaf.key);
    for (BrickHandle& h : previous) h.release();
    last_pinned_ = pinned;  // what the cut holds: the next frame's requests must fit beside it
    // A cut that waits while nothing arrives is stalled (the pool cannot take what it asks for,
    // or the requests cannot be posted for want of room): as converged as this pool allows.
    const uint64_t uploads = cache.stats().uploads;
    stalled_frames_ = uploads == last_uploads_ ? stalled_frames_ + 1 : 0;
    last_uploads_ = uploads;
    // Data pointers of the leaves, read by the render threads.
    data_.assign(handles_.size(), nullptr);
    data_keys_.resize(handles_.size());
    for (size_t i = 0; i < handles_.size(); ++i) {
      if (handles_[i].resident()) data_[i] = handles_[i].template voxels<Stored>();
      data_keys_[i] = handles_[i].key();
    }
  }

  // --- visibility feedback -----------------------------------------------------------------
  /// Screen rectangle [x0, x1) x [y0, y1) covering a world box; false when the box reaches
  /// behind the eye (then it is treated as visible).
  bool screen_rect(const Camera& cam, const Box3d& box, int w, int h, int r[4]) const {
    Vec3d f, right, up;
    cam.basis(f, right, up);
    const double ty = std::tan(cam.fov_degrees * kPi / 360.0), tx = ty * double(w) / double(h);
    double x0 = kInf, y0 = kInf, x1 = -kInf, y1 = -kInf;
    for (int c = 0; c < 8; ++c) {
      const Vec3d p{c & 1 ? box.hi.x : box.lo.x, c & 2 ? box.hi.y : box.lo.y, c & 4 ? box.hi.z : box.lo.z};
      const Vec3d v = p - cam.eye;
      const double z = dot(v, f);
      if (z <= 1e-9) return false;
      const double sx = dot(v, right) / (z * tx), sy = dot(v, up) / (z * ty);
      const double px = (sx + 1) * 0.5 * w, py = (1 - sy) * 0.5 * h;
      x0 = std::min(x0, px), x1 = std::max(x1, px), y0 = std::min(y0, py), y1 = std::max(y1, py);
    }
    r[0] = std::clamp(int(std::floor(x0)), 0, w);
    r[1] = std::clamp(int(std::floor(y0)), 0, h);
    r[2] = std::clamp(int(std::ceil(x1)), 0, w);
    r[3] = std::clamp(int(std::ceil(y1)), 0, h);
    return true;
  }

  void query_visibility(const FrameSetup& setup) {
    BrickCache& cache = ctx_.bricks();
    const Camera& cam = setup.camera;
    const int w = setup.width, h = setup.height;
    const ImageRays rays(cam, w, h);
    const int tiles_x = (w + 15) / 16;
    const int group = int(frame_ % uint64_t(std::max(1, p_.visibility_groups)));
    queries_ = 0;
    struct Verdict {
      bool visible;
      int64_t in_front;  // pixels in front of the depth buffer, counted up to visibility_pixels
    };
    std::vector<std::pair<BrickKey, Verdict>> known;  // this frame's verdicts on the cut's leaves
    for (const auto& leaf : leaves_) {
      if (leaf.payload == kEmptyLeaf) continue;
      const Box3d box = world_box(leaf.key);
      int r[4];
      bool visible = true;
      int64_t in_front = p_.visibility_pixels;
      if (screen_rect(cam, box, w, h, r)) {
        if (r[0] >= r[2] || r[1] >= r[3]) continue;  // off screen: the frustum test decides
        const int cx = (r[0] + r[2]) / 2, cy = (r[1] + r[3]) / 2;
        const int tile = (std::min(cx, w - 1) / 16) + (std::min(cy, h - 1) / 16) * tiles_x;
        if (tile % std::max(1, p_.visibility_groups) != group) continue;  // another frame's query
        ++queries_;
        const int64_t area = int64_t(r[2] - r[0]) * int64_t(r[3] - r[1]);
        const int64_t needed = std::min<int64_t>(p_.visibility_pixels, area);
        in_front = 0;
        for (int y = r[1]; y < r[3] && in_front < needed; ++y)
          for (int x = r[0]; x < r[2] && in_front < needed; ++x) {
            const Rayd ray = rays.ray(x + 0.5, y + 0.5);
            const Interval<double> span = intersect(ray, box);
            if (!span.empty() && std::max(span.t0, 0.0) < double(occlusion_(x, y))) ++in_front;
          }
        visible = in_front >= needed;
      }
      cache.mark_visible(leaf.key, visible);
      known.emplace_back(leaf.key, Verdict{visible, in_front});
    }
    // A parent is visible when any of its children is, or when its children together have
    // visibility_pixels in front of the depth buffer (children too small to pass the threshold
    // alone must not make their parent invisible, or the cut would collapse and refine again
    // frame after frame). Children's verdicts are the latest: this frame's, an earlier frame's
    // for leaves another tile group holds (untested counts as visible), none for empty leaves.
    // Deepest first, so inner children are decided before their parents.
    std::unordered_map<uint64_t, Verdict> verdict;
    for (const auto& leaf : leaves_) {
      const bool visible = leaf.payload != kEmptyLeaf && cache.visibility(leaf.key).value_or(true);
      verdict[leaf.key.code()] = Verdict{visible, visible ? int64_t(p_.visibility_pixels) : 0};
    }
    for (const auto& [key, v] : known) verdict[key.code()] = v;
    std::sort(inner_.begin(), inner_.end(), [](const BrickKey& a, const BrickKey& b) { return a.level > b.level; });
    for (const BrickKey& parent : inner_) {
      Verdict v{false, 0};
      for (int c = 0; c < 8; ++c) {
        const BrickKey child = parent.child(c);
        if (!layout_.contains(child)) continue;
        auto it = verdict.find(child.code());
        if (it == verdict.end()) continue;
        v.visible |= it->second.visible;
        v.in_front += it->second.in_front;
      }
      v.visible |= v.in_front >= p_.visibility_pixels;
      v.in_front = std::min<int64_t>(v.in_front, p_.visibility_pixels);
      verdict[parent.code()] = v;
      cache.mark_visible(parent, v.visible);
    }
  }

  // --- rays ------------------------------------------------------------------------------
  struct Tracer {
    const GobbettiRenderer& r;
    const FrameSetup& setup;
    const ImageRays rays;
    RayCounters& counters;
    const bool gradients;

    Tracer(const GobbettiRenderer& renderer, const FrameSetup& s, RayCounters& c)
        : r(renderer), setup(s), rays(s.camera, s.width, s.height), counters(c), gradients(r.ctx_.needs_gradients(s.outputs)) {}

    /// A data leaf's brick as the ray sees it: the ray in the brick's local coordinates
    /// (level voxels, apron included), l(t) = lo + ld t, sampled in single precision with the
    /// last cell's corners kept (coherent steps usually stay in a cell).
    ///
    /// Points are clamped to the level's voxel centres (inside, first and last), as the
    /// reference clamps them, and cells to those between them: past the volume's faces the
    /// apron only repeats the face's voxels, so a cell reaching into it has no gradient across
    /// the face, and a ray entering there (a point rounded a hair outside) was shaded from a
    /// normal lying in the face.
    struct Brick {
      const Stored* data = nullptr;
      int level = 0;
      int64_t e = 0;
      float inv_scale = 1;  // 1 / 2^steps: finest -> level voxels
      float lo[3] = {}, ld[3] = {};
      float inside_lo[3] = {}, inside_hi[3] = {};  // the level's voxel centres, local
      int64_t cell_lo[3] = {}, cell_hi[3] = {};    // the cells between them
      bool wide = false;                           // needs_wide_interpolation
      mutable int64_t cached = -1;
      mutable float c[8] = {};

      float sample(double t, Vec3d* gradient = nullptr) const {
        int64_t cell[3];
        float u[3];
        for (int a = 0; a < 3; ++a) {
          const float l = std::clamp(lo[a] + ld[a] * float(t), inside_lo[a], inside_hi[a]);
          cell[a] = std::clamp<int64_t>(int64_t(l), cell_lo[a], cell_hi[a]);
          u[a] = l - float(cell[a]);
        }
        const int64_t index = (cell[2] * e + cell[1]) * e + cell[0];
        if (index != cached) {
          const Stored* p = data + index;
          const int64_t dy = e, dz = e * e;
          c[0] = float(p[0]), c[1] = float(p[1]), c[2] = float(p[dy]), c[3] = float(p[dy + 1]);
          c[4] = float(p[dz]), c[5] = float(p[dz + 1]), c[6] = float(p[dz + dy]), c[7] = float(p[dz + dy + 1]);
          cached = index;
        }
        if (gradient) *gradient = Vec3d(trilinear_gradient(c, u[0], u[1], u[2], wide)) * double(inv_scale);
        return trilinear(c, u[0], u[1], u[2], wide);
      }
    };

    Brick brick_of(const gobbetti::LeafVisit& leaf, const PrimaryRay& ray) const {
      Brick b;
      b.data = r.data_[leaf.payload];
      // The brick's own key: a damaged leaf's is an ancestor's (a coarser level stands in).
      const BrickKey& key = r.data_keys_[leaf.payload];
      b.level = int(key.level);
      b.e = r.E_;
      b.wide = r.wide_values_;
      const double inv_scale = 1.0 / double(int64_t(1) << r.layout_.steps(b.level));
      b.inv_scale = float(inv_scale);
      const Vec3s level_dims = r.layout_.level_dims(b.level);
      for (int a = 0; a < 3; ++a) {
        const int64_t offset = key.coords()[a] * r.M_ - r.A_;
        b.lo[a] = float((ray.org[a] + 0.5) * inv_scale - 0.5 - double(offset));
        b.ld[a] = float(ray.dir[a] * inv_scale);
        const int64_t first = std::max<int64_t>(-offset, 0), last = std::min<int64_t>(level_dims[a] - 1 - offset, b.e - 1);
        b.inside_lo[a] = float(first), b.inside_hi[a] = float(last);
        b.cell_lo[a] = first, b.cell_hi[a] = std::max(first, last - 1);
      }
      return b;
    }

    void pixel(int x, int y, FrameBuffers& out) {
      ++counters.rays;
      const PrimaryRay ray = primary_ray(rays, r.geo_, x, y);
      PixelResult px;
      px.color = r.scene_.background;
      double occlusion = kInf;
      if (ray.hits()) {
        if (r.scene_.mode == RenderMode::iso) iso(ray, px, occlusion);
        else dvr(ray, px, occlusion);
      }
      write_pixel(out, x, y, px);
      r.occlusion_(x, y) = float(occlusion);
    }

    Vec3d shade_normal(const Vec3d& gradient_finest, const Vec3d& dir) {
      ++counters.gradients;
      return facing_normal(gradient_finest / r.geo_.spacing, dir);
    }

    void iso(const PrimaryRay& ray, PixelResult& px, double& occlusion) {
      const auto& surfaces = r.scene_.isosurfaces;
      const double speed = length(ray.dir);  // finest voxels per unit t
      double prev_t = 0, prev[4] = {};
      bool have_prev = false;
      double t_next = ray.span.t0;
      double hit_t = kInf;
      int hit_s = -1;
      Brick hit_brick;
      CrossingBracket hit_bracket{hit_t, hit_t, 0, 0};  // a hit not bisected is taken where it is
      r.index_.traverse(ray.org, ray.dir, ray.span.t0, ray.span.t1, [&](const gobbetti::LeafVisit& leaf) {
        ++counters.nodes;
        if (leaf.outside || leaf.payload == kEmptyLeaf) {
          have_prev = false;
          t_next = leaf.tb;
          return true;
        }
        if (leaf.payload & kConstantLeaf) {
          const double c = r.constants_[leaf.payload & ~kConstantLeaf];
          for (size_t s = 0; s < surfaces.size(); ++s)
            if (c == surfaces[s].value) {  // a constant region at the isovalue: the surface starts here
              hit_t = std::max(leaf.ta, ray.span.t0);
              hit_s = int(s);
              return false;
            }
          have_prev = false;
          t_next = leaf.tb;
          return true;
        }
        ++counters.bricks;
        const Brick b = brick_of(leaf, ray);
        const double dt = r.step_by_level_[size_t(b.level)] / speed;
        if (!have_prev) t_next = leaf.ta;
        double t = std::max(t_next, leaf.ta);
        // Fixed steps inside the leaf, then one sample at its exit, so that a crossing in the
        // last part-step is bracketed even when the next leaf is empty.
        for (bool last = false; !last;) {
          if (t >= leaf.tb) {
            if (have_prev && prev_t >= leaf.tb - 1e-9 * dt) break;
            t = leaf.tb;
            last = true;
          }
          ++counters.samples;
          const double v = b.sample(t);
          for (size_t s = 0; s < surfaces.size(); ++s) {
            const double g = v - surfaces[s].value;
            if (!have_prev && g == 0) {  // the ray starts on the surface (or re-enters data on it)
              if (t < hit_t) hit_t = t, hit_s = int(s), hit_brick = b, hit_bracket = {t, t, 0, 0};
            } else if (have_prev && ((prev[s] < 0) != (g < 0) || g == 0)) {
              const double iso = surfaces[s].value;
              CrossingBracket bracket;
              const double th = bisect_crossing(
                  [&](double m) {
                    ++counters.samples;
                    return b.sample(m) - iso;
                  },
                  prev_t, t, prev[s], g, r.p_.refine, &bracket);
              if (th < hit_t) hit_t = th, hit_s = int(s), hit_brick = b, hit_bracket = bracket;
            }
            prev[s] = g;
          }
          prev_t = t;
          have_prev = true;
          if (hit_s >= 0) return false;
          t_next = t + dt;
          t += dt;
        }
        return true;
      });
      if (hit_s < 0) return;
      px.depth = occlusion = hit_t;
      px.alpha = 1;
      px.color = surfaces[size_t(hit_s)].color;
      if (!gradients) return;
      Vec3d g(0.0);
      if (hit_brick.data) {
        g = crossing_gradient(
            [&](double u) {
              Vec3d gu;
              hit_brick.sample(u, &gu);
              return gu;
            },
            hit_t, hit_bracket, ray.dir);
      }
      const Vec3d n = shade_normal(g, ray.world.dir);
      if (setup.outputs.normals) px.normal = n;
      if (!r.shading_.lit()) return;
      double light_distance;
      const Vec3d l = r.shading_.to_light(ray.world.at(hit_t), setup.camera.eye, light_distance);
      px.color = r.shading_.shade(px.color, n, -ray.world.dir, l, false);
    }

    void dvr(const PrimaryRay& ray, PixelResult& px, double& occlusion) {
      const double speed = length(ray.dir);
      const double stop = r.scene_.quality.termination_opacity;
      const bool lit = r.shading_.lit();
      Vec3d accum(0.0);
      double a_acc = 0;
      // The ray is integrated up to `covered`: each sample stands for the step after it and is
      // taken at that step's middle (the midpoint rule, second order in the step, as raymarch's
      // and the reference's samples), in the leaf that holds it; a ray's last step is cut where
      // it leaves the volume and sampled at its own middle.
      double covered = ray.span.t0;
      auto composite = [&](Vec3f c, double a, double t, const Vec3d& gradient) {
        Vec3d n(0.0);
        if (gradients) n = shade_normal(gradient, ray.world.dir);
        if (lit) {
          double light_distance;
          c = r.shading_.shade(c, n, -ray.world.dir, r.shading_.to_light(ray.world.at(t), setup.camera.eye, light_distance), false);
        }
        accum += Vec3d(c) * ((1 - a_acc) * a);
        a_acc += (1 - a_acc) * a;
        if (px.depth == kInf && a_acc >= 0.5) {
          px.depth = t;
          if (setup.outputs.normals) px.normal = n;
        }
      };
      r.index_.traverse(ray.org, ray.dir, ray.span.t0, ray.span.t1, [&](const gobbetti::LeafVisit& leaf) {
        ++counters.nodes;
        if (leaf.outside || leaf.payload == kEmptyLeaf) {
          covered = std::max(covered, leaf.tb);
          return true;
        }
        if (leaf.payload & kConstantLeaf) {
          // A constant region: its emission-absorption integral in closed form, from where the
          // last sample's step ended.
          Vec3f c;
          float a;
          r.scene_.transfer_function.eval(r.constants_[leaf.payload & ~kConstantLeaf], c, a);
          const double from = std::max(leaf.ta, covered);
          const double length_voxels = (leaf.tb - from) * speed;
          if (a > 0 && length_voxels > 0) composite(c, 1 - std::pow(1 - double(a), length_voxels), from, Vec3d(0.0));
          covered = std::max(covered, leaf.tb);
          if (a_acc >= stop) occlusion = leaf.tb;
          return a_acc < stop;
        }
        ++counters.bricks;
        const Brick b = brick_of(leaf, ray);
        const TfTable& tf = r.tf_by_level_[size_t(b.level)];
        const double dt = r.step_by_level_[size_t(b.level)] / speed;
        covered = std::max(covered, leaf.ta);
        while (covered < leaf.tb) {
          double t = covered + 0.5 * dt;
          const double part = std::min(dt, ray.span.t1 - covered);
          if (t >= leaf.tb) {
            if (part >= dt) break;  // the step's middle lies in the next leaf: sampled there
            t = covered + 0.5 * part;  // the ray's last, cut step
          }
          ++counters.samples;
          Vec3d g(0.0);
          const double v = b.sample(t, gradients ? &g : nullptr);
          Vec3f c;
          float a;
          tf.lookup(float(v), c, a);
          if (a > 0 && part < dt) a = float(1 - std::pow(1 - double(a), part / dt));
          if (a > 0) composite(c, a, t, g);
          covered += dt;
          if (a_acc >= stop) {
            occlusion = t;
            return false;
          }
        }
        return true;
      });
      px.color = Vec3f(accum + Vec3d(r.scene_.background) * (1 - a_acc));
      px.alpha = float(a_acc);
    }
  };

  const RenderContext& ctx_;
  const Scene& scene_;
  const VolumeGeometry& geo_;
  const GridLayout& layout_;
  GobbettiParams p_;
  ShadingModel shading_;
  double lod_ratio_ = 1;
  int coarsest_level_ = 0;  // the coarsest level that resolves every axis (GridLayout::coarsest_resolving)
  bool wide_values_ = false;  // needs_wide_interpolation: values near the largest float
  Box3d clip_world_;  // the rendered region in world coordinates
  int64_t M_ = 32, A_ = 1, E_ = 34;
  std::vector<double> step_by_level_;   // sampling step per level, finest voxels
  std::vector<TfTable> tf_by_level_;    // the 2D transfer-function table: opacity corrected per level

  // This frame's cut, written by begin_frame(), read by the render threads.
  uint64_t frame_ = 0;
  std::vector<BrickHandle> handles_;
  std::vector<const Stored*> data_;
  std::vector<BrickKey> data_keys_;  // the key of each of handles_
  std::vector<float> constants_;
  std::vector<gobbetti::CutLeaf> leaves_;
  std::vector<BrickKey> inner_;  // the cut's refined nodes, for visibility propagation
  gobbetti::SpatialIndex index_;
  mutable FloatImage occlusion_;  // where each ray became opaque; pixels are written by one tile each
  uint64_t data_leaves_ = 0, constant_leaves_ = 0, deferred_ = 0, occluded_ = 0, requests_ = 0, queries_ = 0, pool_full_ = 0;
  uint64_t damaged_ = 0;  // nodes of the cut whose brick cannot be read: an ancestor's stands in
  double refine_seconds_ = 0, index_seconds_ = 0, visibility_seconds_ = 0;
  uint64_t last_uploads_ = 0;
  int stalled_frames_ = 0;
  uint32_t last_pinned_ = 0;
};

}  // namespace

BackendEntry gobbetti_backend() {
  BackendEntry e;
  e.info.name = "gobbetti";
  e.info.description = "Gobbetti et al. 2008: adaptive out-of-core refinement of the brick octree, per-frame spatial "
                       "index with neighbour links, stackless traversal, visibility feedback";
  e.info.kinds = {DataKind::structured};
  e.info.modes = {RenderMode::iso, RenderMode::dvr};
  e.info.params = gobbetti_params().declarations();
  e.info.quality_param = "lod_ratio";
  e.info.quality_sweep = {4, 2, 1, 0.5, 0.25};
  e.create = [](const RenderContext& ctx, const BackendParams& p) -> std::unique_ptr<Renderer> {
    const GobbettiParams gp = gobbetti_params().bind(p);
    return dispatch_value_type(ctx.bricks().shape().type, [&](auto stored) -> std::unique_ptr<Renderer> {
      return std::make_unique<GobbettiRenderer<decltype(stored)>>(ctx, gp);
    });
  };
  return e;
}

}  // namespace brickyard
