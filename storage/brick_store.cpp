#include "storage/brick_store.h"

#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;
constexpr size_t kNodesPerChunk = 65536;  // 1 MiB node-table records
const std::string kManifestKey = "manifest";

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
    if (n != kManifestDb && n != kNodesDb && n != kBricksDb) return StoreState::not_a_store;
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
std::unique_ptr<lmdb::Env> open_existing(const std::string& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) throw Error(Errc::not_found, "no such store").with_file(dir);
  if (!fs::is_directory(dir, ec)) throw Error(Errc::format, "not a brickyard store (not a directory)").with_file(dir);
  if (!is_store_directory(dir)) throw Error(Errc::format, "not a brickyard store (no data.mdb)").with_file(dir);
  lmdb::EnvOptions options;
  options.read_only = true;
  auto env = std::make_unique<lmdb::Env>(dir, options);
  if (!env->has_database(kManifestDb)) throw Error(Errc::format, "not a brickyard store (no manifest)").with_file(dir);
  return env;
}

Manifest load_manifest(lmdb::Env& env, const lmdb::Database& db, const std::string& dir) {
  lmdb::ReadTxn txn(env);
  auto text = txn.get(db, lmdb::as_bytes(kManifestKey));
  if (!text) throw Error(Errc::format, "not a brickyard store (empty manifest database)").with_file(dir);
  return Manifest::from_json(std::string(reinterpret_cast<const char*>(text->data()), text->size()), dir);
}
}  // namespace

Manifest read_manifest(const std::string& dir) {
  auto env = open_existing(dir);
  const auto db = env->open_database(kManifestDb, false);
  return load_manifest(*env, db, dir);
}

BrickStore::BrickStore(const std::string& dir, OpenOptions options) : path_(dir) {
  env_ = open_existing(dir);
  manifest_db_ = env_->open_database(kManifestDb, false);
  manifest_ = load_manifest(*env_, manifest_db_, dir);
  if (!manifest_.complete && !options.allow_incomplete)
    throw Error(Errc::format, "the store is incomplete: its build was interrupted or failed; run the import again")
        .with_file(dir);
  layout_ = manifest_.layout();
  nodes_ = NodeTable(layout_);
  if (!env_->has_database(kNodesDb) || !env_->has_database(kBricksDb)) {
    if (manifest_.complete) throw Error(Errc::corrupt, "complete store without node or brick database").with_file(dir);
    return;  // an incomplete store may have neither yet
  }
  nodes_db_ = env_->open_database(kNodesDb, false);
  bricks_db_ = env_->open_database(kBricksDb, false);
  if (!manifest_.complete) return;  // the node table is written last

  lmdb::ReadTxn txn(*env_);
  for (int level = 0; level < layout_.levels; ++level) {
    auto& records = nodes_.level(level);
    for (size_t start = 0, chunk = 0; start < records.size(); start += kNodesPerChunk, ++chunk) {
      const auto key = node_chunk_key(uint32_t(level), uint32_t(chunk));
      auto value = txn.get(nodes_db_, key);
      const size_t n = std::min(kNodesPerChunk, records.size() - start);
      if (!value || value->size() != n * sizeof(NodeRecord))
        throw Error(Errc::corrupt,
                    fmt::format("node table chunk {} of level {} is {}", chunk, level,
                                value ? fmt::format("{} bytes, expected {}", value->size(), n * sizeof(NodeRecord)) : "missing"))
            .with_file(dir);
      std::memcpy(records.data() + start, value->data(), value->size());
    }
  }
}

BrickStore::~BrickStore() = default;

std::optional<std::span<const std::byte>> BrickStore::record(const lmdb::ReadTxn& txn, const BrickKey& key) const {
  return txn.get(bricks_db_, brick_key_bytes(key));
}

void BrickStore::read_brick(const lmdb::ReadTxn& txn, const BrickKey& key, std::span<std::byte> out) const {
  if (!layout_.contains(key))
    throw Error(Errc::not_found, fmt::format("brick is outside the store's {} levels", layout_.levels))
        .with_file(path_)
        .with_key(key.to_string());
  BY_CHECK_EQ(out.size(), format().bytes());
  const NodeRecord& node = nodes_.at(key);
  if (node.is_constant()) {
    dispatch_value_type(format().type, [&](auto tag) {
      using T = decltype(tag);
      std::fill_n(reinterpret_cast<T*>(out.data()), format().voxels(), static_cast<T>(node.constant));
    });
    return;
  }
  auto rec = record(txn, key);
  if (!rec) throw Error(Errc::corrupt, "brick record is missing").with_file(path_).with_key(key.to_string());
  try {
    decode_brick(format(), key, *rec, out);
  } catch (Error& e) {
    e.with_file(path_);
    throw;
  }
}

void BrickStore::read_brick(const BrickKey& key, std::span<std::byte> out) const {
  auto txn = begin_read();
  read_brick(txn, key, out);
}

void BrickStore::for_each_record(const lmdb::ReadTxn& txn,
                                 const std::function<bool(const BrickKey&, std::span<const std::byte>)>& f) const {
  txn.for_each(bricks_db_, [&](lmdb::Bytes key, lmdb::Bytes value) {
    if (key.size() != 8) throw Error(Errc::corrupt, fmt::format("brick key of {} bytes", key.size())).with_file(path_);
    return f(BrickKey::from_bytes(reinterpret_cast<const uint8_t*>(key.data())), value);
  });
}

uint64_t BrickStore::record_count() const {
  auto txn = begin_read();
  return txn.count(bricks_db_);
}

StoreWriter::StoreWriter(const std::string& dir, const Manifest& initial, const lmdb::EnvOptions& options,
                         uint64_t batch_bytes) {
  if (is_store_directory(dir)) throw Error(Errc::internal, "StoreWriter needs a directory without a store").with_file(dir);
  env_ = std::make_unique<lmdb::Env>(dir, options);
  manifest_db_ = env_->open_database(kManifestDb, true);
  nodes_db_ = env_->open_database(kNodesDb, true);
  bricks_db_ = env_->open_database(kBricksDb, true);
  writer_ = std::make_unique<lmdb::BatchWriter>(*env_, batch_bytes);
  Manifest m = initial;
  m.complete = false;
  writer_->put(manifest_db_, lmdb::as_bytes(kManifestKey), lmdb::as_bytes(m.to_json()));
  writer_->commit();
}

StoreWriter::~StoreWriter() = default;

void StoreWriter::put_brick(const BrickKey& key, std::vector<std::byte>&& record) {
  writer_->put(bricks_db_, brick_key_bytes(key), std::move(record));
}

void StoreWriter::finish(const Manifest& final_manifest, const NodeTable& nodes) {
  writer_->commit();
  env_->sync();  // every brick is durable before anything claims the store is complete
  const StoreLayout& layout = nodes.layout();
  for (int level = 0; level < layout.levels; ++level) {
    const auto& records = nodes.level(level);
    for (size_t start = 0, chunk = 0; start < records.size(); start += kNodesPerChunk, ++chunk) {
      const size_t n = std::min(kNodesPerChunk, records.size() - start);
      const auto* bytes = reinterpret_cast<const std::byte*>(records.data() + start);
      writer_->put(nodes_db_, node_chunk_key(uint32_t(level), uint32_t(chunk)),
                   std::span<const std::byte>(bytes, n * sizeof(NodeRecord)));
    }
  }
  Manifest m = final_manifest;
  m.complete = true;
  // One transaction: the node table and the complete flag appear together or not at all.
  const std::string text = m.to_json();
  writer_->put(manifest_db_, lmdb::as_bytes(kManifestKey), lmdb::as_bytes(text));
  env_->set_no_sync(false);
  writer_->commit();
}

}  // namespace brickyard
