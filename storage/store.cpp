#include "storage/store.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>
#include <lz4.h>
#include <xxhash.h>

#include "core/error.h"
#include "storage/page_codec.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;
constexpr size_t kNodesPerChunk = 65536;  // 1 MiB node-table records
const std::string kManifestKey = "manifest";
// The XXH3-64 of the manifest's text, little-endian, beside it: a flipped bit in the manifest
// would otherwise be read as another volume (other dims, spacing or value range).
const std::string kManifestChecksumKey = "manifest.xxh3";
// An interrupted build's state, beside the manifest of the incomplete store it is building.
const std::string kCheckpointKey = "build.checkpoint";
constexpr uint32_t kCheckpointMagic = 0x4b435942;  // "BYCK"
constexpr size_t kCheckpointChunk = size_t(64) << 20;  // LZ4 takes at most 2 GiB at once
// Table chunks (node table, octree page table, cluster table, time-step ranges) end in the
// XXH3-64 of their records, little-endian: a flipped bit in a node's range would otherwise skip
// its brick or draw a constant that is not there, unseen. Chunks without it (stores written
// before) are read unchecked.
constexpr size_t kTableChecksumBytes = 8;

uint64_t read_le64(const std::byte* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= uint64_t(p[i]) << (8 * i);
  return v;
}
std::array<std::byte, 8> le64(uint64_t v) {
  std::array<std::byte, 8> b;
  for (int i = 0; i < 8; ++i) b[size_t(i)] = std::byte((v >> (8 * i)) & 0xff);
  return b;
}

/// A table chunk's records followed by their checksum.
std::vector<std::byte> checksummed_chunk(const void* records, size_t bytes) {
  const auto* p = static_cast<const std::byte*>(records);
  std::vector<std::byte> v(p, p + bytes);
  const auto sum = le64(XXH3_64bits(records, bytes));
  v.insert(v.end(), sum.begin(), sum.end());
  return v;
}

/// Copies a table chunk of `bytes` bytes of records into `out`, checking its size and, where
/// it has one, its checksum. `what` names the chunk in errors.
void read_table_chunk(const std::optional<std::span<const std::byte>>& value, size_t bytes, const std::string& what,
                      const std::string& dir, void* out) {
  if (!value || (value->size() != bytes && value->size() != bytes + kTableChecksumBytes))
    throw Error(Errc::corrupt, fmt::format("{} is {}", what,
                                           value ? fmt::format("{} bytes, expected {}", value->size(), bytes + kTableChecksumBytes)
                                                 : "missing"))
        .with_file(dir);
  if (value->size() == bytes + kTableChecksumBytes) {
    const uint64_t stored = read_le64(value->data() + bytes), actual = XXH3_64bits(value->data(), bytes);
    if (stored != actual)
      throw Error(Errc::corrupt, fmt::format("{} fails its checksum: stored {:016x}, computed {:016x}", what, stored, actual))
          .with_file(dir);
  }
  std::memcpy(out, value->data(), bytes);
}

/// Whether a constant node's value is one a store of type t holds (read_brick converts it to
/// the type): finite, and for the integer types a whole number within their range.
bool holds_value(ValueType t, float v) {
  switch (t) {
    case ValueType::f32: return std::isfinite(v);
    default: return v >= integer_min(t) && v <= integer_max(t) && v == std::floor(v);
  }
}

/// Writes the manifest's text and its checksum (in the writer's next transaction).
void put_manifest(lmdb::BatchWriter& writer, const lmdb::Database& db, const std::string& text) {
  writer.put(db, lmdb::as_bytes(kManifestKey), lmdb::as_bytes(text));
  const auto sum = le64(XXH3_64bits(text.data(), text.size()));
  writer.put(db, lmdb::as_bytes(kManifestChecksumKey), std::span<const std::byte>(sum.data(), sum.size()));
}

std::array<std::byte, 8> node_chunk_key(uint32_t level, uint32_t chunk) {
  std::array<std::byte, 8> k{};
  for (int i = 0; i < 4; ++i) {
    k[size_t(i)] = std::byte((level >> (24 - 8 * i)) & 0xff);
    k[size_t(4 + i)] = std::byte((chunk >> (24 - 8 * i)) & 0xff);
  }
  return k;
}

std::array<std::byte, 8> brick_key_bytes(const BrickKey& key) {
  const auto b = key.to_bytes();
  std::array<std::byte, 8> out;
  std::memcpy(out.data(), b.data(), 8);
  return out;
}

/// A record or node-table key as LMDB takes it: the one-step key (8 bytes), or in a grid of
/// several time steps the step (big-endian u32) before it, so that each step's records are
/// contiguous and in the same order.
struct KeyBytes {
  std::array<std::byte, 12> bytes{};
  size_t size = 8;
  lmdb::Bytes span() const { return {bytes.data(), size}; }
};
KeyBytes keyed(bool series, int step, const std::array<std::byte, 8>& key) {
  KeyBytes k;
  const size_t at = series ? 4 : 0;
  for (size_t i = 0; i < at; ++i) k.bytes[i] = std::byte((uint32_t(step) >> (24 - 8 * i)) & 0xff);
  std::memcpy(k.bytes.data() + at, key.data(), 8);
  k.size = at + 8;
  return k;
}

std::array<std::byte, 8> big_endian_id(uint64_t id) {
  std::array<std::byte, 8> out;
  for (int i = 0; i < 8; ++i) out[size_t(i)] = std::byte((id >> (56 - 8 * i)) & 0xff);
  return out;
}

/// The per-time-step range chunks sit in the cluster table's database after its own chunks.
constexpr uint64_t kStepRangesKey = uint64_t(0x01) << 56;
std::array<std::byte, 8> step_ranges_key(uint64_t chunk) { return big_endian_id(kStepRangesKey | chunk); }

uint64_t id_from_big_endian(lmdb::Bytes key) {
  uint64_t id = 0;
  for (std::byte b : key) id = (id << 8) | uint64_t(b);
  return id;
}

bool known_database(const std::string& name) {
  for (const char* known : {kManifestDb, kNodesDb, kBricksDb, kTetClustersDb, kTetsDb, kOctreeDb})
    if (name == known) return true;
  return false;
}

// The octree's page table lives in its database under keys no page has (a page id's top byte
// is its root depth, at most 19 << 1).
constexpr uint64_t kOctreeTableKey = uint64_t(0xff) << 56;
bool is_octree_table_key(lmdb::Bytes key) { return key.size() == 8 && key[0] == std::byte{0xff}; }

uint64_t elapsed_ns(std::chrono::steady_clock::time_point since) {
  return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - since).count());
}

/// A loader thread's reader: one read snapshot, kept while it reads (the store is immutable).
class StoreReader final : public PageReader {
 public:
  StoreReader(const Store& store, int step) : store_(store), step_(step), txn_(store.begin_read()) {}
  PageRead read(const PageKey& key, std::span<std::byte> out) override { return store_.read_page(txn_, key, out, step_); }

 private:
  const Store& store_;
  int step_;
  lmdb::ReadTxn txn_;
};

/// Time step `step` (1 or later) of a grid of several, as the cache's L3 sees it: the store's
/// records of that step under the same page keys as step 0's, so that a cache holds one step.
class StepPages final : public PageSource {
 public:
  StepPages(const Store& store, int step) : store_(store), step_(step), name_(fmt::format("{} (time step {})", store.path(), step)) {}
  const std::string& source_name() const override { return name_; }
  std::vector<PageKindInfo> page_kinds() const override { return store_.page_kinds(); }
  std::unique_ptr<PageReader> open_reader() const override { return std::make_unique<StoreReader>(store_, step_); }
  std::string describe(const PageKey& key) const override { return fmt::format("{} of time step {}", store_.describe(key), step_); }

 private:
  const Store& store_;
  int step_;
  std::string name_;
};

}  // namespace

bool is_store_directory(const std::string& dir) {
  std::error_code ec;
  return fs::is_regular_file(fs::path(dir) / "data.mdb", ec);
}

StoreState probe_store(const std::string& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) return StoreState::absent;
  if (!fs::is_directory(dir, ec)) return StoreState::not_a_store;
  if (!is_store_directory(dir)) return fs::is_empty(dir, ec) ? StoreState::absent : StoreState::not_a_store;
  lmdb::EnvOptions options;
  options.read_only = true;
  std::unique_ptr<lmdb::Env> env;
  try {
    env = std::make_unique<lmdb::Env>(dir, options);
  } catch (const Error&) {
    return StoreState::not_a_store;
  }
  bool other = false;
  const auto names = env->database_names(&other);
  if (other) return StoreState::not_a_store;
  if (names.empty()) return StoreState::incomplete;  // killed before the first commit
  for (const auto& n : names)
    if (!known_database(n)) return StoreState::not_a_store;
  const auto db = env->open_database(kManifestDb, false);
  lmdb::ReadTxn txn(*env);
  auto text = txn.get(db, lmdb::as_bytes(kManifestKey));
  if (!text) return StoreState::incomplete;
  try {
    const Manifest m = Manifest::from_json(std::string(reinterpret_cast<const char*>(text->data()), text->size()), dir);
    return m.complete ? StoreState::complete : StoreState::incomplete;
  } catch (const Error&) {
    return StoreState::not_a_store;
  }
}

void remove_store_files(const std::string& dir) {
  for (const char* name : {"data.mdb", "lock.mdb"}) {
    std::error_code ec;
    fs::remove(fs::path(dir) / name, ec);
    if (ec) throw Error(Errc::io, fmt::format("cannot remove {}: {}", name, ec.message())).with_file(dir);
  }
}

namespace {
std::unique_ptr<lmdb::Env> open_existing(const std::string& dir, bool writable = false) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) throw Error(Errc::not_found, "no such store").with_file(dir);
  if (!fs::is_directory(dir, ec)) throw Error(Errc::format, "not a brickyard store (not a directory)").with_file(dir);
  if (!is_store_directory(dir)) throw Error(Errc::format, "not a brickyard store (no data.mdb)").with_file(dir);
  lmdb::EnvOptions options;
  options.read_only = !writable;
  auto env = std::make_unique<lmdb::Env>(dir, options);
  if (!env->has_database(kManifestDb)) throw Error(Errc::format, "not a brickyard store (no manifest)").with_file(dir);
  return env;
}

Manifest load_manifest(const lmdb::ReadTxn& txn, const lmdb::Database& db, const std::string& dir) {
  auto text = txn.get(db, lmdb::as_bytes(kManifestKey));
  if (!text) throw Error(Errc::format, "not a brickyard store (empty manifest database)").with_file(dir);
  if (auto sum = txn.get(db, lmdb::as_bytes(kManifestChecksumKey))) {
    const uint64_t actual = XXH3_64bits(text->data(), text->size());
    if (sum->size() != 8 || read_le64(sum->data()) != actual)
      throw Error(Errc::corrupt, fmt::format("the manifest fails its checksum: stored {}, computed {:016x}",
                                             sum->size() == 8 ? fmt::format("{:016x}", read_le64(sum->data()))
                                                              : fmt::format("{} bytes", sum->size()),
                                             actual))
          .with_file(dir)
          .with_key("manifest");
  }
  return Manifest::from_json(std::string(reinterpret_cast<const char*>(text->data()), text->size()), dir);
}
}  // namespace

Manifest read_manifest(const std::string& dir) {
  auto env = open_existing(dir);
  const auto db = env->open_database(kManifestDb, false);
  const lmdb::ReadTxn txn(*env);
  return load_manifest(txn, db, dir);
}

// Checkpoint record: magic, raw size (u64), XXH3-64 of the raw bytes, then chunks of at most
// kCheckpointChunk raw bytes, each its raw and compressed sizes (u32) and its LZ4 block.
std::optional<std::vector<std::byte>> read_build_checkpoint(const std::string& dir) {
  auto env = open_existing(dir);
  const auto db = env->open_database(kManifestDb, false);
  const lmdb::ReadTxn txn(*env);
  const auto rec = txn.get(db, lmdb::as_bytes(kCheckpointKey));
  if (!rec || rec->size() < 20) return std::nullopt;
  const std::byte* p = rec->data();
  const std::byte* end = p + rec->size();
  uint32_t magic = 0;
  uint64_t raw = 0, sum = 0;
  std::memcpy(&magic, p, 4), std::memcpy(&raw, p + 4, 8), std::memcpy(&sum, p + 12, 8);
  p += 20;
  if (magic != kCheckpointMagic || raw > (uint64_t(1) << 40)) return std::nullopt;
  std::vector<std::byte> out(raw);
  uint64_t at = 0;
  while (at < raw) {
    uint32_t n = 0, c = 0;
    if (end - p < 8) return std::nullopt;
    std::memcpy(&n, p, 4), std::memcpy(&c, p + 4, 4);
    p += 8;
    if (n > raw - at || c > uint64_t(end - p)) return std::nullopt;
    const int got = LZ4_decompress_safe(reinterpret_cast<const char*>(p), reinterpret_cast<char*>(out.data() + at),
                                        int(c), int(n));
    if (got != int(n)) return std::nullopt;
    p += c, at += n;
  }
  if (p != end || XXH3_64bits(out.data(), out.size()) != sum) return std::nullopt;
  return out;
}

Store::Store(const std::string& dir, OpenOptions options) : path_(dir) {
  env_ = open_existing(dir, options.writable);
  manifest_db_ = env_->open_database(kManifestDb, false);
  // Every database is opened first, then the manifest and the tables are read in one read
  // transaction: a writer changing the store meanwhile (build-octree on a live store replaces
  // the octree table and the manifest together) is seen whole or not at all, never an old
  // manifest beside a new or missing table.
  const auto open_if_present = [&](const char* name, lmdb::Database& db) {
    if (env_->has_database(name)) db = env_->open_database(name, false);
  };
  open_if_present(kNodesDb, nodes_db_);
  open_if_present(kBricksDb, bricks_db_);
  open_if_present(kOctreeDb, octree_db_);
  open_if_present(kTetClustersDb, clusters_db_);
  open_if_present(kTetsDb, tets_db_);
  const lmdb::ReadTxn txn(*env_);
  manifest_ = load_manifest(txn, manifest_db_, dir);
  if (!manifest_.complete && !options.allow_incomplete)
    throw Error(Errc::format, "the store is incomplete: its build was interrupted or failed; run the import again")
        .with_file(dir);
  DatasetInfo info;
  info.name = dir;
  info.kind = manifest_.kind;
  info.min_value = manifest_.min_value;
  info.max_value = manifest_.max_value;
  info.time_steps = manifest_.time_steps;
  info.source = manifest_.source;
  if (manifest_.kind == DataKind::tetrahedral) {
    load_cluster_table(txn);
    info.world = manifest_.mesh.bounds;
    // A mesh's unit: the edge of a cube holding one tetrahedron's share of the box, a stand-in
    // for the mean edge length that needs no pass over the tetrahedra.
    const Vec3d e = info.world.extent();
    const double volume = std::max(e.x, 1e-300) * std::max(e.y, 1e-300) * std::max(e.z, 1e-300);
    info.unit_length = manifest_.mesh.tets ? std::cbrt(volume / double(manifest_.mesh.tets)) : 1.0;
    datasets_.push_back(std::make_unique<Dataset>(std::move(info), std::nullopt,
                                                  TetView(clusters_, size_t(manifest_.mesh.page_bytes), manifest_.time_steps,
                                                          step_ranges_)));
    return;
  }
  layout_ = manifest_.layout();
  // Step 0's node table now, the others when first asked for: a scene of one step of a long
  // series loads that step's table, not every one.
  nodes_.resize(size_t(manifest_.time_steps));
  steps_loaded_ = std::make_unique<std::atomic<bool>[]>(size_t(manifest_.time_steps));
  load_node_table(txn, 0);
  steps_loaded_[0].store(true, std::memory_order_release);
  info.world = Box3d(manifest_.origin, manifest_.origin + manifest_.spacing * Vec3d(manifest_.dims - Vec3s(1)));
  info.unit_length = min_component(manifest_.spacing);
  std::optional<OctreeView> octree;
  if (manifest_.octree) {
    if (octree_db_.name.empty())
      throw Error(Errc::corrupt, "the manifest records an octree volume but the store has no octree database").with_file(dir);
    load_octree_table(txn);
    octree.emplace(octree_layout(), *manifest_.octree, std::span<const OctreePageRange>(octree_pages_));
  }
  for (int step = 0; step < manifest_.time_steps; ++step) {
    datasets_.push_back(std::make_unique<Dataset>(
        info, GridView(nodes_[size_t(step)], manifest_.format.shape(), manifest_.origin, manifest_.spacing), std::nullopt,
        step == 0 ? std::move(octree) : std::nullopt));
    if (step > 0) step_sources_.push_back(std::make_unique<StepPages>(*this, step));
  }
}

void Store::check_step(int step) const {
  if (step < 0 || step >= manifest_.time_steps)
    throw Error(Errc::invalid_argument, fmt::format("time step {} of a dataset with {} (0 to {})", step, manifest_.time_steps,
                                                    manifest_.time_steps - 1))
        .with_file(path_)
        .with_field("time_step");
}

const Dataset& Store::dataset(int step) const {
  if (kind() != DataKind::structured) {
    check_step(step);
    return *datasets_.front();
  }
  (void)nodes(step);  // its view points at the step's node table: loaded first
  return *datasets_[size_t(step)];
}

const PageSource& Store::step_pages(int step) const {
  check_step(step);
  if (step == 0 || kind() != DataKind::structured) return *this;
  return *step_sources_[size_t(step - 1)];
}

const NodeTable& Store::nodes(int step) const {
  check_step(step);
  // Not std::call_once: a load that throws (a damaged table) must leave the step unloaded for
  // the next call, and libstdc++'s call_once over pthread_once does not survive an exception
  // everywhere (under TSan the next call waits forever).
  if (!steps_loaded_[size_t(step)].load(std::memory_order_acquire)) {
    const std::lock_guard lock(steps_mutex_);
    if (!steps_loaded_[size_t(step)].load(std::memory_order_relaxed)) {
      const lmdb::ReadTxn txn(*env_);
      load_node_table(txn, step);
      steps_loaded_[size_t(step)].store(true, std::memory_order_release);
    }
  }
  return nodes_[size_t(step)];
}

void Store::load_node_table(const lmdb::ReadTxn& txn, int step) const {
  const std::string& dir = path_;
  NodeTable& table = nodes_[size_t(step)];
  table = NodeTable(layout_);
  if (nodes_db_.name.empty() || bricks_db_.name.empty()) {
    if (manifest_.complete) throw Error(Errc::corrupt, "complete store without node or brick database").with_file(dir);
    return;  // an incomplete store may have neither yet
  }
  if (!manifest_.complete) return;  // the node table is written last

  const bool series = manifest_.time_steps > 1;
  const std::string of_step = series ? fmt::format(" of time step {}", step) : "";
  for (int level = 0; level < layout_.levels; ++level) {
    auto& records = table.level(level);
    for (size_t start = 0, chunk = 0; start < records.size(); start += kNodesPerChunk, ++chunk) {
      const KeyBytes key = keyed(series, step, node_chunk_key(uint32_t(level), uint32_t(chunk)));
      const size_t n = std::min(kNodesPerChunk, records.size() - start);
      read_table_chunk(txn.get(nodes_db_, key.span()), n * sizeof(NodeRecord),
                       fmt::format("node table chunk {} of level {}{}", chunk, level, of_step), dir, records.data() + start);
    }
    // What the builder writes, and what readers rely on: an ordered range (its bounds may be
    // infinite: a conservative bound of values near the largest float rounds out to infinity),
    // and a constant value of the store's type. A chunk without a checksum, or a forged one,
    // may hold anything.
    for (size_t i = 0; i < records.size(); ++i) {
      const NodeRecord& r = records[i];
      if (!(r.min <= r.max))
        throw Error(Errc::corrupt, fmt::format("the node table gives the brick the value range [{}, {}]", r.min, r.max))
            .with_file(dir)
            .with_key(layout_.key_at(level, int64_t(i)).to_string());
      if (r.is_constant() && !holds_value(manifest_.format.type, r.constant))
        throw Error(Errc::corrupt, fmt::format("the node table gives the brick the constant value {}, which is not a {} value{}",
                                               r.constant, to_string(manifest_.format.type),
                                               is_integer(manifest_.format.type)
                                                   ? fmt::format(" (a whole number in [{:g}, {:g}])",
                                                                 integer_min(manifest_.format.type),
                                                                 integer_max(manifest_.format.type))
                                                   : std::string(" (a finite number)")))
            .with_file(dir)
            .with_key(layout_.key_at(level, int64_t(i)).to_string());
    }
  }
}

void Store::load_octree_table(const lmdb::ReadTxn& txn) {
  octree_pages_.resize(size_t(manifest_.octree->pages));
  for (size_t start = 0, chunk = 0; start < octree_pages_.size(); start += kNodesPerChunk, ++chunk) {
    const size_t n = std::min(kNodesPerChunk, octree_pages_.size() - start);
    read_table_chunk(txn.get(octree_db_, big_endian_id(kOctreeTableKey | chunk)), n * sizeof(OctreePageRange),
                     fmt::format("octree page table chunk {}", chunk), path_, octree_pages_.data() + start);
  }
  for (size_t i = 1; i < octree_pages_.size(); ++i)
    if (!(octree_pages_[i - 1].id < octree_pages_[i].id))
      throw Error(Errc::corrupt, fmt::format("octree page table is not sorted at entry {}", i)).with_file(path_);
}

void Store::load_cluster_table(const lmdb::ReadTxn& txn) {
  const std::string& dir = path_;
  if (clusters_db_.name.empty() || tets_db_.name.empty()) {
    if (manifest_.complete) throw Error(Errc::corrupt, "complete mesh store without cluster or tet database").with_file(dir);
    return;
  }
  if (!manifest_.complete) return;  // the cluster table is written last
  clusters_.resize(size_t(manifest_.mesh.clusters));
  for (size_t start = 0, chunk = 0; start < clusters_.size(); start += kNodesPerChunk, ++chunk) {
    const size_t n = std::min(kNodesPerChunk, clusters_.size() - start);
    read_table_chunk(txn.get(clusters_db_, big_endian_id(chunk)), n * sizeof(TetCluster), fmt::format("cluster table chunk {}", chunk),
                     dir, clusters_.data() + start);
  }
  if (manifest_.time_steps > 1) {
    const size_t per_chunk = kNodesPerChunk, steps = size_t(manifest_.time_steps);
    step_ranges_.resize(clusters_.size() * steps);
    for (size_t start = 0, chunk = 0; start < step_ranges_.size(); start += per_chunk, ++chunk) {
      const size_t n = std::min(per_chunk, step_ranges_.size() - start);
      read_table_chunk(txn.get(clusters_db_, step_ranges_key(chunk)), n * sizeof(TetStepRange),
                       fmt::format("time-step range chunk {}", chunk), dir, step_ranges_.data() + start);
    }
  }
  const uint32_t steps = uint32_t(manifest_.time_steps), sets = manifest_.mesh.position_sets(manifest_.time_steps);
  for (size_t c = 0; c < clusters_.size(); ++c)
    if (TetClusterPage::bytes(clusters_[c].vertices, clusters_[c].tets, steps, sets) > manifest_.mesh.page_bytes)
      throw Error(Errc::corrupt, fmt::format("cluster {} of {} vertices and {} tetrahedra does not fit the store's "
                                             "{}-byte pages", c, clusters_[c].vertices, clusters_[c].tets,
                                             manifest_.mesh.page_bytes))
          .with_file(dir)
          .with_field("mesh.page_bytes");
}

Store::~Store() = default;

std::optional<std::span<const std::byte>> Store::record(const lmdb::ReadTxn& txn, const BrickKey& key, int step) const {
  check_step(step);
  return txn.get(bricks_db_, keyed(manifest_.time_steps > 1, step, brick_key_bytes(key)).span());
}

void Store::read_brick(const lmdb::ReadTxn& txn, const BrickKey& key, std::span<std::byte> out, int step) const {
  if (!layout_.contains(key))
    throw Error(Errc::not_found, fmt::format("brick is outside the store's {} levels", layout_.levels))
        .with_file(path_)
        .with_key(key.to_string());
  BY_CHECK_EQ(out.size(), format().bytes());
  const NodeRecord& node = nodes(step).at(key);
  if (node.is_constant()) {
    dispatch_value_type(format().type, [&](auto tag) {
      using T = decltype(tag);
      std::fill_n(reinterpret_cast<T*>(out.data()), format().voxels(), static_cast<T>(node.constant));
    });
    return;
  }
  auto rec = record(txn, key, step);
  if (!rec) throw Error(Errc::corrupt, "brick record is missing").with_file(path_).with_key(key.to_string());
  try {
    decode_brick(format(), key, *rec, out);
  } catch (Error& e) {
    e.with_file(path_);
    throw;
  }
}

void Store::read_brick(const BrickKey& key, std::span<std::byte> out, int step) const {
  auto txn = begin_read();
  read_brick(txn, key, out, step);
}

std::vector<PageKindInfo> Store::page_kinds() const {
  if (kind() == DataKind::tetrahedral) return {{RecordKind::tet_cluster, size_t(manifest_.mesh.page_bytes), manifest_.mesh.clusters}};
  uint64_t stored = 0;  // a step's, on average: the stats are summed over the steps
  for (const LevelStats& l : manifest_.stats) stored += uint64_t(l.bricks - l.constant) / uint64_t(manifest_.time_steps);
  std::vector<PageKindInfo> kinds{{RecordKind::brick, format().bytes(), stored}};
  if (manifest_.octree) kinds.push_back({RecordKind::octree_page, size_t(manifest_.octree->page_bytes), manifest_.octree->pages});
  return kinds;
}

std::unique_ptr<PageReader> Store::open_reader() const { return std::make_unique<StoreReader>(*this, 0); }

std::string Store::describe(const PageKey& key) const {
  if (key.kind == RecordKind::brick) return BrickKey::from_code(key.id).to_string();
  if (key.kind == RecordKind::tet_cluster) return fmt::format("cluster {}", key.id);
  if (key.kind == RecordKind::octree_page) return describe_octree_page(key.id);
  return to_string(key);
}

PageRead Store::read_page(const lmdb::ReadTxn& txn, const PageKey& key, std::span<std::byte> out, int step) const {
  const bool brick = key.kind == RecordKind::brick && kind() == DataKind::structured;
  const bool cluster = key.kind == RecordKind::tet_cluster && kind() == DataKind::tetrahedral;
  if (key.kind == RecordKind::octree_page && manifest_.octree) return read_octree_page(txn, key, out);
  if (!brick && !cluster)
    throw Error(Errc::not_found, fmt::format("a {} store holds no {} records", to_string(kind()), to_string(key.kind)))
        .with_file(path_)
        .with_key(describe(key));
  PageRead read;
  if (brick) {
    const BrickKey k = BrickKey::from_code(key.id);
    if (!layout_.contains(k))
      throw Error(Errc::not_found, fmt::format("brick is outside the store's {} levels", layout_.levels))
          .with_file(path_)
          .with_key(k.to_string());
    if (nodes(step).at(k).is_constant()) {  // no record: the node's value, as read_brick gives it
      read_brick(txn, k, out, step);
      return read;
    }
    auto rec = record(txn, k, step);
    if (!rec) throw Error(Errc::corrupt, "brick record is missing").with_file(path_).with_key(k.to_string());
    read.stored_bytes = rec->size();
    const auto start = std::chrono::steady_clock::now();
    try {
      decode_brick(format(), k, *rec, out);
    } catch (Error& e) {
      e.with_file(path_);
      throw;
    }
    read.decode_ns = elapsed_ns(start);
    return read;
  }
  if (key.id >= clusters_.size())
    throw Error(Errc::not_found, fmt::format("the mesh has {} clusters", clusters_.size())).with_file(path_).with_key(describe(key));
  if (out.size() != manifest_.mesh.page_bytes)
    throw Error(Errc::internal, fmt::format("a {}-byte buffer for {}-byte cluster pages", out.size(), manifest_.mesh.page_bytes));
  auto rec = txn.get(tets_db_, big_endian_id(key.id));
  if (!rec) throw Error(Errc::corrupt, "cluster record is missing").with_file(path_).with_key(describe(key));
  read.stored_bytes = rec->size();
  const auto start = std::chrono::steady_clock::now();
  size_t used = 0;
  try {
    used = decode_page(key, *rec, out);
  } catch (Error& e) {
    e.with_file(path_).with_key(describe(key));  // "cluster 18", as verify names it
    throw;
  }
  const TetCluster& c = clusters_[key.id];
  const size_t expected = TetClusterPage::bytes(c.vertices, c.tets, uint32_t(manifest_.time_steps),
                                                manifest_.mesh.position_sets(manifest_.time_steps));
  // A page may carry its BVH after its tetrahedra (import --bvh): only then may it be longer.
  const bool with_bvh = used > expected && manifest_.build.find("\"bvh\"") != std::string::npos;
  if (used != expected && !with_bvh)
    throw Error(Errc::corrupt, fmt::format("cluster page holds {} bytes, its table entry ({} vertices, {} tetrahedra) {}",
                                           used, c.vertices, c.tets, expected))
        .with_file(path_)
        .with_key(describe(key));
  read.decode_ns = elapsed_ns(start);
  return read;
}

PageRead Store::read_octree_page(const lmdb::ReadTxn& txn, const PageKey& key, std::span<std::byte> out) const {
  const OctreeLayout layout = octree_layout();
  if (out.size() != manifest_.octree->page_bytes)
    throw Error(Errc::internal, fmt::format("a {}-byte buffer for {}-byte octree pages", out.size(), manifest_.octree->page_bytes));
  const BrickKey root = BrickKey::from_code(key.id);
  const Vec3s nodes = root.level <= uint32_t(layout.cap_page_root()) ? layout.nodes_at(int(root.level)) : Vec3s(0);
  if (!layout.is_page_root(int(root.level)) || int64_t(root.x) >= nodes.x || int64_t(root.y) >= nodes.y ||
      int64_t(root.z) >= nodes.z)
    throw Error(Errc::not_found, fmt::format("no page of an octree of depth {} is rooted there", layout.depth))
        .with_file(path_)
        .with_key(describe(key));
  auto rec = txn.get(octree_db_, big_endian_id(key.id));
  if (!rec)
    throw Error(Errc::not_found, "the octree stores no such page (its subtree is consolidated or outside the volume)")
        .with_file(path_)
        .with_key(describe(key));
  PageRead read;
  read.stored_bytes = rec->size();
  const auto start = std::chrono::steady_clock::now();
  try {
    decode_page(key, *rec, out);
    dispatch_value_type(layout.type, [&](auto t) {
      const auto page = OctreePage<decltype(t)>::view(out, layout);
      if (page.header->root_depth != root.level)
        throw Error(Errc::corrupt, fmt::format("the page says it is rooted at depth {}", page.header->root_depth));
    });
  } catch (Error& e) {
    e.with_file(path_).with_key(describe(key));
    throw;
  }
  read.decode_ns = elapsed_ns(start);
  return read;
}

void Store::for_each_page(const lmdb::ReadTxn& txn, RecordKind kind,
                          const std::function<bool(const PageKey&, std::span<const std::byte>)>& f) const {
  if (kind == RecordKind::octree_page) {
    if (!manifest_.octree) return;
    txn.for_each(octree_db_, [&](lmdb::Bytes key, lmdb::Bytes value) {
      if (is_octree_table_key(key)) return true;
      if (key.size() != 8) throw Error(Errc::corrupt, fmt::format("octree page key of {} bytes", key.size())).with_file(path_);
      return f({RecordKind::octree_page, id_from_big_endian(key)}, value);
    });
    return;
  }
  if (kind == RecordKind::brick) {
    for_each_record(txn, [&](const BrickKey& k, std::span<const std::byte> r) { return f({RecordKind::brick, k.code()}, r); });
    return;
  }
  if (kind != RecordKind::tet_cluster || this->kind() != DataKind::tetrahedral) return;
  txn.for_each(tets_db_, [&](lmdb::Bytes key, lmdb::Bytes value) {
    if (key.size() != 8) throw Error(Errc::corrupt, fmt::format("cluster key of {} bytes", key.size())).with_file(path_);
    return f({RecordKind::tet_cluster, id_from_big_endian(key)}, value);
  });
}

void Store::for_each_record(const lmdb::ReadTxn& txn,
                                 const std::function<bool(const BrickKey&, std::span<const std::byte>)>& f) const {
  for_each_step_record(txn, [&](int, const BrickKey& k, std::span<const std::byte> r) { return f(k, r); });
}

void Store::for_each_step_record(const lmdb::ReadTxn& txn,
                                 const std::function<bool(int, const BrickKey&, std::span<const std::byte>)>& f) const {
  const bool series = manifest_.time_steps > 1;
  const size_t width = series ? 12 : 8;
  txn.for_each(bricks_db_, [&](lmdb::Bytes key, lmdb::Bytes value) {
    if (key.size() != width)
      throw Error(Errc::corrupt, fmt::format("brick key of {} bytes (a {} has {}-byte keys)", key.size(),
                                             series ? "grid of several time steps" : "grid", width))
          .with_file(path_);
    uint32_t step = 0;
    for (size_t i = 0; series && i < 4; ++i) step = (step << 8) | uint32_t(key[i]);
    return f(int(step), BrickKey::from_bytes(reinterpret_cast<const uint8_t*>(key.data() + width - 8)), value);
  });
}

uint64_t Store::record_count() const {
  auto txn = begin_read();
  return txn.count(kind() == DataKind::tetrahedral ? tets_db_ : bricks_db_);
}

StoreWriter::StoreWriter(const std::string& dir, const Manifest& initial, const lmdb::EnvOptions& options,
                         uint64_t batch_bytes)
    : kind_(initial.kind), time_steps_(initial.time_steps) {
  if (is_store_directory(dir)) throw Error(Errc::internal, "StoreWriter needs a directory without a store").with_file(dir);
  env_ = std::make_unique<lmdb::Env>(dir, options);
  manifest_db_ = env_->open_database(kManifestDb, true);
  if (kind_ == DataKind::tetrahedral) {
    clusters_db_ = env_->open_database(kTetClustersDb, true);
    tets_db_ = env_->open_database(kTetsDb, true);
  } else {
    nodes_db_ = env_->open_database(kNodesDb, true);
    bricks_db_ = env_->open_database(kBricksDb, true);
  }
  writer_ = std::make_unique<lmdb::BatchWriter>(*env_, batch_bytes);
  Manifest m = initial;
  m.complete = false;
  if (kind_ == DataKind::tetrahedral) m.format_version = std::max(m.format_version, kMeshStoreFormatVersion);
  if (kind_ == DataKind::structured && time_steps_ > 1) m.format_version = std::max(m.format_version, kTimeSeriesGridFormatVersion);
  put_manifest(*writer_, manifest_db_, m.to_json());
  writer_->commit();
}

StoreWriter::~StoreWriter() = default;

std::unique_ptr<StoreWriter> StoreWriter::reopen(const std::string& dir, const lmdb::EnvOptions& options,
                                                 uint64_t batch_bytes) {
  std::unique_ptr<StoreWriter> w(new StoreWriter());
  w->env_ = std::make_unique<lmdb::Env>(dir, options);
  w->manifest_db_ = w->env_->open_database(kManifestDb, false);
  w->nodes_db_ = w->env_->open_database(kNodesDb, true);
  w->bricks_db_ = w->env_->open_database(kBricksDb, true);
  w->writer_ = std::make_unique<lmdb::BatchWriter>(*w->env_, batch_bytes);
  {
    const lmdb::ReadTxn txn(*w->env_);
    w->time_steps_ = load_manifest(txn, w->manifest_db_, dir).time_steps;
  }
  return w;
}

void StoreWriter::put_checkpoint(std::span<const std::byte> state) {
  std::vector<std::byte> rec(20);
  const uint32_t magic = kCheckpointMagic;
  const uint64_t raw = state.size(), sum = XXH3_64bits(state.data(), state.size());
  std::memcpy(rec.data(), &magic, 4), std::memcpy(rec.data() + 4, &raw, 8), std::memcpy(rec.data() + 12, &sum, 8);
  for (size_t at = 0; at < state.size(); at += kCheckpointChunk) {
    const uint32_t n = uint32_t(std::min(kCheckpointChunk, state.size() - at));
    const size_t head = rec.size();
    rec.resize(head + 8 + size_t(LZ4_compressBound(int(n))));
    const int c = LZ4_compress_default(reinterpret_cast<const char*>(state.data() + at),
                                       reinterpret_cast<char*>(rec.data() + head + 8), int(n), LZ4_compressBound(int(n)));
    if (c <= 0) throw Error(Errc::internal, "LZ4 compression of the build checkpoint failed").with_file(env_->path());
    const uint32_t cs = uint32_t(c);
    std::memcpy(rec.data() + head, &n, 4), std::memcpy(rec.data() + head + 4, &cs, 4);
    rec.resize(head + 8 + cs);
  }
  writer_->put(manifest_db_, lmdb::as_bytes(kCheckpointKey), std::move(rec));
  writer_->commit();
}

void StoreWriter::put_brick(const BrickKey& key, std::vector<std::byte>&& record, int step) {
  BY_CHECK(kind_ == DataKind::structured && step >= 0 && step < time_steps_);
  writer_->put(bricks_db_, keyed(time_steps_ > 1, step, brick_key_bytes(key)).span(), std::move(record));
}

void StoreWriter::put_step_nodes(int step, const NodeTable& nodes) {
  BY_CHECK(kind_ == DataKind::structured && time_steps_ > 1 && step >= 0 && step < time_steps_);
  const GridLayout& layout = nodes.layout();
  for (int level = 0; level < layout.levels; ++level) {
    const auto& records = nodes.level(level);
    for (size_t start = 0, chunk = 0; start < records.size(); start += kNodesPerChunk, ++chunk) {
      const size_t n = std::min(kNodesPerChunk, records.size() - start);
      writer_->put(nodes_db_, keyed(true, step, node_chunk_key(uint32_t(level), uint32_t(chunk))).span(),
                   checksummed_chunk(records.data() + start, n * sizeof(NodeRecord)));
    }
  }
}

void StoreWriter::finish_series(const Manifest& final_manifest) {
  BY_CHECK(kind_ == DataKind::structured && time_steps_ > 1 && final_manifest.time_steps == time_steps_);
  BY_CHECK_EQ(final_manifest.step_ranges.size(), size_t(time_steps_));
  writer_->commit();
  env_->sync();  // every brick and node table is durable before anything claims the store is complete
  Manifest m = final_manifest;
  m.format_version = std::max(m.format_version, kTimeSeriesGridFormatVersion);
  commit_final(m);
}

void StoreWriter::put_cluster(uint64_t cluster, std::span<const std::byte> page) {
  BY_CHECK(kind_ == DataKind::tetrahedral);
  writer_->put(tets_db_, big_endian_id(cluster), encode_page({RecordKind::tet_cluster, cluster}, page));
}

void StoreWriter::put_cluster_record(uint64_t cluster, std::vector<std::byte>&& record) {
  BY_CHECK(kind_ == DataKind::tetrahedral);
  writer_->put(tets_db_, big_endian_id(cluster), std::move(record));
}

void StoreWriter::finish(const Manifest& final_manifest, const NodeTable& nodes) {
  BY_CHECK(kind_ == DataKind::structured && final_manifest.kind == DataKind::structured && time_steps_ == 1);
  writer_->commit();
  env_->sync();  // every brick is durable before anything claims the store is complete
  const GridLayout& layout = nodes.layout();
  for (int level = 0; level < layout.levels; ++level) {
    const auto& records = nodes.level(level);
    for (size_t start = 0, chunk = 0; start < records.size(); start += kNodesPerChunk, ++chunk) {
      const size_t n = std::min(kNodesPerChunk, records.size() - start);
      writer_->put(nodes_db_, node_chunk_key(uint32_t(level), uint32_t(chunk)),
                   checksummed_chunk(records.data() + start, n * sizeof(NodeRecord)));
    }
  }
  commit_final(final_manifest);
}

void StoreWriter::finish(const Manifest& final_manifest, const std::vector<TetCluster>& clusters,
                         const std::vector<TetStepRange>& step_ranges) {
  BY_CHECK(final_manifest.time_steps == 1 || step_ranges.size() == clusters.size() * size_t(final_manifest.time_steps));
  BY_CHECK(kind_ == DataKind::tetrahedral && final_manifest.kind == DataKind::tetrahedral);
  BY_CHECK_EQ(final_manifest.mesh.clusters, uint64_t(clusters.size()));
  writer_->commit();
  env_->sync();  // every cluster page is durable before anything claims the store is complete
  for (size_t start = 0, chunk = 0; start < clusters.size(); start += kNodesPerChunk, ++chunk) {
    const size_t n = std::min(kNodesPerChunk, clusters.size() - start);
    writer_->put(clusters_db_, big_endian_id(chunk), checksummed_chunk(clusters.data() + start, n * sizeof(TetCluster)));
  }
  if (final_manifest.time_steps > 1)
    for (size_t start = 0, chunk = 0; start < step_ranges.size(); start += kNodesPerChunk, ++chunk) {
      const size_t n = std::min(kNodesPerChunk, step_ranges.size() - start);
      writer_->put(clusters_db_, step_ranges_key(chunk), checksummed_chunk(step_ranges.data() + start, n * sizeof(TetStepRange)));
    }
  Manifest m = final_manifest;
  m.format_version = std::max(m.format_version, kMeshStoreFormatVersion);
  commit_final(m);
}

void StoreWriter::commit_final(Manifest m) {
  m.complete = true;
  // One transaction: the table and the complete flag appear together or not at all, and the
  // checkpoint of a resumed build goes with them.
  const std::string text = m.to_json();
  put_manifest(*writer_, manifest_db_, text);
  writer_->erase(manifest_db_, lmdb::as_bytes(kCheckpointKey));
  env_->set_no_sync(false);
  writer_->commit();
}

// ------------------------------------------------------------------------------ OctreeWriter

OctreeWriter::OctreeWriter(Store& store, uint64_t batch_bytes) : store_(store) {
  if (store.kind() != DataKind::structured)
    throw Error(Errc::unsupported, "an octree volume is built over a grid; this store is a tetrahedral mesh").with_file(store.path());
  if (store.env_->options().read_only) throw Error(Errc::internal, "OctreeWriter needs a store opened writable").with_file(store.path());
  if (store.time_steps() > 1)
    throw Error(Errc::unsupported, fmt::format("an octree volume is built over a grid of one time step; this one has {}",
                                               store.time_steps()))
        .with_file(store.path());
  writer_ = std::make_unique<lmdb::BatchWriter>(*store.env_, batch_bytes);
  if (store.manifest_.octree) {  // the manifest stops claiming the old octree before its pages go
    Manifest m = store.manifest_;
    m.octree.reset();
    put_manifest(*writer_, store.manifest_db_, m.to_json());
    writer_->commit();
    store.manifest_ = m;
  }
  store.octree_db_ = store.env_->open_database(kOctreeDb, true);
  store.env_->clear_database(store.octree_db_);
}

OctreeWriter::~OctreeWriter() = default;

size_t OctreeWriter::put_page(uint64_t id, std::span<const std::byte> page) {
  auto record = encode_page({RecordKind::octree_page, id}, page);
  const size_t n = record.size();
  writer_->put(store_.octree_db_, big_endian_id(id), std::move(record));
  return n;
}

void OctreeWriter::finish(const OctreeSummary& summary, std::vector<OctreePageRange> pages) {
  BY_CHECK_EQ(summary.pages, uint64_t(pages.size()));
  std::sort(pages.begin(), pages.end(), [](const OctreePageRange& a, const OctreePageRange& b) { return a.id < b.id; });
  writer_->commit();
  store_.env_->sync();  // every page is durable before the manifest claims the octree
  for (size_t start = 0, chunk = 0; start < pages.size(); start += kNodesPerChunk, ++chunk) {
    const size_t n = std::min(kNodesPerChunk, pages.size() - start);
    writer_->put(store_.octree_db_, big_endian_id(kOctreeTableKey | chunk), checksummed_chunk(pages.data() + start, n * sizeof(OctreePageRange)));
  }
  Manifest m = store_.manifest_;
  m.octree = summary;
  put_manifest(*writer_, store_.manifest_db_, m.to_json());
  writer_->commit();
  store_.env_->sync();
  store_.manifest_ = m;
  store_.octree_pages_ = std::move(pages);
}

}  // namespace brickyard
