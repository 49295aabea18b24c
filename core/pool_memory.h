#pragma once
/// @file pool_memory.h
/// @brief Memory for large, long-lived arrays (the cache's L1 pool, a back end's brick pool,
/// per-pixel ray states): backed by transparent huge pages where the system offers them on
/// request (Linux's madvise mode), so that what is touched is committed 2 MiB at a time
/// instead of 4 KiB: on this project's virtual machines a 4 KiB page fault costs about 10 us,
/// 0.7 s for 256 MiB, against 15 ms in huge pages. Pools are not zeroed, since a slot is
/// written whole before it is read: an L1 budget is a ceiling, and memory no slot has touched
/// is never committed.

#include <cstddef>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace brickyard {

/// @brief `bytes` bytes, uninitialised, aligned to 16 bytes at least; from huge pages where
/// the size reaches one. Released with std::free. @throws std::bad_alloc.
inline void* pool_allocate(size_t bytes) {
  constexpr size_t kHugePage = size_t(2) << 20;
  if (bytes < kHugePage) {  // too small to gain from a huge page
    if (void* p = std::malloc(bytes == 0 ? 1 : bytes)) return p;
    throw std::bad_alloc();
  }
  const size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
  void* p = std::aligned_alloc(kHugePage, rounded);
  if (!p) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  madvise(p, rounded, MADV_HUGEPAGE);  // a hint: refused where THP is off, and nothing changes
#endif
  return p;
}

struct PoolFree {
  void operator()(void* p) const { std::free(p); }
};

template <typename T>
using PoolArray = std::unique_ptr<T[], PoolFree>;

/// @brief n uninitialised elements (pool_allocate).
template <typename T>
PoolArray<T> make_pool_array(size_t n) {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T> && alignof(T) <= 16,
                "slots of plain values");
  return PoolArray<T>(static_cast<T*>(pool_allocate(n * sizeof(T))));
}

/// @brief A standard allocator over pool_allocate, for vectors of per-pixel state that are
/// large and replaced whole (std::vector<RayState, PoolAllocator<RayState>>).
template <typename T>
struct PoolAllocator {
  static_assert(alignof(T) <= 16, "pool_allocate aligns to 16 bytes");
  using value_type = T;
  PoolAllocator() = default;
  template <typename U>
  PoolAllocator(const PoolAllocator<U>&) {}
  T* allocate(size_t n) { return static_cast<T*>(pool_allocate(n * sizeof(T))); }
  void deallocate(T* p, size_t) { std::free(p); }
  friend bool operator==(const PoolAllocator&, const PoolAllocator&) { return true; }
};

}  // namespace brickyard
