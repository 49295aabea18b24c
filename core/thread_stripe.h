#pragma once
/// @file thread_stripe.h
/// @brief A small per-thread index for striped structures: each thread gets a stable stripe
/// the first time it asks, round-robin, so concurrent threads mostly write different lines.

#include <atomic>
#include <cstddef>

namespace brickyard {

inline size_t thread_stripe(size_t stripes) {
  static std::atomic<size_t> next{0};
  thread_local const size_t id = next.fetch_add(1, std::memory_order_relaxed);
  return id % stripes;
}

}  // namespace brickyard
