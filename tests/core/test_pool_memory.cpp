// Pool memory (core/pool_memory.h): uninitialised arrays and vectors on huge pages where the
// size reaches one, aligned for what they hold, usable end to end, and released.

#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>
#include <vector>

#include "core/pool_memory.h"

namespace brickyard {
namespace {

TEST(PoolMemory, ArraysBelowAndAboveAHugePageHoldWhatIsWritten) {
  for (const size_t n : {size_t(0), size_t(1), size_t(1000), (size_t(2) << 20) / sizeof(uint16_t) + 7, size_t(3) << 20}) {
    PoolArray<uint16_t> a = make_pool_array<uint16_t>(n);
    ASSERT_NE(a.get(), nullptr) << n;
    EXPECT_EQ(reinterpret_cast<uintptr_t>(a.get()) % 16, 0u) << n;
    for (size_t i = 0; i < n; ++i) a[i] = uint16_t(i * 7);
    uint64_t sum = 0, want = 0;
    for (size_t i = 0; i < n; ++i) sum += a[i], want += uint16_t(i * 7);
    EXPECT_EQ(sum, want) << n;
  }
  // Past a huge page the array starts on one, so that the whole of it can be backed by them.
  const PoolArray<std::byte> big = make_pool_array<std::byte>(size_t(5) << 20);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(big.get()) % (size_t(2) << 20), 0u);
}

TEST(PoolMemory, VectorsOnThePoolAllocatorBehaveAsVectors) {
  struct State {
    double t = 1.5;
    float value = -2;
    bool done = false;
  };
  std::vector<State, PoolAllocator<State>> states;
  states.assign(size_t(512) * 512, State{});  // 4 MiB: on huge pages
  EXPECT_EQ(states.size(), size_t(512) * 512);
  EXPECT_EQ(states.back().t, 1.5);
  EXPECT_EQ(states[1000].value, -2.0f);
  states[7].done = true;
  states.assign(16, State{});  // shrinks and reuses or replaces its storage: values are fresh
  EXPECT_FALSE(states[7].done);
  std::vector<uint32_t, PoolAllocator<uint32_t>> slots(100, 0xffffffffu);
  std::iota(slots.begin(), slots.end(), 0u);
  EXPECT_EQ(slots[99], 99u);
  EXPECT_TRUE(PoolAllocator<int>() == PoolAllocator<int>(PoolAllocator<double>()));
}

}  // namespace
}  // namespace brickyard
