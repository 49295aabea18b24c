#pragma once
/// @file parallel.h
/// @brief brickyard's parallel loop over an index range: TBB's parallel_for in normal builds,
/// plain std::threads under ThreadSanitizer.
///
/// Debian's libtbb is not built with TSan, so TSan sees neither TBB's task hand-off nor its
/// joins and reports races on every task object (and, worse, a suppression broad enough to
/// silence those also silences real races in the loop bodies). Under TSan this loop therefore
/// runs its chunks on std::threads, whose creation and join TSan understands, so that the
/// TSan preset checks brickyard's own synchronisation exactly. All brickyard code loops
/// through this header.

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace brickyard {

/// @brief Calls body(chunk_begin, chunk_end) over disjoint chunks covering [begin, end), in
/// parallel (as many threads as the current TBB arena allows); chunks hold at least `grain`
/// indices where possible. An exception from body is rethrown to the caller.
template <typename Index, typename Body>
void parallel_for(Index begin, Index end, Index grain, const Body& body) {
  if (begin >= end) return;
  grain = std::max<Index>(grain, 1);
#if defined(__SANITIZE_THREAD__)
  const int threads = std::max(1, tbb::this_task_arena::max_concurrency());
  const Index chunk = std::max<Index>(grain, (end - begin) / Index(4 * threads));
  std::atomic<Index> next{begin};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    try {
      for (Index b = next.fetch_add(chunk); b < end; b = next.fetch_add(chunk)) body(b, std::min<Index>(end, b + chunk));
    } catch (...) {
      std::lock_guard lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
#else
  tbb::parallel_for(tbb::blocked_range<Index>(begin, end, grain),
                    [&](const tbb::blocked_range<Index>& r) { body(r.begin(), r.end()); });
#endif
}

}  // namespace brickyard
