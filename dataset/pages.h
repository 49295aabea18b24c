#pragma once
/// @file pages.h
/// @brief The disk side of the cache: records of any kind (grid bricks, octree pages,
/// tetrahedral clusters), addressed by (record kind, 64-bit id), each kind decoded into pages
/// of one fixed size.
///
/// A store implements PageSource; the cache reads through it and knows nothing else of the
/// store (no LMDB, no codec). Back ends never see a PageSource: they reach pages only through
/// the cache, which is what keeps the cache wall of DESIGN.md.
///
/// Thread safety: a PageSource is immutable once open and may be shared by any number of
/// threads. A PageReader is not thread-safe: each loader thread opens its own (for a store, one
/// read snapshot each) and keeps it while it reads.

#include <compare>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace brickyard {

/// @brief The kinds of record a dataset stores. The value is part of trace files (a byte of
/// each record), so values are never reused.
enum class RecordKind : uint8_t {
  brick = 0,        ///< a grid brick, id BrickKey::code()
  octree_page = 1,  ///< a subtree page of an octree volume
  tet_cluster = 2,  ///< a cluster of tetrahedra with its vertices and scalars
};
inline constexpr size_t kRecordKinds = 3;
std::string_view to_string(RecordKind k);
/// @brief "brick", "octree_page" or "tet_cluster"; Error(invalid_argument) naming `field` else.
RecordKind record_kind_from_string(std::string_view s, std::string_view field = "kind");

/// @brief A page's address: its record kind and its id within the kind.
struct PageKey {
  RecordKind kind = RecordKind::brick;
  uint64_t id = 0;
  friend auto operator<=>(const PageKey&, const PageKey&) = default;
  friend bool operator==(const PageKey&, const PageKey&) = default;
  template <typename H>
  friend H AbslHashValue(H h, const PageKey& k) {
    return H::combine(std::move(h), uint8_t(k.kind), k.id);
  }
};
/// @brief "brick 0x...", for messages.
std::string to_string(const PageKey& k);

/// @brief One record kind a source holds: the size of its decoded pages and how many records.
struct PageKindInfo {
  RecordKind kind = RecordKind::brick;
  size_t page_bytes = 0;  ///< every decoded page of the kind has exactly this many bytes
  uint64_t records = 0;   ///< records stored (pages with a payload)
};

/// @brief What one read cost: the stored (compressed) bytes and the decode's time.
struct PageRead {
  uint64_t stored_bytes = 0;
  uint64_t decode_ns = 0;
};

/// @brief Reads and decodes records for one thread.
class PageReader {
 public:
  virtual ~PageReader() = default;
  /// @brief Decodes the record of `key` into `out` (page_bytes of its kind). Throws
  /// Error(not_found) for a key the source does not hold, Error(corrupt) for a record that
  /// fails its checks; both name the source and the key.
  virtual PageRead read(const PageKey& key, std::span<std::byte> out) = 0;
};

/// @brief A source of records: what the cache's L3 is.
class PageSource {
 public:
  virtual ~PageSource() = default;
  /// @brief Where the records come from (a store's directory), named in errors.
  virtual const std::string& source_name() const = 0;
  /// @brief The record kinds held, each with its page size.
  virtual std::vector<PageKindInfo> page_kinds() const = 0;
  /// @brief A reader for the calling thread.
  virtual std::unique_ptr<PageReader> open_reader() const = 0;
  /// @brief A key as its kind writes it ("level 2 (1, 0, 3)" for a brick), for messages.
  virtual std::string describe(const PageKey& key) const { return to_string(key); }
};

}  // namespace brickyard
