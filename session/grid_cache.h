#pragma once
/// @file grid_cache.h
/// @brief A grid store's cache as one object, for tools, tests and benchmarks that read bricks
/// without a renderer (`brickyard flight`, the cache's tests): the page cache over the store,
/// and its typed brick view. Renderers get theirs from a RenderSession instead.
///
/// The store must outlive it; members are destroyed in reverse order (the view, then the cache).
/// A caller that reports the cache's trace written calls close() first (see PageCache).

#include "cache/brick_cache.h"
#include "cache/page_cache.h"
#include "storage/store.h"

namespace brickyard {

class GridCache {
 public:
  /// @brief The cache over time step `step` of the store's grid.
  /// @throws Error(unsupported) for a store without a grid; Error(invalid_argument) for a step
  /// it does not have; the cache's errors for its budgets.
  GridCache(const Store& store, const CacheConfig& config, int step = 0)
      : pages_(store.step_pages(step), config), bricks_(pages_, store.dataset(step).grid()) {}

  /// @brief PageCache::close(): stops the loader and writes the trace. @throws Error(io).
  void close() { pages_.close(); }

  PageCache& pages() { return pages_; }
  BrickCache& bricks() { return bricks_; }
  BrickCache* operator->() { return &bricks_; }
  BrickCache& operator*() { return bricks_; }

 private:
  PageCache pages_;
  BrickCache bricks_;
};

}  // namespace brickyard
