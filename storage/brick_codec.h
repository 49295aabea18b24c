#pragma once
/// @file brick_codec.h
/// @brief The on-disk brick record: a fixed 64-byte header followed by the payload, the
/// brick's (M + 2A)^3 voxels compressed with LZ4 or LZ4-HC, optionally after a byte-shuffle.
///
/// Header fields are little-endian. The checksum is XXH3-64 of the decoded voxels, so a
/// decode proves the bytes a renderer samples are the bytes that were written. Decoding
/// checks magic, version, sizes, coordinates and checksum; any mismatch is Error(corrupt)
/// naming the key.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "core/brick_key.h"
#include "core/value_type.h"
#include "dataset/grid.h"

namespace brickyard {

inline constexpr uint32_t kBrickMagic = 0x4b425942;  // "BYBK" in file order
inline constexpr uint16_t kBrickFormatVersion = 1;

enum class Codec : uint8_t { none = 0, lz4 = 1, lz4hc = 2 };
std::string_view to_string(Codec c);

/// @brief Record header, exactly as stored (64 bytes, little-endian).
struct BrickHeader {
  uint32_t magic;
  uint16_t version;
  uint8_t value_type;   ///< ValueType
  uint8_t codec;        ///< Codec
  uint8_t flags;        ///< kBrickShuffled
  uint8_t apron;        ///< A
  uint16_t brick_size;  ///< M
  uint32_t level;
  uint32_t x, y, z;
  float min, max;        ///< over the whole payload, apron included
  uint32_t raw_size;     ///< decoded payload bytes: (M + 2A)^3 * sizeof(value)
  uint32_t payload_size; ///< stored payload bytes after the header
  uint32_t reserved0;
  uint64_t checksum;     ///< XXH3-64 of the decoded payload
  uint8_t reserved[8];
};
static_assert(sizeof(BrickHeader) == 64, "the brick header is part of the on-disk format");
inline constexpr uint8_t kBrickShuffled = 1;

/// @brief How bricks are laid out (their shape, which readers see) and compressed (which only
/// the store sees): fixed for a whole store.
struct BrickFormat : BrickShape {
  Codec codec = Codec::lz4;
  int hc_level = 9;     ///< LZ4-HC compression level (1..12)
  bool shuffle = true;  ///< byte-shuffle before compression (u16 and f32 only)

  const BrickShape& shape() const { return *this; }
  bool shuffles() const { return shuffle && type != ValueType::u8; }
};

/// @brief Encodes one brick's decoded voxels (format.bytes() of them, x fastest) as a record.
std::vector<std::byte> encode_brick(const BrickFormat& format, const BrickKey& key, std::span<const std::byte> voxels,
                                    float min, float max);

/// @brief Reads and validates a record's header (no decompression).
BrickHeader read_brick_header(std::span<const std::byte> record, const BrickKey& key);

/// @brief Decodes a record into `out` (format.bytes()), verifying header, sizes and checksum.
void decode_brick(const BrickFormat& format, const BrickKey& key, std::span<const std::byte> record,
                  std::span<std::byte> out);

/// @brief Groups the bytes of equal significance of n elements of `elem` bytes (Blosc's
/// shuffle): all first bytes, then all second bytes, ... unshuffle inverts it.
void shuffle_bytes(const std::byte* in, std::byte* out, size_t n, size_t elem);
void unshuffle_bytes(const std::byte* in, std::byte* out, size_t n, size_t elem);

}  // namespace brickyard
