#pragma once
/// @file render_session.h
/// @brief A scene ready to render: the one layer that composes store -> cache -> back end. It
/// opens the scene's dataset (a store), builds the page cache over it (and the grid's typed
/// brick view), the RenderContext, and the one back end the scene names, and nothing else.
///
/// Ownership and lifetimes. A RenderSession owns, and destroys in reverse order: the Store
/// (the dataset and its views), the PageCache and BrickCache, the RenderContext, the back end.
/// - store() is valid for the session's whole life; dataset() and context() too, but for a grid
///   of several time steps, whose frame of another step than the last one's replaces them (with
///   the cache and back end: a new step is new data, cold): reset_cache() keeps the same Store
///   and RenderContext (the context is re-pointed at the new cache).
/// - pages(), bricks() and everything the back end holds are replaced by reset_cache(): a
///   reference taken before it must not be used after it. Take them again.
/// - Handles from the cache must be released before reset_cache() and before the session ends.
/// Not thread-safe: one thread drives a session (the back end uses threads inside a frame).

#include <map>
#include <memory>
#include <optional>
#include <string>

#include "renderers/common/render.h"
#include "renderers/common/renderer.h"
#include "storage/store.h"

namespace brickyard {

class RenderSession {
 public:
  struct Options {
    std::string backend;                      ///< "" : the scene's
    std::map<std::string, double> params;     ///< override or add to the scene's parameters
    std::optional<CacheConfig> cache;         ///< unset: from the scene's budgets
    const BackendRegistry* registry = nullptr; ///< null: backends(), the built-in and loaded ones
  };

  /// @throws Error naming the store or the back end; a kind, mode, view or normal method the
  /// back end does not have names the scene's key (or the dataset), before any frame.
  RenderSession(const Scene& scene, const Options& options);
  RenderSession(const Scene& scene) : RenderSession(scene, Options{}) {}
  ~RenderSession();
  RenderSession(const RenderSession&) = delete;
  RenderSession& operator=(const RenderSession&) = delete;

  const Scene& scene() const { return scene_; }
  const BackendInfo& backend() const { return entry_->info; }
  const BackendParams& params() const { return params_; }
  const Store& store() const { return *store_; }
  /// @brief The dataset shown: for a grid of several time steps, the step of the last frame
  /// (before any, the scene's time_step).
  const Dataset& dataset() const { return store_->dataset(step_); }
  const RenderContext& context() const { return *context_; }
  /// @brief The cache, until the next reset_cache().
  PageCache& pages() { return *pages_; }
  /// @brief The grid's bricks in the cache, until the next reset_cache(). @throws
  /// Error(unsupported) for a dataset without a grid.
  BrickCache& bricks() { return context_->bricks(); }

  /// @brief The camera of frame f, in world coordinates.
  Camera camera(int frame) const;
  /// @brief What render(frame) renders: the scene's camera for the frame, its image size.
  FrameSetup setup(int frame, const FrameOutputs& outputs = {}) const;
  FrameStats render(int frame, FrameBuffers& out, const FrameOutputs& outputs = {});
  /// @brief Renders a frame set up by the caller (a camera in world coordinates that the
  /// scene's normalised cameras cannot place: tests, tools).
  FrameStats render(const FrameSetup& setup, FrameBuffers& out);
  /// @brief Drops every cached page (a new cache and back end): the next frame is cold.
  void reset_cache();
  /// @brief Whether the back end's last frame was complete (see Renderer::converged()).
  bool converged() const;
  /// @brief The most frames settle() renders by default before it gives up on converging.
  static constexpr int kMaxSettleFrames = 500;
  /// @brief How settle() renders the frames before the converged one.
  enum class Settle {
    refine,    ///< as they would be shown: the frames taken are the frames to converge
    complete,  ///< none is shown: each may be completed at once (Renderer::set_complete_frames)
  };
  /// @brief Renders frame `frame` repeatedly, letting the loader serve each frame's requests,
  /// until the back end converges (at most max_frames); returns the frames it took. With
  /// Settle::complete, frames are completed at once until one converges, then rendered as
  /// they would be shown until one of those converges too (usually the next): the count is
  /// then not the frames a viewer would see converge.
  int settle(int frame, const FrameOutputs& outputs, int max_frames = kMaxSettleFrames, Settle how = Settle::refine);
  int settle(const FrameSetup& setup, int max_frames = kMaxSettleFrames, Settle how = Settle::refine);
  /// @brief Renders complete frames (none is shown: Renderer::set_complete_frames), letting the
  /// loader serve each one's requests, until one converges (at most max_frames); `out` holds
  /// the last. Returns the frames it took: the wait for a still camera's converged image.
  int complete(const FrameSetup& setup, FrameBuffers& out, int max_frames = kMaxSettleFrames);

 private:
  void build_cache();
  /// Replaces the cache, context and back end by ones over time step `step` of a grid series.
  void show_step(int step);
  /// show_step(step) where the dataset is a grid and the step is not the one shown.
  void follow_step(int step);

  Scene scene_;
  Options options_;
  const BackendEntry* entry_ = nullptr;
  BackendParams params_;
  std::unique_ptr<Store> store_;
  int step_ = 0;  ///< a grid's time step that the cache, context and back end hold
  std::unique_ptr<PageCache> pages_;
  std::unique_ptr<BrickCache> bricks_;
  std::unique_ptr<RenderContext> context_;
  std::unique_ptr<Renderer> renderer_;
};

/// @brief The cache configuration a scene asks for.
CacheConfig cache_config(const Scene& scene);
/// @brief `c` with its L1 budget shared with a back end that keeps its own brick pool
/// (BackendInfo::l1_staging_slots): the cache's L1 holds only the slots that back end stages
/// through, at most a quarter of the budget, under LRU; CacheConfig::backend_pool_bytes is the
/// rest. Other back ends' configurations are unchanged.
CacheConfig share_l1_budget(CacheConfig c, size_t brick_bytes, const BackendInfo& info, const BackendParams& params);

}  // namespace brickyard
