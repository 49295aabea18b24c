#include "renderers/common/render.h"

#include <algorithm>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "core/parallel.h"
#include "core/timing.h"

namespace brickyard {

FrameStats render_frame(Renderer& renderer, const RenderContext& context, const FrameSetup& setup, FrameBuffers& out) {
  PageCache& cache = context.pages();
  FrameStats stats;
  stats.frame = setup.frame;
  stats.width = setup.width;
  stats.height = setup.height;
  stats.threads = tbb::this_task_arena::max_concurrency();
  const CacheStats before = cache.stats();
  Stopwatch frame_watch;

  out = FrameBuffers(setup.width, setup.height, setup.outputs);
  cache.frame_begin();
  Stopwatch watch;
  renderer.begin_frame(setup);
  stats.add_phase("prepare", watch.seconds());

  const int tiles_x = (setup.width + kTileSize - 1) / kTileSize, tiles_y = (setup.height + kTileSize - 1) / kTileSize;
  std::vector<RayCounters> tile_counters(size_t(tiles_x) * size_t(tiles_y));
  std::vector<std::thread::id> tile_thread(tile_counters.size());
  double render_seconds = 0, finish_seconds = 0;
  do {
    watch = Stopwatch();
    parallel_for<int>(0, tiles_x * tiles_y, 1, [&](int begin, int end) {
      for (int t = begin; t < end; ++t) {
        const int tx = t % tiles_x, ty = t / tiles_x;
        const Tile tile{tx * kTileSize, ty * kTileSize, std::min(setup.width, (tx + 1) * kTileSize),
                        std::min(setup.height, (ty + 1) * kTileSize)};
        renderer.render_tile(setup, tile, out, tile_counters[size_t(t)]);
        tile_thread[size_t(t)] = std::this_thread::get_id();
      }
    });
    render_seconds += watch.seconds();
    watch = Stopwatch();
    renderer.end_frame(setup, out);
    finish_seconds += watch.seconds();
  } while (renderer.another_pass());
  for (const RayCounters& c : tile_counters) stats.counters += c;
  std::sort(tile_thread.begin(), tile_thread.end());
  stats.tile_threads = int(std::unique(tile_thread.begin(), tile_thread.end()) - tile_thread.begin());
  stats.add_phase("render", render_seconds);

  watch = Stopwatch();
  const FrameReport report = cache.frame_end();
  stats.add_phase("finish", finish_seconds + watch.seconds());
  stats.seconds = frame_watch.seconds();
  renderer.add_statistics(stats);

  const CacheStats after = cache.stats();
  stats.requests = report.requests;
  stats.uploads = after.uploads - before.uploads;
  stats.stalls = after.stalls - before.stalls;
  stats.bytes_read = after.l3_bytes_read - before.l3_bytes_read;
  stats.bytes_decoded = after.l3_bytes_decoded - before.l3_bytes_decoded;
  stats.unreadable = after.failed_keys;
  return stats;
}

}  // namespace brickyard
