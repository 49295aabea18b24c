#include "storage/lmdb_env.h"

#include <lmdb.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.h"
#include "core/units.h"

namespace brickyard::lmdb {
namespace {

std::string key_text(Bytes key) {
  if (key.empty()) return {};
  // Printable keys (names) as text, binary keys (brick codes) as hex.
  bool printable = std::all_of(key.begin(), key.end(), [](std::byte b) { return b >= std::byte(32) && b < std::byte(127); });
  if (printable) return std::string(reinterpret_cast<const char*>(key.data()), key.size());
  std::string hex;
  for (std::byte b : key) hex += fmt::format("{:02x}", unsigned(b));
  return hex;
}

Errc errc_of(int rc) {
  switch (rc) {
    case MDB_MAP_FULL:
    case MDB_READERS_FULL:
    case MDB_TXN_FULL:
    case ENOSPC:
    case ENOMEM: return Errc::resource;
    case MDB_NOTFOUND: return Errc::not_found;
    case MDB_CORRUPTED:
    case MDB_PAGE_NOTFOUND:
    case MDB_INVALID: return Errc::corrupt;
    case MDB_VERSION_MISMATCH: return Errc::unsupported;
    default: return Errc::io;
  }
}

/// The one place LMDB return codes become brickyard errors.
[[noreturn]] void fail(int rc, std::string_view op, const std::string& path, std::string_view db = {}, Bytes key = {}) {
  std::string msg = fmt::format("{} failed: {}", op, mdb_strerror(rc));
  if (!db.empty()) msg += fmt::format(" (database '{}')", db);
  Error e(errc_of(rc), msg);
  e.with_file(path);
  if (!key.empty()) e.with_key(key_text(key));
  throw e;
}

MDB_val to_val(Bytes b) { return {b.size(), const_cast<std::byte*>(b.data())}; }
Bytes to_bytes(const MDB_val& v) { return {static_cast<const std::byte*>(v.mv_data), v.mv_size}; }

}  // namespace

std::string error_text(int rc) { return mdb_strerror(rc); }

Env::Env(const std::string& dir, const EnvOptions& options) : path_(dir), options_(options) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    if (options.read_only) throw Error(Errc::not_found, "no such directory").with_file(dir);
    std::filesystem::create_directories(dir, ec);
    if (ec) throw Error(Errc::io, fmt::format("cannot create directory: {}", ec.message())).with_file(dir);
  }
  if (int rc = mdb_env_create(&env_)) fail(rc, "mdb_env_create", path_);
  auto check = [&](int rc, std::string_view op) {
    if (rc) {
      mdb_env_close(env_);
      env_ = nullptr;
      fail(rc, op, path_);
    }
  };
  check(mdb_env_set_maxdbs(env_, options.max_dbs), "mdb_env_set_maxdbs");
  check(mdb_env_set_maxreaders(env_, options.max_readers), "mdb_env_set_maxreaders");
  if (!options.read_only) check(mdb_env_set_mapsize(env_, options.map_size), "mdb_env_set_mapsize");
  unsigned flags = MDB_NOTLS;
  if (options.read_only) flags |= MDB_RDONLY;
  if (options.no_sync) flags |= MDB_NOSYNC;
  if (options.random_access) flags |= MDB_NORDAHEAD;
  check(mdb_env_open(env_, dir.c_str(), flags, 0644), "mdb_env_open");
}

Env::~Env() {
  if (env_) mdb_env_close(env_);
}

Database Env::open_database(const std::string& name, bool create) {
  MDB_txn* txn = nullptr;
  const bool write = create && !options_.read_only;
  if (int rc = mdb_txn_begin(env_, nullptr, write ? 0 : MDB_RDONLY, &txn)) fail(rc, "mdb_txn_begin", path_, name);
  MDB_dbi dbi = 0;
  int rc = mdb_dbi_open(txn, name.c_str(), write ? MDB_CREATE : 0, &dbi);
  if (rc) {
    mdb_txn_abort(txn);
    if (rc == MDB_NOTFOUND)
      throw Error(Errc::not_found, fmt::format("database '{}' does not exist", name)).with_file(path_);
    fail(rc, "mdb_dbi_open", path_, name);
  }
  // Committing (even a read transaction) makes the handle usable by later transactions.
  if ((rc = mdb_txn_commit(txn))) fail(rc, "mdb_txn_commit", path_, name);
  return {dbi, name};
}

void Env::clear_database(const Database& db) {
  MDB_txn* txn = nullptr;
  if (int rc = mdb_txn_begin(env_, nullptr, 0, &txn)) fail(rc, "mdb_txn_begin (write)", path_, db.name);
  if (int rc = mdb_drop(txn, db.dbi, 0)) {
    mdb_txn_abort(txn);
    fail(rc, "mdb_drop", path_, db.name);
  }
  if (int rc = mdb_txn_commit(txn)) fail(rc, "mdb_txn_commit", path_, db.name);
}

bool Env::has_database(const std::string& name) {
  MDB_txn* txn = nullptr;
  if (int rc = mdb_txn_begin(env_, nullptr, MDB_RDONLY, &txn)) fail(rc, "mdb_txn_begin", path_, name);
  MDB_dbi dbi = 0;
  const int rc = mdb_dbi_open(txn, name.c_str(), 0, &dbi);
  mdb_txn_abort(txn);
  if (rc == MDB_NOTFOUND) return false;
  if (rc) fail(rc, "mdb_dbi_open", path_, name);
  return true;
}

std::vector<std::string> Env::database_names(bool* other_records) {
  MDB_txn* txn = nullptr;
  if (int rc = mdb_txn_begin(env_, nullptr, MDB_RDONLY, &txn)) fail(rc, "mdb_txn_begin", path_);
  std::vector<std::string> names;
  bool other = false;
  MDB_dbi main = 0;
  int rc = mdb_dbi_open(txn, nullptr, 0, &main);
  MDB_cursor* cursor = nullptr;
  if (rc == 0) rc = mdb_cursor_open(txn, main, &cursor);
  if (rc) {
    mdb_txn_abort(txn);
    fail(rc, "mdb_cursor_open (main)", path_);
  }
  MDB_val k{}, v{};
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    // Named databases are records of the main database whose value is a database header.
    std::string name(static_cast<const char*>(k.mv_data), k.mv_size);
    MDB_dbi dbi = 0;
    if (v.mv_size == 48 && mdb_dbi_open(txn, name.c_str(), 0, &dbi) == 0) names.push_back(name);
    else other = true;
  }
  mdb_cursor_close(cursor);
  mdb_txn_abort(txn);
  if (other_records) *other_records = other;
  return names;
}

void Env::sync() {
  if (int rc = mdb_env_sync(env_, 1)) fail(rc, "mdb_env_sync", path_);
}

void Env::set_no_sync(bool no_sync) {
  if (int rc = mdb_env_set_flags(env_, MDB_NOSYNC, no_sync ? 1 : 0)) fail(rc, "mdb_env_set_flags", path_);
  options_.no_sync = no_sync;
}

uint64_t Env::map_size() const {
  MDB_envinfo info;
  mdb_env_info(env_, &info);
  return info.me_mapsize;
}

bool Env::grow() {
  if (!options_.growth) return false;
  const uint64_t current = map_size();
  if (current >= options_.max_map_size) return false;
  const uint64_t next = std::min(options_.max_map_size, current * 2);
  if (int rc = mdb_env_set_mapsize(env_, next)) fail(rc, "mdb_env_set_mapsize", path_);
  return true;
}

ReadTxn::ReadTxn(Env& env) : env_(&env) {
  int rc = mdb_txn_begin(env.handle(), nullptr, MDB_RDONLY, &txn_);
  if (rc == MDB_MAP_RESIZED) {
    // Another process grew the map: adopt its size and retry.
    mdb_env_set_mapsize(env.handle(), 0);
    rc = mdb_txn_begin(env.handle(), nullptr, MDB_RDONLY, &txn_);
  }
  if (rc) fail(rc, "mdb_txn_begin (read)", env.path());
}

ReadTxn::~ReadTxn() {
  if (txn_) mdb_txn_abort(txn_);
}

std::optional<Bytes> ReadTxn::get(const Database& db, Bytes key) const {
  MDB_val k = to_val(key), v{};
  const int rc = mdb_get(txn_, db.dbi, &k, &v);
  if (rc == MDB_NOTFOUND) return std::nullopt;
  if (rc) fail(rc, "mdb_get", env_->path(), db.name, key);
  return to_bytes(v);
}

void ReadTxn::for_each(const Database& db, const std::function<bool(Bytes, Bytes)>& f) const {
  MDB_cursor* cursor = nullptr;
  if (int rc = mdb_cursor_open(txn_, db.dbi, &cursor)) fail(rc, "mdb_cursor_open", env_->path(), db.name);
  struct Closer {
    MDB_cursor* c;
    ~Closer() { mdb_cursor_close(c); }
  } closer{cursor};
  MDB_val k{}, v{};
  int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST);
  while (rc == 0) {
    if (!f(to_bytes(k), to_bytes(v))) return;
    rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT);
  }
  if (rc != MDB_NOTFOUND) fail(rc, "mdb_cursor_get", env_->path(), db.name);
}

uint64_t ReadTxn::count(const Database& db) const {
  MDB_stat st;
  if (int rc = mdb_stat(txn_, db.dbi, &st)) fail(rc, "mdb_stat", env_->path(), db.name);
  return st.ms_entries;
}

BatchWriter::BatchWriter(Env& env, uint64_t batch_bytes) : env_(env), batch_bytes_(batch_bytes) {}

void BatchWriter::put(const Database& db, Bytes key, Bytes value) {
  put(db, key, std::vector<std::byte>(value.begin(), value.end()));
}

void BatchWriter::put(const Database& db, Bytes key, std::vector<std::byte>&& value) {
  pending_bytes_ += key.size() + value.size();
  pending_.push_back({&db, std::vector<std::byte>(key.begin(), key.end()), std::move(value), false});
  if (pending_bytes_ >= batch_bytes_) commit();
}

void BatchWriter::erase(const Database& db, Bytes key) {
  pending_.push_back({&db, std::vector<std::byte>(key.begin(), key.end()), {}, true});
}

void BatchWriter::commit() {
  if (pending_.empty()) return;
  while (true) {
    MDB_txn* txn = nullptr;
    int rc = mdb_txn_begin(env_.handle(), nullptr, 0, &txn);
    if (rc) fail(rc, "mdb_txn_begin (write)", env_.path());
    const Op* failed = nullptr;
    for (const Op& op : pending_) {
      MDB_val k = to_val(op.key);
      if (op.erase) {
        rc = mdb_del(txn, op.db->dbi, &k, nullptr);
        if (rc == MDB_NOTFOUND) rc = 0;
      } else {
        MDB_val v = to_val(op.value);
        rc = mdb_put(txn, op.db->dbi, &k, &v, 0);
      }
      if (rc) {
        failed = &op;
        break;
      }
    }
    if (rc == 0) rc = mdb_txn_commit(txn);
    else mdb_txn_abort(txn);
    if (rc == 0) break;
    if (rc == MDB_MAP_FULL && env_.grow()) continue;  // replay the whole batch in the larger map
    if (rc == MDB_MAP_FULL)
      throw Error(Errc::resource,
                  fmt::format("the store is full: its map size of {} is exhausted{}", format_bytes(double(env_.map_size())),
                              env_.options().growth ? " (growth limit reached)" : " and growth is disabled"))
          .with_file(env_.path())
          .with_key(failed ? key_text(failed->key) : std::string());
    if (failed) fail(rc, failed->erase ? "mdb_del" : "mdb_put", env_.path(), failed->db->name, failed->key);
    fail(rc, "mdb_txn_commit", env_.path());
  }
  committed_bytes_ += pending_bytes_;
  ++commits_;
  pending_.clear();
  pending_bytes_ = 0;
}

}  // namespace brickyard::lmdb
