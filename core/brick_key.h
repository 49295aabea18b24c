#pragma once
/// @file brick_key.h
/// @brief Brick keys: a level (0 = coarsest) and integer brick coordinates inside that level,
/// with the level-major Morton code that orders bricks on disk and in caches.
///
/// The 64-bit code is [level: 6 bits][Morton(x, y, z): 57 bits] (bit 63 is zero), so sorting
/// codes sorts by level first and then along the Z-order curve: bricks near in space are near
/// in the order. Its big-endian bytes sort the same way under memcmp (LMDB's default order).

#include <array>
#include <compare>
#include <cstdint>
#include <functional>
#include <ostream>
#include <string>

#include "core/math.h"

#if defined(__BMI2__)
#include <immintrin.h>
#endif

namespace brickyard {

/// @brief Bits per axis in a Morton code: brick coordinates are < 2^19 (524288 bricks per axis).
inline constexpr int kMortonBitsPerAxis = 19;
inline constexpr uint32_t kMaxBrickCoord = (1u << kMortonBitsPerAxis) - 1;
/// @brief Levels 0..kMaxLevel are representable (6 bits).
inline constexpr int kMaxLevel = 63;

namespace detail {
/// Spreads the low 19 bits of v so that bit i moves to bit 3i.
constexpr uint64_t spread_bits_3(uint64_t v) {
  v &= 0x7ffff;
  v = (v | (v << 32)) & 0x001f00000000ffffull;
  v = (v | (v << 16)) & 0x001f0000ff0000ffull;
  v = (v | (v << 8)) & 0x100f00f00f00f00full;
  v = (v | (v << 4)) & 0x10c30c30c30c30c3ull;
  v = (v | (v << 2)) & 0x1249249249249249ull;
  return v;
}
/// Inverse of spread_bits_3: gathers every third bit.
constexpr uint32_t compact_bits_3(uint64_t v) {
  v &= 0x1249249249249249ull;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ull;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00full;
  v = (v ^ (v >> 8)) & 0x001f0000ff0000ffull;
  v = (v ^ (v >> 16)) & 0x001f00000000ffffull;
  v = (v ^ (v >> 32)) & 0x7ffffull;
  return static_cast<uint32_t>(v);
}
}  // namespace detail

/// @brief Morton (Z-order) code of 19-bit coordinates, x in the lowest bit of each triple.
/// Uses BMI2 PDEP where the target has it; morton_encode_portable is the reference.
constexpr uint64_t morton_encode_portable(uint32_t x, uint32_t y, uint32_t z) {
  return detail::spread_bits_3(x) | (detail::spread_bits_3(y) << 1) | (detail::spread_bits_3(z) << 2);
}
constexpr Vec3u morton_decode_portable(uint64_t code) {
  return {detail::compact_bits_3(code), detail::compact_bits_3(code >> 1), detail::compact_bits_3(code >> 2)};
}

inline uint64_t morton_encode(uint32_t x, uint32_t y, uint32_t z) {
#if defined(__BMI2__)
  constexpr uint64_t mask = 0x1249249249249249ull & ((1ull << (3 * kMortonBitsPerAxis)) - 1);
  return _pdep_u64(x, mask) | _pdep_u64(y, mask << 1) | _pdep_u64(z, mask << 2);
#else
  return morton_encode_portable(x, y, z);
#endif
}

inline Vec3u morton_decode(uint64_t code) {
#if defined(__BMI2__)
  constexpr uint64_t mask = 0x1249249249249249ull & ((1ull << (3 * kMortonBitsPerAxis)) - 1);
  return {static_cast<uint32_t>(_pext_u64(code, mask)), static_cast<uint32_t>(_pext_u64(code, mask << 1)),
          static_cast<uint32_t>(_pext_u64(code, mask << 2))};
#else
  return morton_decode_portable(code);
#endif
}

/// @brief A brick at one level of a multiresolution hierarchy. Level 0 is the coarsest;
/// coordinates count bricks (not voxels) along each axis of that level.
struct BrickKey {
  uint32_t level = 0;
  uint32_t x = 0, y = 0, z = 0;

  /// @brief Whether level and coordinates fit in the 64-bit code.
  constexpr bool valid() const {
    return level <= uint32_t(kMaxLevel) && x <= kMaxBrickCoord && y <= kMaxBrickCoord && z <= kMaxBrickCoord;
  }
  /// @brief Level-major Morton code; requires valid().
  uint64_t code() const { return (uint64_t(level) << 57) | morton_encode(x, y, z); }
  static BrickKey from_code(uint64_t code) {
    Vec3u c = morton_decode(code & ((1ull << 57) - 1));
    return {static_cast<uint32_t>(code >> 57), c.x, c.y, c.z};
  }

  /// @brief Big-endian bytes of code(): memcmp order equals code order.
  std::array<uint8_t, 8> to_bytes() const {
    std::array<uint8_t, 8> b{};
    uint64_t c = code();
    for (int i = 7; i >= 0; --i, c >>= 8) b[i] = static_cast<uint8_t>(c & 0xff);
    return b;
  }
  static BrickKey from_bytes(const uint8_t* b) {
    uint64_t c = 0;
    for (int i = 0; i < 8; ++i) c = (c << 8) | b[i];
    return from_code(c);
  }

  /// @brief The brick one level coarser that contains this one (level must be > 0).
  constexpr BrickKey parent() const { return {level - 1, x >> 1, y >> 1, z >> 1}; }
  /// @brief Child i (0..7, bit 0 = +x, bit 1 = +y, bit 2 = +z) one level finer.
  constexpr BrickKey child(int i) const {
    return {level + 1, (x << 1) | uint32_t(i & 1), (y << 1) | uint32_t((i >> 1) & 1), (z << 1) | uint32_t((i >> 2) & 1)};
  }
  constexpr Vec3u coords() const { return {x, y, z}; }

  /// @brief "L3 (4, 5, 6)": the form every error message and tool uses.
  std::string to_string() const;

  friend constexpr bool operator==(const BrickKey&, const BrickKey&) = default;
  /// Orders like code(): by level, then Morton order.
  friend std::strong_ordering operator<=>(const BrickKey& a, const BrickKey& b) {
    if (a.level != b.level) return a.level <=> b.level;
    return morton_encode(a.x, a.y, a.z) <=> morton_encode(b.x, b.y, b.z);
  }
  friend std::ostream& operator<<(std::ostream& os, const BrickKey& k) { return os << k.to_string(); }
};

}  // namespace brickyard

template <>
struct std::hash<brickyard::BrickKey> {
  size_t operator()(const brickyard::BrickKey& k) const noexcept {
    // Fibonacci hashing of the code spreads Morton-adjacent keys over buckets.
    return static_cast<size_t>(k.code() * 0x9e3779b97f4a7c15ull);
  }
};
