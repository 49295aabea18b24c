#include "storage/page_codec.h"

#include <lz4.h>
#include <xxhash.h>

#include <bit>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

static_assert(std::endian::native == std::endian::little, "page headers are stored little-endian");

namespace {
Error corrupt(const PageKey& key, std::string message) {
  Error e(Errc::corrupt, std::move(message));
  e.with_key(to_string(key));
  return e;
}
}  // namespace

std::vector<std::byte> encode_page(const PageKey& key, std::span<const std::byte> bytes) {
  if (bytes.size() > size_t(std::numeric_limits<int>::max() / 2))
    throw Error(Errc::invalid_argument, fmt::format("a page of {} bytes is larger than a record holds", bytes.size()))
        .with_key(to_string(key));
  const int bound = LZ4_compressBound(int(bytes.size()));
  std::vector<std::byte> record(sizeof(PageHeader) + size_t(bound));
  const int stored = bytes.empty() ? 0
                                   : LZ4_compress_default(reinterpret_cast<const char*>(bytes.data()),
                                                          reinterpret_cast<char*>(record.data() + sizeof(PageHeader)),
                                                          int(bytes.size()), bound);
  if (stored < 0 || (stored == 0 && !bytes.empty()))
    throw Error(Errc::internal, "LZ4 compression failed").with_key(to_string(key));
  record.resize(sizeof(PageHeader) + size_t(stored));
  PageHeader h{};
  h.magic = kPageMagic;
  h.version = kPageFormatVersion;
  h.kind = uint8_t(key.kind);
  h.id = key.id;
  h.raw_size = uint32_t(bytes.size());
  h.payload_size = uint32_t(stored);
  h.checksum = XXH3_64bits(bytes.data(), bytes.size());
  std::memcpy(record.data(), &h, sizeof h);
  return record;
}

size_t decode_page(const PageKey& key, std::span<const std::byte> record, std::span<std::byte> out) {
  if (record.size() < sizeof(PageHeader))
    throw corrupt(key, fmt::format("page record of {} bytes is shorter than its {}-byte header", record.size(),
                                   sizeof(PageHeader)));
  PageHeader h;
  std::memcpy(&h, record.data(), sizeof h);
  if (h.magic != kPageMagic) throw corrupt(key, fmt::format("bad page magic 0x{:08x}", h.magic));
  if (h.version > kPageFormatVersion)
    throw Error(Errc::unsupported, fmt::format("page format version {} is newer than this build reads ({})", h.version,
                                               kPageFormatVersion))
        .with_key(to_string(key));
  if (h.kind != uint8_t(key.kind) || h.id != key.id)
    throw corrupt(key, fmt::format("record holds {}", to_string(PageKey{RecordKind(h.kind), h.id})));
  if (sizeof(PageHeader) + h.payload_size != record.size())
    throw corrupt(key, fmt::format("payload size {} does not match the record ({} bytes after the header)", h.payload_size,
                                   record.size() - sizeof(PageHeader)));
  if (h.raw_size > out.size())
    throw corrupt(key, fmt::format("page decodes to {} bytes, more than the kind's {}-byte pages", h.raw_size, out.size()));
  if (h.raw_size > 0) {
    const int n = LZ4_decompress_safe(reinterpret_cast<const char*>(record.data() + sizeof(PageHeader)),
                                      reinterpret_cast<char*>(out.data()), int(h.payload_size), int(h.raw_size));
    if (n != int(h.raw_size)) throw corrupt(key, fmt::format("LZ4 payload does not decode to {} bytes ({})", h.raw_size, n));
  }
  const uint64_t sum = XXH3_64bits(out.data(), h.raw_size);
  if (sum != h.checksum)
    throw corrupt(key, fmt::format("checksum mismatch: stored {:016x}, decoded data {:016x}", h.checksum, sum));
  if (out.size() > h.raw_size) std::memset(out.data() + h.raw_size, 0, out.size() - h.raw_size);  // out may be empty
  return h.raw_size;
}

}  // namespace brickyard
