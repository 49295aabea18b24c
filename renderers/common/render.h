#pragma once
/// @file render.h
/// @brief Rendering a scene: open its store, build its cache and the one back end it names
/// (and nothing else), and render frames in parallel over image tiles.

#include <map>
#include <memory>
#include <optional>
#include <string>

#include "renderers/common/renderer.h"

namespace brickyard {

inline constexpr int kTileSize = 16;

/// @brief Renders one frame with `renderer`: cache.frame_begin(), begin_frame(), tiles in
/// parallel (TBB), end_frame(), cache.frame_end(). Fills `out` (allocated here) and returns
/// the frame's statistics.
FrameStats render_frame(Renderer& renderer, const RenderContext& context, const FrameSetup& setup, FrameBuffers& out);

/// @brief A scene ready to render: its store, its cache, its back end.
class RenderSession {
 public:
  struct Options {
    std::string backend;                      ///< "" : the scene's
    std::map<std::string, double> params;     ///< override or add to the scene's parameters
    std::optional<CacheConfig> cache;         ///< unset: from the scene's budgets
    const BackendRegistry* registry = nullptr; ///< null: builtin_backends()
  };

  /// @throws Error naming the store or the back end; DataKind/mode mismatches name the key.
  RenderSession(const Scene& scene, const Options& options);
  RenderSession(const Scene& scene) : RenderSession(scene, Options{}) {}
  ~RenderSession();

  const Scene& scene() const { return scene_; }
  const BackendInfo& backend() const { return entry_->info; }
  const BackendParams& params() const { return params_; }
  BrickCache& cache() { return *cache_; }
  const BrickStore& store() const { return *store_; }
  const RenderContext& context() const { return *context_; }

  /// @brief The camera of frame f, in world coordinates.
  Camera camera(int frame) const;
  FrameStats render(int frame, FrameBuffers& out, const FrameOutputs& outputs = {});
  /// @brief Drops every cached brick (a new cache and back end): the next frame is cold.
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

 private:
  void build();

  Scene scene_;
  Options options_;
  const BackendEntry* entry_ = nullptr;
  BackendParams params_;
  std::unique_ptr<BrickStore> store_;
  std::unique_ptr<BrickCache> cache_;
  std::unique_ptr<RenderContext> context_;
  std::unique_ptr<Renderer> renderer_;
};

/// @brief The cache configuration a scene asks for.
CacheConfig cache_config(const Scene& scene);
/// @brief `c` with its L1 budget shared with a back end that keeps its own brick pool
/// (BackendInfo::l1_staging_slots): the cache's L1 holds only the slots that back end stages
/// through, at most a quarter of the budget, under LRU; CacheConfig::backend_pool_bytes is the
/// rest. Other back ends' configurations are unchanged.
CacheConfig share_l1_budget(CacheConfig c, const BrickFormat& format, const BackendInfo& info, const BackendParams& params);

}  // namespace brickyard
