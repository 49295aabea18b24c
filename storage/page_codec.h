#pragma once
/// @file page_codec.h
/// @brief The on-disk record of every page kind other than grid bricks (octree pages,
/// tetrahedral clusters): a fixed 32-byte header, then the page's bytes compressed with LZ4.
///
/// Header fields are little-endian. The checksum is XXH3-64 of the decoded bytes. A record
/// stores only the bytes its page uses; decoding writes them at the front of a page of the
/// kind's fixed size and zeroes the rest. Any mismatch is Error(corrupt) naming the key.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "dataset/pages.h"

namespace brickyard {

inline constexpr uint32_t kPageMagic = 0x47505942;  // "BYPG" in file order
inline constexpr uint16_t kPageFormatVersion = 1;

/// @brief Record header, exactly as stored (32 bytes, little-endian).
struct PageHeader {
  uint32_t magic;
  uint16_t version;
  uint8_t kind;          ///< RecordKind
  uint8_t reserved0;
  uint64_t id;
  uint32_t raw_size;     ///< decoded bytes
  uint32_t payload_size; ///< stored bytes after the header
  uint64_t checksum;     ///< XXH3-64 of the decoded bytes
};
static_assert(sizeof(PageHeader) == 32, "the page header is part of the on-disk format");

/// @brief Encodes a page's used bytes as a record.
std::vector<std::byte> encode_page(const PageKey& key, std::span<const std::byte> bytes);
/// @brief Decodes a record into the front of `out` (at least its raw size), zeroing the rest;
/// returns the decoded size.
size_t decode_page(const PageKey& key, std::span<const std::byte> record, std::span<std::byte> out);

}  // namespace brickyard
