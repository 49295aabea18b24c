#pragma once
/// @file trace.h
/// @brief Access traces: what the cache was asked for, in order, so that any policy and size
/// can be replayed offline against the same requests.
///
/// Formats, chosen by read_trace from the file's first bytes or its name:
/// - brickyard (`.bytrace`): a 16-byte header ("BYTRACE1", record count) then 24-byte records
///   {u64 key, u32 frame, u32 size, u8 kind, u8 hit level, u8 record kind, u8 reserved, u32
///   thread}, little-endian (the record kind's byte was reserved, 0, in traces written before
///   pages had kinds: they read as bricks);
/// - libCacheSim oracleGeneral (`.oracleGeneral`, `.oracleGeneral.bin`): 24-byte records
///   {u32 timestamp, u64 object id, u32 size, i64 next access vtime (-1: never)};
/// - text (`.txt`, `.csv`): one "key size kind" per line (size optional, default 1; kind
///   optional, a record kind's name, default brick); '#' starts a comment.
///
/// An object is a (record kind, key) pair: the same key of two kinds is two objects. Its size
/// is the size of its latest access (libCacheSim's rule): an access at another size than the
/// cached copy's replaces that copy (see replay.h).

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "dataset/pages.h"

namespace brickyard {

enum class AccessKind : uint8_t {
  demand = 0,            ///< a renderer's lookup
  blocking = 1,          ///< a blocking fetch (tools, reference renderer): a demand that may stall
  prefetch_request = 2,  ///< a request queued for the loader (no data moves yet)
  prefetch_fill = 3,     ///< the loader made a requested brick resident
};
std::string_view to_string(AccessKind k);

struct TraceRecord {
  uint64_t key = 0;      ///< BrickKey::code() for brickyard traces, any id otherwise
  uint32_t frame = 0;
  uint32_t size = 1;     ///< bytes (the decoded page size, in traces the cache records)
  AccessKind kind = AccessKind::demand;
  uint8_t hit_level = 0; ///< where the live cache found it: 1 L1, 2 L2, 3 store; 0 unknown
  uint32_t thread = 0;
  RecordKind record = RecordKind::brick;  ///< the kind of page accessed
};

struct Trace {
  std::vector<TraceRecord> records;
  /// @brief Number of distinct objects, and the working set: the sum over objects of each
  /// one's largest size, the smallest cache that never has to evict (the "N%" sizes of
  /// cachebench are fractions of it).
  uint64_t unique_objects() const;
  uint64_t unique_bytes() const;
  uint32_t frames() const;  ///< 1 + the largest frame number
  /// @brief The record kinds present, in RecordKind order.
  std::vector<RecordKind> record_kinds() const;
  /// @brief Only the records of one kind.
  Trace of_kind(RecordKind kind) const;
};

/// @brief Per record, the id of its object: the key itself when the trace holds one record
/// kind, else a dense id per distinct (kind, key), numbered in order of first access.
std::vector<uint64_t> object_ids(const Trace& trace);

enum class TraceFormat { brickyard, oracle_general, text };
std::string_view to_string(TraceFormat f);
/// @brief Format from a name: "brickyard", "oracleGeneral", "text"; Error(invalid_argument) else.
TraceFormat parse_trace_format(std::string_view name);
/// @brief Format implied by a path's extension (brickyard when unknown).
TraceFormat trace_format_of(const std::string& path);

/// @brief Reads a trace; errors name the file and the record or line at fault.
Trace read_trace(const std::string& path);
Trace read_trace(const std::string& path, TraceFormat format);
/// @brief Writes a trace atomically in the given format. oracleGeneral gets each record's next
/// demand access to the same object, whatever its size (libCacheSim's next access time).
void write_trace(const std::string& path, const Trace& trace, TraceFormat format);

/// @brief For each record, the index of the next demand access that a copy of its object at
/// this record's size would serve (kNoNextAccess = never): the next demand access to the
/// object, unless an access or fill at another size, which replaces the copy, comes first
/// (then never). The future OPT looks at. `ids` from object_ids(), or empty.
std::vector<uint64_t> next_demand_access(const Trace& trace, const std::vector<uint64_t>& ids = {});

/// @brief Synthetic traces for sanity checks (size: bytes per object).
Trace zipf_trace(uint64_t objects, uint64_t requests, double alpha, uint64_t seed, uint32_t size = 1);
Trace scan_trace(uint64_t objects, uint64_t passes, uint32_t size = 1);
/// @brief A loop over `objects` repeated `passes` times: LRU's worst case when objects > capacity.
Trace loop_trace(uint64_t objects, uint64_t passes, uint32_t size = 1);

}  // namespace brickyard
