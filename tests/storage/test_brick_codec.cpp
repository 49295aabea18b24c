#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "core/error.h"
#include "storage/brick_codec.h"
#include "dataset/grid.h"

namespace brickyard {
namespace {

template <typename T>
std::vector<std::byte> smooth_brick(const BrickFormat& f, double scale) {
  std::vector<T> v(f.voxels());
  const int e = f.edge();
  for (int z = 0; z < e; ++z)
    for (int y = 0; y < e; ++y)
      for (int x = 0; x < e; ++x)
        v[size_t((z * e + y) * e + x)] = static_cast<T>(scale * (1.5 + std::sin(x * 0.2) * std::cos(y * 0.15) + z * 0.01));
  std::vector<std::byte> b(v.size() * sizeof(T));
  std::memcpy(b.data(), v.data(), b.size());
  return b;
}

std::vector<std::byte> brick_for(const BrickFormat& f) {
  switch (f.type) {
    case ValueType::u8: return smooth_brick<uint8_t>(f, 80);
    case ValueType::i8: return smooth_brick<int8_t>(f, -40);  // negative: the sign bits shuffled too
    case ValueType::u16: return smooth_brick<uint16_t>(f, 20000);
    case ValueType::i16: return smooth_brick<int16_t>(f, -12000);
    case ValueType::f32: return smooth_brick<float>(f, 1.0);
  }
  return {};
}

TEST(BrickCodec, RoundTripsEveryTypeCodecAndShuffle) {
  const BrickKey key{3, 5, 6, 7};
  for (ValueType t : {ValueType::u8, ValueType::i8, ValueType::u16, ValueType::i16, ValueType::f32})
    for (Codec c : {Codec::none, Codec::lz4, Codec::lz4hc})
      for (bool shuffle : {false, true})
        for (int apron : {0, 1, 2}) {
          BrickFormat f{{t, 16, apron}, c, 9, shuffle};
          const auto voxels = brick_for(f);
          const auto record = encode_brick(f, key, voxels, 1.0f, 2.0f);
          std::vector<std::byte> out(f.bytes());
          decode_brick(f, key, record, out);
          EXPECT_EQ(out, voxels) << to_string(t) << " " << to_string(c) << " shuffle " << shuffle;
          const BrickHeader h = read_brick_header(record, key);
          EXPECT_EQ(h.min, 1.0f);
          EXPECT_EQ(h.max, 2.0f);
          EXPECT_EQ(h.raw_size, f.bytes());
          EXPECT_EQ(bool(h.flags & kBrickShuffled), f.shuffles() && c != Codec::none);
        }
}

TEST(BrickCodec, ShuffleIsInvertibleAndHelpsSixteenBitData) {
  std::mt19937 rng(1);
  std::vector<std::byte> in(3 * 1000), shuffled(in.size()), back(in.size());
  for (auto& b : in) b = std::byte(rng());
  shuffle_bytes(in.data(), shuffled.data(), 1000, 3);
  unshuffle_bytes(shuffled.data(), back.data(), 1000, 3);
  EXPECT_EQ(back, in);
  shuffle_bytes(in.data(), shuffled.data(), 1500, 2);
  unshuffle_bytes(shuffled.data(), back.data(), 1500, 2);
  EXPECT_EQ(back, in);

  const BrickFormat with{{ValueType::u16, 32, 1}, Codec::lz4, 9, true};
  BrickFormat without = with;
  without.shuffle = false;
  const auto voxels = brick_for(with);
  EXPECT_LT(encode_brick(with, {}, voxels, 0, 1).size(), encode_brick(without, {}, voxels, 0, 1).size());
}

Errc decode_error(const BrickFormat& f, const BrickKey& key, const std::vector<std::byte>& record, std::string* what) {
  std::vector<std::byte> out(f.bytes());
  try {
    decode_brick(f, key, record, out);
  } catch (const Error& e) {
    *what = e.what();
    EXPECT_EQ(e.key(), key.to_string());
    return e.code();
  }
  ADD_FAILURE() << "decode accepted a bad record";
  return Errc::internal;
}

TEST(BrickCodec, DamagedRecordsAreCorruptErrorsNamingTheKey) {
  const BrickFormat f{{ValueType::u16, 16, 1}, Codec::lz4, 9, true};
  const BrickKey key{2, 1, 0, 3};
  const auto good = encode_brick(f, key, brick_for(f), 0, 1);
  std::string what;

  auto flipped = good;
  flipped[good.size() - 5] ^= std::byte{0x5a};
  EXPECT_EQ(decode_error(f, key, flipped, &what), Errc::corrupt);

  auto truncated = good;
  truncated.resize(good.size() - 10);
  EXPECT_EQ(decode_error(f, key, truncated, &what), Errc::corrupt);
  EXPECT_NE(what.find("payload size"), std::string::npos) << what;

  EXPECT_EQ(decode_error(f, {2, 1, 0, 4}, good, &what), Errc::corrupt);  // stored under another key
  EXPECT_NE(what.find("record holds brick L2 (1, 0, 3)"), std::string::npos) << what;

  auto bad_magic = good;
  bad_magic[0] = std::byte{0};
  EXPECT_EQ(decode_error(f, key, bad_magic, &what), Errc::corrupt);

  auto newer = good;
  newer[4] = std::byte{99};
  EXPECT_EQ(decode_error(f, key, newer, &what), Errc::unsupported);

  BrickFormat other = f;
  other.apron = 2;
  EXPECT_EQ(decode_error(other, key, good, &what), Errc::corrupt);

  // A payload byte flipped in an uncompressed record gets past LZ4: the checksum catches it.
  BrickFormat raw = f;
  raw.codec = Codec::none;
  auto plain = encode_brick(raw, key, brick_for(raw), 0, 1);
  plain[sizeof(BrickHeader) + 100] ^= std::byte{1};
  EXPECT_EQ(decode_error(raw, key, plain, &what), Errc::corrupt);
  EXPECT_NE(what.find("checksum mismatch"), std::string::npos) << what;
}

TEST(GridLayout, LevelsHalveUntilOneBrickCoversTheVolume) {
  const GridLayout a = GridLayout::make({256, 256, 256}, 32);
  EXPECT_EQ(a.levels, 4);
  EXPECT_EQ(a.level_dims(0), Vec3s(32));
  EXPECT_EQ(a.level_bricks(3), Vec3s(8));
  EXPECT_EQ(a.total_bricks(), 1 + 8 + 64 + 512);
  const GridLayout b = GridLayout::make({100, 33, 7}, 16);
  EXPECT_EQ(b.levels, 4);  // 100 -> 50 -> 25 -> 13
  EXPECT_EQ(b.level_dims(0), Vec3s(13, 5, 1));
  EXPECT_EQ(b.level_bricks(3), Vec3s(7, 3, 1));
  EXPECT_EQ(GridLayout::make({1, 1, 1}, 8).levels, 1);
  for (int64_t i = 0; i < b.brick_count(3); ++i) EXPECT_EQ(b.linear_index(b.key_at(3, i)), i);
  EXPECT_TRUE(b.contains({3, 6, 2, 0}));
  EXPECT_FALSE(b.contains({3, 7, 0, 0}));
  EXPECT_FALSE(b.contains({4, 0, 0, 0}));
  EXPECT_THROW(GridLayout::make({4, 4, 4}, 24), Error);
  EXPECT_THROW(GridLayout::make({4, 0, 4}, 32), Error);
}

}  // namespace
}  // namespace brickyard
