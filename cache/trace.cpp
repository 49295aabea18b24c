#include "cache/trace.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>

#include <absl/container/flat_hash_map.h>
#include <absl/container/flat_hash_set.h>
#include <fmt/format.h>

#include "cache/policy.h"
#include "core/atomic_file.h"
#include "core/error.h"

namespace brickyard {

namespace {
constexpr char kMagic[8] = {'B', 'Y', 'T', 'R', 'A', 'C', 'E', '1'};
constexpr size_t kRecordBytes = 24;

struct FileCloser {
  void operator()(std::FILE* f) const { if (f) std::fclose(f); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

template <typename T>
void put(std::byte* p, T v) { std::memcpy(p, &v, sizeof v); }
template <typename T>
T get(const std::byte* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

bool ends_with(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}
}  // namespace

std::string_view to_string(AccessKind k) {
  switch (k) {
    case AccessKind::demand: return "demand";
    case AccessKind::blocking: return "blocking";
    case AccessKind::prefetch_request: return "prefetch-request";
    case AccessKind::prefetch_fill: return "prefetch-fill";
  }
  return "?";
}

std::string_view to_string(TraceFormat f) {
  switch (f) {
    case TraceFormat::brickyard: return "brickyard";
    case TraceFormat::oracle_general: return "oracleGeneral";
    case TraceFormat::text: return "text";
  }
  return "?";
}

TraceFormat parse_trace_format(std::string_view name) {
  if (name == "brickyard") return TraceFormat::brickyard;
  if (name == "oracleGeneral" || name == "oracle-general") return TraceFormat::oracle_general;
  if (name == "text") return TraceFormat::text;
  throw Error(Errc::invalid_argument, fmt::format("unknown trace format '{}' (brickyard, oracleGeneral, text)", name))
      .with_field("trace_format");
}

TraceFormat trace_format_of(const std::string& path) {
  if (ends_with(path, ".oracleGeneral") || ends_with(path, ".oracleGeneral.bin")) return TraceFormat::oracle_general;
  if (ends_with(path, ".txt") || ends_with(path, ".csv")) return TraceFormat::text;
  return TraceFormat::brickyard;
}

uint64_t Trace::unique_objects() const {
  absl::flat_hash_set<PageKey> keys;
  for (const auto& r : records) keys.insert({r.record, r.key});
  return keys.size();
}

uint64_t Trace::unique_bytes() const {
  absl::flat_hash_map<PageKey, uint32_t> sizes;
  for (const auto& r : records) {
    uint32_t& s = sizes[{r.record, r.key}];
    s = std::max(s, r.size);
  }
  uint64_t total = 0;
  for (const auto& [k, s] : sizes) total += s;
  return total;
}

std::vector<RecordKind> Trace::record_kinds() const {
  bool seen[kRecordKinds] = {};
  for (const auto& r : records) seen[size_t(r.record)] = true;
  std::vector<RecordKind> out;
  for (size_t k = 0; k < kRecordKinds; ++k)
    if (seen[k]) out.push_back(RecordKind(k));
  return out;
}

Trace Trace::of_kind(RecordKind kind) const {
  Trace t;
  for (const auto& r : records)
    if (r.record == kind) t.records.push_back(r);
  return t;
}

std::vector<uint64_t> object_ids(const Trace& trace) {
  std::vector<uint64_t> ids(trace.records.size());
  if (trace.record_kinds().size() <= 1) {
    for (size_t i = 0; i < ids.size(); ++i) ids[i] = trace.records[i].key;
    return ids;
  }
  absl::flat_hash_map<PageKey, uint64_t> dense;
  for (size_t i = 0; i < ids.size(); ++i) {
    const TraceRecord& r = trace.records[i];
    ids[i] = dense.try_emplace(PageKey{r.record, r.key}, dense.size()).first->second;
  }
  return ids;
}

uint32_t Trace::frames() const {
  uint32_t f = 0;
  for (const auto& r : records) f = std::max(f, r.frame);
  return records.empty() ? 0 : f + 1;
}

namespace {
bool is_demand(AccessKind k) { return k == AccessKind::demand || k == AccessKind::blocking; }

/// The next demand access to the same object, whatever its size (oracleGeneral's field).
std::vector<uint64_t> next_request(const Trace& trace, const std::vector<uint64_t>& ids) {
  std::vector<uint64_t> next(trace.records.size(), kNoNextAccess);
  absl::flat_hash_map<uint64_t, uint64_t> upcoming;
  for (size_t i = trace.records.size(); i-- > 0;) {
    auto it = upcoming.find(ids[i]);
    next[i] = it == upcoming.end() ? kNoNextAccess : it->second;
    if (is_demand(trace.records[i].kind)) upcoming[ids[i]] = i;
  }
  return next;
}
}  // namespace

std::vector<uint64_t> next_demand_access(const Trace& trace, const std::vector<uint64_t>& given_ids) {
  const std::vector<uint64_t> ids = given_ids.size() == trace.records.size() ? given_ids : object_ids(trace);
  std::vector<uint64_t> next(trace.records.size(), kNoNextAccess);
  // Per object, scanning backwards: the size of its next demand access or fill, and the next
  // demand access that a copy of that size would serve. A fill of the copy's size leaves the
  // copy in place; one of another size replaces it, as a demand access of another size does.
  struct Upcoming {
    uint32_t size;
    uint64_t serves;
  };
  absl::flat_hash_map<uint64_t, Upcoming> upcoming;
  for (size_t i = trace.records.size(); i-- > 0;) {
    const TraceRecord& r = trace.records[i];
    auto it = upcoming.find(ids[i]);
    next[i] = it != upcoming.end() && it->second.size == r.size ? it->second.serves : kNoNextAccess;
    if (is_demand(r.kind)) upcoming[ids[i]] = {r.size, i};
    else if (r.kind == AccessKind::prefetch_fill) upcoming[ids[i]] = {r.size, next[i]};
  }
  return next;
}

Trace read_trace(const std::string& path) {
  // Sniff the magic first: a brickyard trace is recognised whatever its name.
  check_readable_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  char magic[8] = {};
  in.read(magic, 8);
  if (in.gcount() == 8 && std::memcmp(magic, kMagic, 8) == 0) return read_trace(path, TraceFormat::brickyard);
  const TraceFormat f = trace_format_of(path);
  if (f == TraceFormat::brickyard)
    throw Error(Errc::format, "not a brickyard trace (no BYTRACE1 magic); name it .oracleGeneral or .txt for those formats")
        .with_file(path);
  return read_trace(path, f);
}

Trace read_trace(const std::string& path, TraceFormat format) {
  check_readable_file(path);
  Trace t;
  if (format == TraceFormat::text) {
    std::ifstream in(path);
    if (!in) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
    std::string line;
    for (uint64_t n = 1; std::getline(in, line); ++n) {
      if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
      for (char& c : line)
        if (c == ',') c = ' ';
      std::istringstream fields(line);
      std::string key_text, size_text, kind_text, extra;
      if (!(fields >> key_text)) continue;
      TraceRecord r;
      try {
        size_t used = 0;
        // stoull takes "-5" as 2^64 - 5: a sign is not a key or a size.
        if (key_text[0] == '-' || key_text[0] == '+')
          throw std::invalid_argument(key_text);
        r.key = std::stoull(key_text, &used, 0);
        if (used != key_text.size()) throw std::invalid_argument(key_text);
        if (fields >> size_text) {
          if (size_text[0] == '-' || size_text[0] == '+') throw std::invalid_argument(size_text);
          const unsigned long long s = std::stoull(size_text, &used);
          if (used != size_text.size() || s == 0 || s > UINT32_MAX) throw std::invalid_argument(size_text);
          r.size = uint32_t(s);
        }
      } catch (const std::exception&) {
        throw Error(Errc::format, fmt::format("line {}: expected 'key [size [kind]]' with integers, got '{}'", n, line))
            .with_file(path);
      }
      if (fields >> kind_text) {
        try {
          r.record = record_kind_from_string(kind_text);
        } catch (const Error& e) {
          throw Error(Errc::format, fmt::format("line {}: {}", n, e.message())).with_file(path);
        }
      }
      if (fields >> extra)
        throw Error(Errc::format, fmt::format("line {}: unexpected '{}' after key, size and kind", n, extra)).with_file(path);
      t.records.push_back(r);
    }
    return t;
  }

  FilePtr f(std::fopen(path.c_str(), "rb"));
  if (!f) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  std::error_code ec;
  const uint64_t file_size = std::filesystem::file_size(path, ec);
  if (ec) throw Error(Errc::io, fmt::format("cannot read its size: {}", ec.message())).with_file(path);
  uint64_t count = 0;
  if (format == TraceFormat::brickyard) {
    std::byte header[16];
    if (std::fread(header, 1, 16, f.get()) != 16 || std::memcmp(header, kMagic, 8) != 0)
      throw Error(Errc::format, "not a brickyard trace (no BYTRACE1 magic)").with_file(path);
    count = get<uint64_t>(header + 8);
    // Compared by division: 16 + count * 24 wraps for a forged count (2^61 matches an empty file).
    if (count != (file_size - 16) / kRecordBytes || (file_size - 16) % kRecordBytes != 0)
      throw Error(Errc::format, fmt::format("header says {} records ({} bytes), the file has {} bytes: truncated or corrupt",
                                            count, count <= (UINT64_MAX - 16) / kRecordBytes
                                                       ? fmt::format("{}", 16 + count * kRecordBytes)
                                                       : std::string("more than 2^64"),
                                            file_size))
          .with_file(path);
  } else {
    if (file_size % kRecordBytes != 0)
      throw Error(Errc::format, fmt::format("{} bytes is not a whole number of 24-byte oracleGeneral records", file_size))
          .with_file(path);
    count = file_size / kRecordBytes;
  }
  t.records.reserve(count);
  std::vector<std::byte> buffer(kRecordBytes * 65536);
  for (uint64_t done = 0; done < count;) {
    const size_t n = size_t(std::min<uint64_t>(65536, count - done));
    if (std::fread(buffer.data(), kRecordBytes, n, f.get()) != n)
      throw Error(Errc::format, fmt::format("short read at record {}", done)).with_file(path);
    for (size_t i = 0; i < n; ++i) {
      const std::byte* p = buffer.data() + i * kRecordBytes;
      TraceRecord r;
      if (format == TraceFormat::brickyard) {
        r.key = get<uint64_t>(p);
        r.frame = get<uint32_t>(p + 8);
        r.size = get<uint32_t>(p + 12);
        const uint8_t kind = get<uint8_t>(p + 16);
        if (kind > uint8_t(AccessKind::prefetch_fill))
          throw Error(Errc::format, fmt::format("record {}: unknown access kind {}", done + i, kind)).with_file(path);
        r.kind = AccessKind(kind);
        r.hit_level = get<uint8_t>(p + 17);
        const uint8_t record = get<uint8_t>(p + 18);
        if (record >= kRecordKinds)
          throw Error(Errc::format, fmt::format("record {}: unknown record kind {}", done + i, record)).with_file(path);
        r.record = RecordKind(record);
        r.thread = get<uint32_t>(p + 20);
      } else {
        r.frame = get<uint32_t>(p);  // timestamp: seconds in libCacheSim traces; kept as the time window
        r.key = get<uint64_t>(p + 4);
        r.size = std::max<uint32_t>(1, get<uint32_t>(p + 12));
      }
      t.records.push_back(r);
    }
    done += n;
  }
  return t;
}

void write_trace(const std::string& path, const Trace& trace, TraceFormat format) {
  AtomicFile file(path);
  if (format == TraceFormat::text) {
    std::string text;
    for (const auto& r : trace.records)
      text += r.record == RecordKind::brick ? fmt::format("{} {}\n", r.key, r.size)
                                            : fmt::format("{} {} {}\n", r.key, r.size, to_string(r.record));
    file.write(text.data(), text.size());
    file.commit();
    return;
  }
  if (format == TraceFormat::brickyard) {
    std::byte header[16];
    std::memcpy(header, kMagic, 8);
    put<uint64_t>(header + 8, trace.records.size());
    file.write(header, 16);
  }
  // oracleGeneral has no record kinds: a trace of several writes each (kind, key) object's
  // dense id (object_ids) as its id.
  const std::vector<uint64_t> ids = format == TraceFormat::oracle_general ? object_ids(trace) : std::vector<uint64_t>{};
  const std::vector<uint64_t> next =
      format == TraceFormat::oracle_general ? next_request(trace, ids) : std::vector<uint64_t>{};
  std::vector<std::byte> buffer;
  buffer.reserve(kRecordBytes * 65536);
  for (size_t i = 0; i < trace.records.size(); ++i) {
    const TraceRecord& r = trace.records[i];
    std::byte rec[kRecordBytes] = {};
    if (format == TraceFormat::brickyard) {
      put<uint64_t>(rec, r.key);
      put<uint32_t>(rec + 8, r.frame);
      put<uint32_t>(rec + 12, r.size);
      put<uint8_t>(rec + 16, uint8_t(r.kind));
      put<uint8_t>(rec + 17, r.hit_level);
      put<uint8_t>(rec + 18, uint8_t(r.record));
      put<uint32_t>(rec + 20, r.thread);
    } else {
      put<uint32_t>(rec, r.frame);
      put<uint64_t>(rec + 4, ids[i]);
      put<uint32_t>(rec + 12, r.size);
      put<int64_t>(rec + 16, next[i] == kNoNextAccess ? int64_t(-1) : int64_t(next[i]));
    }
    buffer.insert(buffer.end(), rec, rec + kRecordBytes);
    if (buffer.size() >= kRecordBytes * 65536) {
      file.write(buffer.data(), buffer.size());
      buffer.clear();
    }
  }
  file.write(buffer.data(), buffer.size());
  file.commit();
}

Trace zipf_trace(uint64_t objects, uint64_t requests, double alpha, uint64_t seed, uint32_t size) {
  if (objects == 0) throw Error(Errc::invalid_argument, "a Zipf trace needs at least one object").with_field("objects");
  // Inverse-CDF sampling over a precomputed table: exact for any alpha >= 0.
  std::vector<double> cdf(objects);
  double sum = 0;
  for (uint64_t i = 0; i < objects; ++i) cdf[i] = (sum += 1.0 / std::pow(double(i + 1), alpha));
  for (double& c : cdf) c /= sum;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // Ranks are scattered over ids so that popularity is not correlated with key order.
  std::vector<uint64_t> ids(objects);
  for (uint64_t i = 0; i < objects; ++i) ids[i] = i;
  std::shuffle(ids.begin(), ids.end(), rng);
  Trace t;
  t.records.reserve(requests);
  for (uint64_t r = 0; r < requests; ++r) {
    const uint64_t rank = uint64_t(std::lower_bound(cdf.begin(), cdf.end(), u(rng)) - cdf.begin());
    t.records.push_back({ids[std::min(rank, objects - 1)], uint32_t(r / std::max<uint64_t>(1, requests / 100)), size});
  }
  return t;
}

Trace scan_trace(uint64_t objects, uint64_t passes, uint32_t size) {
  // Each pass touches new objects: a one-time scan, nothing is ever reused.
  Trace t;
  for (uint64_t p = 0; p < passes; ++p)
    for (uint64_t i = 0; i < objects; ++i) t.records.push_back({p * objects + i, uint32_t(p), size});
  return t;
}

Trace loop_trace(uint64_t objects, uint64_t passes, uint32_t size) {
  Trace t;
  for (uint64_t p = 0; p < passes; ++p)
    for (uint64_t i = 0; i < objects; ++i) t.records.push_back({i, uint32_t(p), size});
  return t;
}

}  // namespace brickyard
