#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <set>
#include <vector>

#include "core/brick_key.h"

namespace brickyard {
namespace {

TEST(Morton, HardwareAndPortableEncodingsAgree) {
  std::mt19937_64 rng(7);
  for (int i = 0; i < 10000; ++i) {
    const uint32_t x = rng() & kMaxBrickCoord, y = rng() & kMaxBrickCoord, z = rng() & kMaxBrickCoord;
    const uint64_t code = morton_encode(x, y, z);
    EXPECT_EQ(code, morton_encode_portable(x, y, z));
    EXPECT_EQ(morton_decode(code), Vec3u(x, y, z));
    EXPECT_EQ(morton_decode_portable(code), Vec3u(x, y, z));
  }
}

TEST(Morton, InterleavesXLowest) {
  EXPECT_EQ(morton_encode(1, 0, 0), 1u);
  EXPECT_EQ(morton_encode(0, 1, 0), 2u);
  EXPECT_EQ(morton_encode(0, 0, 1), 4u);
  EXPECT_EQ(morton_encode(2, 0, 0), 8u);
  EXPECT_EQ(morton_encode(kMaxBrickCoord, kMaxBrickCoord, kMaxBrickCoord), (uint64_t(1) << 57) - 1);
}

TEST(BrickKey, CodeAndBytesRoundTrip) {
  std::mt19937_64 rng(11);
  for (int i = 0; i < 10000; ++i) {
    const BrickKey k{uint32_t(rng() % (kMaxLevel + 1)), uint32_t(rng() & kMaxBrickCoord),
                     uint32_t(rng() & kMaxBrickCoord), uint32_t(rng() & kMaxBrickCoord)};
    ASSERT_TRUE(k.valid());
    EXPECT_EQ(BrickKey::from_code(k.code()), k);
    const auto bytes = k.to_bytes();
    EXPECT_EQ(BrickKey::from_bytes(bytes.data()), k);
  }
  EXPECT_FALSE((BrickKey{64, 0, 0, 0}.valid()));
  EXPECT_FALSE((BrickKey{0, kMaxBrickCoord + 1, 0, 0}.valid()));
}

TEST(BrickKey, OrdersByLevelThenMortonAndBytesSortTheSame) {
  std::vector<BrickKey> keys;
  for (uint32_t level = 0; level < 4; ++level)
    for (uint32_t z = 0; z < 4; ++z)
      for (uint32_t y = 0; y < 4; ++y)
        for (uint32_t x = 0; x < 4; ++x) keys.push_back({level, x, y, z});
  std::mt19937 rng(3);
  std::shuffle(keys.begin(), keys.end(), rng);
  std::sort(keys.begin(), keys.end());
  for (size_t i = 1; i < keys.size(); ++i) {
    const BrickKey &a = keys[i - 1], &b = keys[i];
    EXPECT_LE(a.level, b.level);
    EXPECT_LT(a.code(), b.code());
    const auto ab = a.to_bytes(), bb = b.to_bytes();
    EXPECT_LT(std::memcmp(ab.data(), bb.data(), 8), 0) << a << " vs " << b;
  }
  // Level-major: every level-0 key precedes any level-1 key, however large its coordinates.
  EXPECT_LT((BrickKey{0, kMaxBrickCoord, kMaxBrickCoord, kMaxBrickCoord}), (BrickKey{1, 0, 0, 0}));
}

TEST(BrickKey, MortonOrderKeepsOctantsContiguous) {
  // The 8 children of any brick occupy 8 consecutive codes: spatial neighbours are neighbours
  // in the order, at every scale.
  for (uint32_t x = 0; x < 4; ++x)
    for (uint32_t y = 0; y < 4; ++y)
      for (uint32_t z = 0; z < 4; ++z) {
        const BrickKey parent{3, x, y, z};
        std::set<uint64_t> codes;
        for (int c = 0; c < 8; ++c) codes.insert(parent.child(c).code());
        EXPECT_EQ(*codes.rbegin() - *codes.begin(), 7u);
        EXPECT_EQ(*codes.begin(), parent.child(0).code());
      }
}

TEST(BrickKey, ParentAndChildAreInverse) {
  const BrickKey k{5, 10, 21, 7};
  for (int c = 0; c < 8; ++c) EXPECT_EQ(k.child(c).parent(), k);
  EXPECT_EQ(k.child(7), (BrickKey{6, 21, 43, 15}));
  EXPECT_EQ(k.to_string(), "L5 (10, 21, 7)");
  EXPECT_NE(std::hash<BrickKey>{}(k), std::hash<BrickKey>{}(k.child(0)));
}

}  // namespace
}  // namespace brickyard
